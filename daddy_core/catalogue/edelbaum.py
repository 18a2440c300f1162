"""Can an Earth-centred transfer be flown in its time of flight? Edelbaum's estimate against the
velocity change the thruster can make in that time, checked before any iteration.

Edelbaum's low-thrust transfer between circular orbits of speeds v0, v1 with a plane change
theta (Edelbaum 1961; Kechichian 1997): dv = sqrt(v0^2 + v1^2 - 2 v0 v1 cos(pi/2 theta)), the
velocity change of the minimum-time transfer, thrusting throughout. A transfer that may coast
needs less (a fuel-optimal one changes the plane near the nodes: the LEO case's optimum uses
0.79 km/s where this gives 1.06), so the estimate bounds the *time*, not the propellant: at
full thrust T for the whole time of flight the spacecraft makes c ln(m0 / (m0 - T ToF / c)),
and a transfer whose estimate exceeds that cannot be flown in the time of flight. Eccentric
orbits are taken at the circular speed of their semi-major axis, which leaves out the change
of eccentricity (for GTO -> GEO the estimate is below the velocity change needed, so it refuses
nothing reachable there). With J2 the node line drifts by itself, so only the change of
inclination counts; without, the angle between the orbit planes.
"""
from __future__ import annotations

import math

import numpy as np

from ..dynamics.units import Spacecraft, Units
from ..errors import DaddyError


def _orbit_normal(mee: np.ndarray) -> np.ndarray:
    """Unit angular-momentum direction (3,) of modified equinoctial elements [p, f, g, h, k]."""
    h, k = mee[3], mee[4]
    return np.array([2 * k, -2 * h, 1 - h * h - k * k]) / (1 + h * h + k * k)


def edelbaum_dv(mee0: np.ndarray, mee1: np.ndarray, gm: float, node_drift: bool = False) -> float:
    """Edelbaum's velocity change between the orbits of elements mee0 and mee1 (5,), in the
    units of sqrt(gm / p); ``node_drift``: the plane change is the change of inclination only."""
    n0, n1 = _orbit_normal(mee0), _orbit_normal(mee1)
    if node_drift:
        theta = abs(math.acos(np.clip(n0[2], -1, 1)) - math.acos(np.clip(n1[2], -1, 1)))
    else:
        theta = math.acos(np.clip(n0 @ n1, -1.0, 1.0))
    v0, v1 = (math.sqrt(gm * (1 - m[1] ** 2 - m[2] ** 2) / m[0]) for m in (mee0, mee1))
    return math.sqrt(max(v0 * v0 + v1 * v1 - 2 * v0 * v1 * math.cos(0.5 * math.pi * theta), 0.0))


def check_reachable(mee0: np.ndarray, mee1: np.ndarray, units: Units, spacecraft: Spacecraft,
                    tof: float, node_drift: bool = False) -> None:
    """Raise a ``DaddyError`` naming x_target and tof_days when Edelbaum's estimate exceeds the
    velocity change the spacecraft makes at full thrust over the (normalised) time of flight
    ``tof``."""
    dv = edelbaum_dv(mee0, mee1, units.gm, node_drift) * units.vu_km_s
    c = spacecraft.g0_m_s2 * spacecraft.isp_s / 1000.0                       # km/s
    tof_s = float(units.time_s(tof))
    m0 = spacecraft.wet_mass_kg
    m_end = m0 - spacecraft.max_thrust_n * tof_s / (c * 1000.0)
    if m_end > 0 and dv > c * math.log(m0 / m_end):
        raise DaddyError(
            f"case fields 'x_target' and 'tof_days': the target orbit cannot be reached in "
            f"{tof_s / 86400.0:g} days: Edelbaum's estimate of the transfer is {dv:.3f} km/s, and "
            f"{spacecraft.max_thrust_n:g} N at Isp {spacecraft.isp_s:g} s thrusting throughout "
            f"make {c * math.log(m0 / m_end):.3f} km/s (minimum time about "
            f"{(m0 * (1 - math.exp(-dv / c))) * c * 1000.0 / spacecraft.max_thrust_n / 86400.0:.1f}"
            " days)")
