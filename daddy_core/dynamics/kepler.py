"""Keplerian motion of a body on an elliptic orbit, as a function of the elapsed time, written
once for floats and DA (the time may be a DA: a target's state as a polynomial in a free time of
flight).

The closed form is the f and g functions in the eccentric-anomaly difference dE (Battin,
"An Introduction to the Mathematics and Methods of Astrodynamics", 4.3; Vallado, algorithm 8):

    dM = n dt = dE + sigma0 / sqrt(a) (1 - cos dE) - (1 - r0 / a) sin dE     (Kepler's equation)
    r  = a + (r0 - a) cos dE + sigma0 sqrt(a) sin dE
    f  = 1 - a / r0 (1 - cos dE)          g  = a sigma0 / sqrt(gm) (1 - cos dE) + r0 sqrt(a / gm) sin dE
    f' = -sqrt(gm a) / (r r0) sin dE      g' = 1 - a / r (1 - cos dE)

with sigma0 = r0 . v0 / sqrt(gm) and n = sqrt(gm / a^3); r1 = f r0 + g v0, v1 = f' r0 + g' v0.
Kepler's equation is solved by Newton's method, first on the constant part to round-off, then on
the DA: from an exact constant part each Newton step doubles the number of exact orders.
"""
from __future__ import annotations

import math

import numpy as np

from ..da import functions as dm
from ..errors import DaddyError

# Newton steps on the DA after the constant part has converged: exact through order 2^k - 1
_DA_NEWTON_STEPS = 5


def kepler_flow(r0, v0, dt, gm: float):
    """The state [r, v] (6,) of a body on a Keplerian orbit ``dt`` after the state (r0, v0).

    r0, v0: float arrays (3,) [length, length/time, any consistent units with ``gm``]
    [length^3/time^2]; dt: the elapsed time, a float or a DA scalar (negative: backwards). Raises
    a ``DaddyError`` unless the orbit is elliptic.
    """
    r0 = np.asarray(r0, float)
    v0 = np.asarray(v0, float)
    rn = float(np.linalg.norm(r0))
    energy = float(v0 @ v0) / 2.0 - gm / rn
    if not (rn > 0 and energy < 0):
        raise DaddyError(f"kepler_flow: the orbit must be elliptic (negative energy), got "
                         f"|r0| = {rn!r}, energy = {energy!r}")
    a = -gm / (2.0 * energy)
    sa = math.sqrt(a)
    sigma = float(r0 @ v0) / math.sqrt(gm)
    c1, c2 = sigma / sa, 1.0 - rn / a          # Kepler's equation: dE + c1 (1 - cos) - c2 sin
    dM = dt * math.sqrt(gm / a ** 3)

    def residual(E):
        return E + c1 * (1.0 - dm.cos(E)) - c2 * dm.sin(E) - dM

    def slope(E):
        return 1.0 + c1 * dm.sin(E) - c2 * dm.cos(E)     # >= 1 - e > 0 on an ellipse

    M0 = float(dm.cons(dM))
    E0 = M0
    for _ in range(50):
        step = (E0 + c1 * (1.0 - math.cos(E0)) - c2 * math.sin(E0) - M0) / (
            1.0 + c1 * math.sin(E0) - c2 * math.cos(E0))
        E0 -= step
        if abs(step) <= 1e-15 * max(1.0, abs(E0)):
            break
    E = dM - M0 + E0
    if not isinstance(E, float):
        for _ in range(_DA_NEWTON_STEPS):
            E = E - residual(E) / slope(E)
    c, s = dm.cos(E), dm.sin(E)
    r = a + (rn - a) * c + (sigma * sa) * s
    f = 1.0 - (a / rn) * (1.0 - c)
    g = (a * sigma / math.sqrt(gm)) * (1.0 - c) + (rn * math.sqrt(a / gm)) * s
    fd = (-math.sqrt(gm * a) / rn) * s / r
    gd = 1.0 - a * (1.0 - c) / r
    return dm.stack([f * r0[i] + g * v0[i] for i in range(3)]
                    + [fd * r0[i] + gd * v0[i] for i in range(3)])
