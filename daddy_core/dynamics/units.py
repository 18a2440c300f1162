"""Normalisation units and spacecraft parameters: the one place where constants live.

Inside the solver every quantity is normalised: length in LU, time in TU, mass in MU (the
spacecraft's wet mass), thrust in MU * LU / TU^2. At every public boundary values are SI (m, s,
kg, N) or the unit is in the name (``tof_days``, ``final_mass_kg``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import DaddyError

DAY_S = 86400.0

# Paper, Table 4 (Sun-centred two-body)
MU_SUN_KM3_S2 = 1.32712440041e11
AU_KM = 149_597_870.7
# Paper, Table 7 (Earth-Moon CR3BP)
MU_EARTH_KM3_S2 = 398_600.0
MU_MOON_KM3_S2 = 4_902.80
EARTH_MOON_KM = 384_399.0
# mean body radii (the guidance node's domain checks)
EARTH_RADIUS_KM = 6378.1
MOON_RADIUS_KM = 1737.4
# the Earth's second zonal harmonic and the reference radius it goes with (EGM96 / WGS 84, as
# tabulated by Vallado, Fundamentals of Astrodynamics, 4th ed., App. D)
EARTH_J2 = 1.08262668e-3
EARTH_J2_RADIUS_KM = 6378.137
# the solar-sail paper's Earth (Leemans, Carzana & Heiligers, Table 1): its cases' gravity field,
# the zonal harmonics J2, J3, J4 with their reference radius
SAIL_MU_EARTH_KM3_S2 = 398_600.4
SAIL_EARTH_RADIUS_KM = 6378.1363
SAIL_EARTH_ZONALS = (1.082626e-3, -2.533e-6, -1.6186e-6)
# systems whose states are Cartesian [r (3), v (3), (m)]; the Earth-centred one's are modified
# equinoctial elements, time and mass [p, f, g, h, k, t, m] (``models.equinoctial_sundman``)
CARTESIAN_SYSTEMS = ("sun_two_body", "earth_moon_cr3bp", "double_integrator")


@dataclass(frozen=True)
class Units:
    """Normalisation units of one dynamical system.

    Attributes:
        name: system name.
        lu_km: length unit [km].
        tu_s: time unit [s].
        mu_kg: mass unit [kg].
        gm: gravitational parameter in normalised units (1 for two-body problems, the mass ratio
            for the CR3BP, unused for the double integrator).
    """

    name: str
    lu_km: float
    tu_s: float
    mu_kg: float = 1000.0
    gm: float = 1.0

    @property
    def vu_km_s(self) -> float:
        return self.lu_km / self.tu_s

    @property
    def thrust_unit_n(self) -> float:
        """Force unit MU * LU / TU^2 in newtons (LU converted from km to m)."""
        return self.mu_kg * self.lu_km * 1000.0 / self.tu_s ** 2

    # SI -> normalised
    def length(self, m):
        return np.asarray(m, dtype=float) / (self.lu_km * 1000.0)

    def speed(self, m_s):
        return np.asarray(m_s, dtype=float) / (self.vu_km_s * 1000.0)

    def time(self, s):
        return np.asarray(s, dtype=float) / self.tu_s

    def mass(self, kg):
        return np.asarray(kg, dtype=float) / self.mu_kg

    def thrust(self, newton):
        return np.asarray(newton, dtype=float) / self.thrust_unit_n

    # normalised -> SI
    def length_m(self, lu):
        return np.asarray(lu, dtype=float) * (self.lu_km * 1000.0)

    def speed_m_s(self, vu):
        return np.asarray(vu, dtype=float) * (self.vu_km_s * 1000.0)

    def time_s(self, tu):
        return np.asarray(tu, dtype=float) * self.tu_s

    def mass_kg(self, mu):
        return np.asarray(mu, dtype=float) * self.mu_kg

    def thrust_n(self, tu):
        return np.asarray(tu, dtype=float) * self.thrust_unit_n

    # whole states
    def states_si(self, X) -> np.ndarray:
        """Normalised states (..., nx) -> SI: Cartesian [position m, velocity m/s, mass kg];
        Earth-centred [p m, f, g, h, k, time s, mass kg] (f..k are dimensionless)."""
        return self._convert_states(X, self.length_m, self.speed_m_s, self.time_s, self.mass_kg)

    def states_normalised(self, X_si) -> np.ndarray:
        """The inverse of ``states_si``."""
        return self._convert_states(X_si, self.length, self.speed, self.time, self.mass)

    def cartesian_si(self, X) -> np.ndarray:
        """Normalised Cartesian states (..., 6 or 7) [r, v, (m)] -> SI [m, m/s, (kg)], whatever
        the system's own state (Earth-centred: the states of ``models.earth_cartesian``)."""
        return self._convert_cartesian(X, self.length_m, self.speed_m_s, self.mass_kg)

    def cartesian_normalised(self, X_si) -> np.ndarray:
        """The inverse of ``cartesian_si``."""
        return self._convert_cartesian(X_si, self.length, self.speed, self.mass)

    @staticmethod
    def _convert_cartesian(X, length, speed, mass) -> np.ndarray:
        X = np.array(X, dtype=float)
        X[..., :3] = length(X[..., :3])
        X[..., 3:6] = speed(X[..., 3:6])
        if X.shape[-1] == 7:
            X[..., 6] = mass(X[..., 6])
        return X

    def _convert_states(self, X, length, speed, time, mass) -> np.ndarray:
        if self.name in CARTESIAN_SYSTEMS:
            return self._convert_cartesian(X, length, speed, mass)
        X = np.array(X, dtype=float)
        X[..., 0] = length(X[..., 0])
        if X.shape[-1] >= 6:      # [p, f, g, h, k, t, (m)]: a sail's state has no mass
            X[..., 5] = time(X[..., 5])
        if X.shape[-1] == 7:
            X[..., 6] = mass(X[..., 6])
        return X

    def as_dict(self) -> dict:
        """The units as a ``Solution`` records them."""
        return {"system": self.name, "lu_km": self.lu_km, "tu_s": self.tu_s, "mu_kg": self.mu_kg,
                "thrust_unit_n": self.thrust_unit_n, "gm": self.gm}

    @classmethod
    def from_dict(cls, d: dict) -> "Units":
        """Units from ``as_dict``'s record (solutions saved before gm was recorded get 1)."""
        return cls(d.get("system", "double_integrator"), float(d.get("lu_km", 1e-3)),
                   float(d.get("tu_s", 1.0)), float(d.get("mu_kg", 1.0)), float(d.get("gm", 1.0)))


