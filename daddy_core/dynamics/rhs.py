"""The right-hand side type the integrators rely on.

A right-hand side ``f(t, x, u) -> dx/dt`` is a plain function written once for floats, numpy
arrays and DA (``models``). What an integrator may assume about it beyond that signature is
stated on a ``Dynamics`` object, not on attributes set on the function: a plain callable given
where a ``Dynamics`` is expected means the safe defaults.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np


@dataclass(frozen=True)
class Dynamics:
    """A continuous right-hand side and what the integrators may rely on.

    Attributes:
        f: f(t, x, u) -> dx/dt, x (nx, *batch), u (nu, *batch) (floats, arrays or DA).
        scalar_components: f reads x and u only by integer index (``x[0]``, ``u[2]``), so the
            single-state float integrators may pass lists of Python floats, whose arithmetic
            costs a third of numpy scalars' (return ``da.functions.vector([...])`` of the
            components: on floats it stays a list, which those integrators unpack directly);
            False: f receives numpy arrays (always safe).
        prepare_control: u -> u', applied once per integration (the control is constant over a
            stage), whose result f receives as u: what depends on the control only is then not
            recomputed at each Runge-Kutta stage (e.g. ``models.with_thrust_magnitude``).
        max_step: the largest step RK78 may take (None: no bound beyond the interval). RK78's
            error estimate, (k0 + k10 - k11 - k12) h 41/840, vanishes on a component whose rate
            depends on the independent variable only -- its 7th- and 8th-order solutions then
            coincide -- so such a component is integrated unchecked: the time of a
            Sundman-transformed ballistic orbit (``models.equinoctial_sundman``) is one.
    """

    f: Callable
    scalar_components: bool = False
    prepare_control: Optional[Callable] = None
    max_step: Optional[float] = None

    def __call__(self, t, x, u):
        """dx/dt with the control prepared (for callers outside the integrators): an array
        where ``f`` returns the list of floats ``da.functions.vector`` keeps for the integrators."""
        dx = self.f(t, x, self.prepared(u))
        return np.array(dx) if type(dx) is list else dx

    def prepared(self, u):
        """The control as ``f`` receives it during an integration."""
        return u if self.prepare_control is None or u is None else self.prepare_control(u)


# what earlier versions read from attributes set on the function: now ``Dynamics`` fields
RETIRED_ATTRIBUTES = ("scalar_components", "prepare_control", "max_step")


def as_dynamics(rhs) -> Dynamics:
    """``rhs`` itself if it is a ``Dynamics``, else a plain callable with the safe defaults.
    An attribute earlier versions read from the function (``rhs.scalar_components = True``)
    is not read: a FutureWarning (shown to users by default) names its replacement, a
    ``Dynamics`` field."""
    if isinstance(rhs, Dynamics):
        return rhs
    retired = [a for a in RETIRED_ATTRIBUTES if hasattr(rhs, a)]
    if retired:
        fields = ", ".join(f"{a}={getattr(rhs, a)!r}" for a in retired)
        warnings.warn(f"rhs.{retired[0]} is no longer read: pass Dynamics(rhs, {fields}) "
                      "(daddy_core.dynamics.rhs.Dynamics) instead of setting attributes on the "
                      "function", FutureWarning, stacklevel=3)
    return Dynamics(rhs)
