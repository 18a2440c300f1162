"""When a solve must stop (``Deadline``): its time budget, or a caller's cancel request.

Every loop of the solver (DDP, AUL, Newton, KKT polishing) asks ``passed(deadline)`` once per
iteration, so a cancel request stops a solve within one iteration, as the time budget does, and
the solve returns its best point so far with ``Status.CANCELLED``.
"""
from __future__ import annotations

import math
import time
from typing import Protocol

from .results import Status


class CancelFlag(Protocol):
    """Anything with ``is_set()`` (a ``threading.Event``): set it to cancel the solve."""

    def is_set(self) -> bool: ...


class Deadline:
    """A ``time.perf_counter`` time ``at`` [s] (None: no time budget) and a cancel flag (None:
    the solve cannot be cancelled)."""

    __slots__ = ("at", "cancel")

    def __init__(self, at: float | None, cancel: CancelFlag | None = None):
        self.at, self.cancel = at, cancel

    @property
    def cancelled(self) -> bool:
        return self.cancel is not None and self.cancel.is_set()

    def passed(self) -> bool:
        """Cancelled, or the time budget is spent."""
        return self.cancelled or (self.at is not None and time.perf_counter() >= self.at)

    def left(self) -> float:
        """Seconds left (0 once cancelled; inf without a budget)."""
        if self.cancelled:
            return 0.0
        return math.inf if self.at is None else self.at - time.perf_counter()

    @property
    def status(self) -> Status:
        """Why a loop that found the deadline passed stopped."""
        return Status.CANCELLED if self.cancelled else Status.TIME_BUDGET


def passed(deadline: Deadline | None) -> bool:
    """``deadline.passed()``; False without a deadline."""
    return deadline is not None and deadline.passed()