def sun_units(mass_kg: float = 1000.0) -> Units:
    """Paper Table 4: LU = 1 AU, TU = sqrt(LU^3 / mu_sun)."""
    return Units("sun_two_body", AU_KM, math.sqrt(AU_KM ** 3 / MU_SUN_KM3_S2), mass_kg, 1.0)


def earth_moon_units(mass_kg: float = 1000.0) -> Units:
    """Paper Table 7: LU = 384 399 km, TU = sqrt(LU^3 / (GM1 + GM2)), mu = GM2 / (GM1 + GM2)."""
    gm = MU_EARTH_KM3_S2 + MU_MOON_KM3_S2
    return Units("earth_moon_cr3bp", EARTH_MOON_KM, math.sqrt(EARTH_MOON_KM ** 3 / gm), mass_kg,
                 MU_MOON_KM3_S2 / gm)


def earth_units(mass_kg: float = 1000.0) -> Units:
    """Paper Table 10: TU = 1 mean solar day, LU = (mu (TU / 2 pi)^2)^(1/3) (geosynchronous).

    In these units the Earth's gravitational parameter is mu TU^2 / LU^3 = 4 pi^2 (an orbit of
    radius 1 LU has a period of 1 TU), not 1: the units are not the canonical ones in which
    mu = 1, so gm is derived here from its definition rather than assumed."""
    tu = DAY_S
    lu = (MU_EARTH_KM3_S2 * (tu / (2 * math.pi)) ** 2) ** (1.0 / 3.0)
    return Units("earth_equinoctial", lu, tu, mass_kg, MU_EARTH_KM3_S2 * tu ** 2 / lu ** 3)


def earth_sail_units(mass_kg: float = 1.0) -> Units:
    """The solar-sail cases' units: ``earth_units``' (TU = 1 mean solar day, LU the radius of
    a 1-TU circular orbit, 42 241 km) with the sail paper's gravitational parameter."""
    tu = DAY_S
    lu = (SAIL_MU_EARTH_KM3_S2 * (tu / (2 * math.pi)) ** 2) ** (1.0 / 3.0)
    return Units("earth_sail", lu, tu, mass_kg, SAIL_MU_EARTH_KM3_S2 * tu ** 2 / lu ** 3)


def unit_units() -> Units:
    """Dimensionless system (double integrator): every unit is 1 (m, s, kg)."""
    return Units("double_integrator", 1e-3, 1.0, 1.0, 1.0)


SYSTEM_UNITS = {
    "sun_two_body": sun_units,
    "earth_moon_cr3bp": earth_moon_units,
    "earth_equinoctial": earth_units,
    "earth_sail": earth_sail_units,
    "double_integrator": lambda mass_kg=1.0: unit_units(),
}


@dataclass(frozen=True)
class Spacecraft:
    """Spacecraft parameters in SI (paper Table 4 defaults)."""

    wet_mass_kg: float = 1000.0
    dry_mass_kg: float = 500.0
    max_thrust_n: float = 0.5
    isp_s: float = 2000.0
    g0_m_s2: float = 9.81

    def __post_init__(self):
        for field in ("wet_mass_kg", "dry_mass_kg", "max_thrust_n", "isp_s", "g0_m_s2"):
            v = getattr(self, field)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise DaddyError(f"spacecraft.{field} must be a positive finite number, got {v!r}")
        if self.dry_mass_kg >= self.wet_mass_kg:
            raise DaddyError(f"spacecraft.dry_mass_kg ({self.dry_mass_kg}) must be below "
                             f"wet_mass_kg ({self.wet_mass_kg})")

    def exhaust_speed(self, units: Units) -> float:
        """Effective exhaust speed g0 * Isp in normalised velocity units."""
        return self.g0_m_s2 * self.isp_s / (units.vu_km_s * 1000.0)
