"""Exceptions raised by daddy_core."""


class DaddyError(ValueError):
    """Bad input or an impossible request; the message names the offending field or function."""


class DomainError(DaddyError):
    """An elementary function was evaluated outside its domain (e.g. sqrt of a non-positive DA)."""
