"""The many-revolution Earth-centred solar sail of Leemans, Carzana and Heiligers, staged in the
true longitude (a Sundman transformation, dt/dL = r^2 / h up to the normal acceleration's term):
the modified equinoctial elements and the time under the ideal sail's acceleration (``sail``),
the Earth's shadow, its zonal harmonics and the Sun's and the Moon's gravity
(``perturbations``, ``ephemeris``). Written once for floats, arrays and DA, like every model.

State x = [p, f, g, h, k, t] (6, *batch), normalised (``units.earth_sail_units``); no mass
(the sail spends none). Control u = [w1, w2] (2, *batch): the sail normal's tangent-plane
point (``sail.sail_normal``: tan(cone) = |w|, clock = atan2(w2, w1)); or [w] alone when the
model fixes the clock angle (the paper's in-plane steering, clock = 90 deg): w = tan(cone), the
cone signed.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

from ..da import functions as dm
from . import perturbations, sail
from .models import SUNDMAN_MAX_STEP, _gauss_sundman, mee_frame
from .rhs import Dynamics


@dataclass(frozen=True)
class EarthForces:
    """The forces beyond point-mass gravity and the sail, normalised: the zonal harmonics
    ``zonals`` = (J2, J3, J4) of the Earth (``gm``) with their reference radius, and point masses ``third_bodies`` =
    ((gm, position), ...) with position(t) -> a list of 3 components (t the state's time)."""

    gm: float = 1.0
    zonal_radius: float = 0.0
    zonals: tuple = (0.0, 0.0, 0.0)
    third_bodies: tuple = ()

    def acceleration(self, r, t) -> list | None:
        """The perturbing acceleration (a list of 3) at ECI position r and time t, or None."""
        a = None
        if any(self.zonals):
            a = perturbations.zonal_acceleration(r, self.gm, self.zonal_radius, *self.zonals)
        for gm, position in self.third_bodies:
            b = perturbations.third_body_acceleration(r, position(t), gm)
            a = b if a is None else [a[i] + b[i] for i in range(3)]
        return a


@dataclass(frozen=True)
class Sail:
    """The ideal sail in normalised units: ``sail_gm`` = beta gm_sun (its acceleration facing
    the Sun at unit distance), ``sun``(t) the Sun's position (a list of 3), the Earth's shadow
    (cylinder ``shadow_radius``, smoothed over ``shadow_width``; None: no eclipses) and a fixed
    clock angle ``clock`` [rad] (None: the clock angle is the second control)."""

    sail_gm: float
    sun: Callable
    shadow_radius: float | None = None
    shadow_width: float = 0.0
    clock: float | None = None

    @property
    def nu(self) -> int:
        return 1 if self.clock is not None else 2

    def acceleration(self, r, t, u):
        """The sail's acceleration (a list of 3) at ECI position r, time t, under u."""
        r_sun = self.sun(t)
        rs = [r[i] - r_sun[i] for i in range(3)]
        inv_d = 1.0 / dm.sqrt(rs[0] * rs[0] + rs[1] * rs[1] + rs[2] * rs[2])
        s_hat = [c * inv_d for c in rs]
        if self.clock is None:
            n = sail.sail_normal(u[0], u[1], s_hat)
        else:
            n = sail.sail_normal(u[0] * math.cos(self.clock), u[0] * math.sin(self.clock), s_hat)
        light = 1.0
        if self.shadow_radius is not None:
            light = sail.sunlight(r, r_sun, self.shadow_radius, self.shadow_width)
        return sail.sail_acceleration(r, r_sun, n, 1.0, self.sail_gm, light)


def sail_sundman(gm: float, sail_model: Sail, forces: EarthForces = EarthForces()) -> Dynamics:
    """rhs(L, x, u) = dx/dL of the sail's elements and time (module docstring): the sail's and
    the perturbations' inertial accelerations projected on the orbit's RTN axes
    (``models.mee_frame``) and fed to the Gauss equations (``models._gauss_sundman``)."""
    inv_sqrt_gm = gm ** -0.5
    perturbed = bool(forces.third_bodies) or any(forces.zonals)

    def rhs(L, x, u):
        sL, cL = dm.sin(L), dm.cos(L)
        r, r_hat, t_hat, n_hat = mee_frame(x, sL, cL)
        a = sail_model.acceleration(r, x[5], u)
        if perturbed:
            b = forces.acceleration(r, x[5])
            a = [a[i] + b[i] for i in range(3)]
        ar = a[0] * r_hat[0] + a[1] * r_hat[1] + a[2] * r_hat[2]
        at = a[0] * t_hat[0] + a[1] * t_hat[1] + a[2] * t_hat[2]
        an = a[0] * n_hat[0] + a[1] * n_hat[1] + a[2] * n_hat[2]
        rates, _ = _gauss_sundman(x, sL, cL, ar, at, an, inv_sqrt_gm)
        return dm.vector(rates)
    return Dynamics(rhs, scalar_components=True, max_step=SUNDMAN_MAX_STEP)
