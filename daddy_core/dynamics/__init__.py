"""Dynamical models (written once for floats and DA) and their normalisation units."""
from .models import (THRUST_FLOOR, cartesian_to_mee, cr3bp, double_integrator_step, equinoctial,
                     equinoctial_sundman, equinoctial_to_cartesian, keplerian_to_equinoctial,
                     keplerian_to_mee, mee_to_cartesian, thrust_dynamics, thrust_magnitude,
                     thrust_norm, two_body)
from .rhs import Dynamics, as_dynamics
from .units import (SYSTEM_UNITS, Spacecraft, Units, earth_moon_units, earth_units, sun_units,
                    unit_units)

__all__ = [
    "THRUST_FLOOR", "cartesian_to_mee", "cr3bp", "double_integrator_step", "equinoctial",
    "equinoctial_sundman", "equinoctial_to_cartesian", "keplerian_to_equinoctial",
    "keplerian_to_mee", "mee_to_cartesian", "thrust_dynamics", "thrust_magnitude", "thrust_norm",
    "two_body",
    "Dynamics", "as_dynamics", "SYSTEM_UNITS", "Spacecraft", "Units", "earth_moon_units", "earth_units", "sun_units",
    "unit_units",
]
