"""Fuel-optimal costs for any problem: the pseudo-Huber stage cost of the paper's homotopy
(eq. 12-14) and the default (h, delta) sequence that ``solve(..., fuel_optimal=True)`` runs
when the options name none.

With w = u dt / (dt_ref u_max) (the control as a fraction of the bound, weighted by the stage's
share of a reference duration),

    l_h,delta(u) = (1 - h) gain/2 |w|^2 + h gain delta (sqrt(1 + |w|^2 / delta^2) - 1):

h = 0 is the smooth energy-optimal cost; as h -> 1 and delta -> 0 the second term tends to
gain |w|, the propellant (|u| dt) of a constant-exhaust-speed thruster. Each homotopy step
starts from the previous step's solution, so DDP never faces the kink of |w| at zero thrust.
The limit itself, the propellant, is what the exact end game of a fuel-optimal solve minimises
(``FuelStageCost.propellant``, ``throttle``).
"""
from __future__ import annotations

from dataclasses import dataclass

from .da import functions as dm
from .errors import DaddyError

# the paper's sequence for the two-body and Earth-centred transfers (its Table 5); the
# CR3BP cases use their own (catalogue case files)
FUEL_HOMOTOPY = ((0.0, 1e-2), (0.5, 1e-2), (0.9, 2e-3), (0.999, 1e-3))


class FuelStageCost:
    """A stage cost l(x, u, dt, hom) of the fuel homotopy that also states the limit it tends
    to, the propellant, as a function of the thrust magnitude: what the exact fuel end game
    (``throttle``) minimises. Subclasses implement both."""

    def __call__(self, x, u, dt, hom=(0.0, 1.0)):
        raise NotImplementedError

    def propellant(self, x, thrust, dt):
        """The h = 1, delta -> 0 limit of the stage cost at the thrust magnitude ``thrust``
        (B,) (|u|, in u's units): linear in it. Floats or DA, batched like the stage cost."""
        raise NotImplementedError


@dataclass(frozen=True)
class PseudoHuberCost(FuelStageCost):
    """The stage cost l(x, u, dt, hom) of the module docstring for a control of any dimension nu
    (floats or DA, batched: u (nu, B), dt (B,) -> (B,)); ``pseudo_huber_stage_cost`` builds it.

    Attributes:
        u_max: the control bound (same units as u; > 0), the scale of w.
        dt_ref: reference stage duration (e.g. the mean stage), the time scale of w.
        gain: weight of the stage cost against the terminal cost.
    """

    u_max: float
    dt_ref: float
    gain: float = 1.0

    def __call__(self, x, u, dt, hom=(0.0, 1.0)):
        h, delta = hom
        s = dt * (1.0 / (self.dt_ref * self.u_max))
        u2 = u[0] * u[0]
        for i in range(1, len(u)):
            u2 = u2 + u[i] * u[i]
        w2 = u2 * (s * s)
        energy = w2 * (0.5 * self.gain)
        if h == 0.0:
            return energy
        huber = (dm.sqrt(w2 * (1.0 / (delta * delta)) + 1.0) - 1.0) * (self.gain * delta)
        return energy * (1.0 - h) + huber * h

    def propellant(self, x, thrust, dt):
        """gain |w| = gain |u| dt / (dt_ref u_max)."""
        return thrust * (dt * (self.gain / (self.dt_ref * self.u_max)))


def pseudo_huber_stage_cost(u_max: float, dt_ref: float, gain: float = 1.0) -> PseudoHuberCost:
    """The paper's homotopy cost (module docstring), its arguments checked: a
    ``PseudoHuberCost``."""
    if not (u_max > 0 and dt_ref > 0 and gain > 0):
        raise DaddyError(f"pseudo_huber_stage_cost needs u_max, dt_ref and gain > 0, got "
                         f"{u_max!r}, {dt_ref!r}, {gain!r}")
    return PseudoHuberCost(float(u_max), float(dt_ref), float(gain))
