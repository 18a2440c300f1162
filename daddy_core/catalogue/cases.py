"""The paper's test cases as data: JSON files in ``cases/`` (or any user file), loaded into ``Case``.

A case file holds the system name, the initial and target states (in the units named by
``state_units``: ``normalized``, ``km_km_s`` or ``keplerian_km_deg`` = [a km, e, i, RAAN, argp,
true anomaly deg]), the time of flight in days (or ``stage_duration`` for dimensionless
systems), the stage count, the spacecraft, and two groups of settings used in the paper:
``problem`` (what defines the optimal-control problem: cost gains, the integrator tolerance of
the stage maps) and ``solver`` (how it is solved: tolerances, regularisation bound, homotopy
steps, the initial thrust guess).
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..dynamics import models
from ..dynamics.units import DAY_S, EARTH_RADIUS_KM, SYSTEM_UNITS, Spacecraft, Units
from ..errors import DaddyError

CASES_DIR = Path(__file__).with_name("cases")
SYSTEMS = tuple(SYSTEM_UNITS)
STATE_UNITS = ("normalized", "km_km_s", "keplerian_km_deg")
PROBLEM_KEYS = ("stage_cost_gain", "terminal_cost_gain", "integrator_tol")
# a case's solver section: the paper's per-case settings (``solver.case_options``), no others
SOLVER_KEYS = ("tol_ddp", "tol_aul", "tol_newton", "rho_max", "homotopy", "u_guess_n")


@dataclass(frozen=True)
class Case:
    """A loaded test case, normalised.

    Attributes:
        name, description, system: identification.
        units: normalisation units of the system.
        spacecraft: SI spacecraft parameters (None for the double integrator).
        x0: (nx,) normalised initial state, mass (= wet mass / MU) appended for massive systems.
        x_target: (nx,) normalised target (mass entry = x0's, unused by the terminal conditions).
        tof: total time of flight, normalised.
        stages: number of stages N.
        problem: problem settings (stage_cost_gain, terminal_cost_gain, integrator_tol).
        solver: solver settings (tolerances, rho_max, homotopy sequence, u_guess_n, ...).
    """

    name: str
    description: str
    system: str
    units: Units
    spacecraft: Spacecraft | None
    x0: np.ndarray
    x_target: np.ndarray
    tof: float
    stages: int
    problem: dict = field(default_factory=dict)
    solver: dict = field(default_factory=dict)

    def rhs(self) -> models.Dynamics | None:
        """Continuous right-hand side rhs(t, x, u), or None for a discrete system."""
        if self.system == "double_integrator":
            return None
        c = self.spacecraft.exhaust_speed(self.units)
        if self.system == "sun_two_body":
            return models.two_body(self.units.gm, c)
        if self.system == "earth_moon_cr3bp":
            return models.cr3bp(self.units.gm, c)
        return models.equinoctial(self.units.gm, c)


def list_cases() -> list[str]:
    """Names of the bundled catalogue cases."""
    return sorted(p.stem for p in CASES_DIR.glob("*.json"))


def load_case(name_or_path: str | Path) -> Case:
    """Load a bundled case by name, or a user case file by path."""
    p = Path(name_or_path)
    if p.suffix != ".json":
        p = CASES_DIR / f"{name_or_path}.json"
        if not p.exists():
            raise DaddyError(f"unknown case {str(name_or_path)!r}; known: {', '.join(list_cases())}"
                             " (or give a path to a .json case file)")
    elif not p.exists():
        raise DaddyError(f"case file {str(p)!r} does not exist")
    try:
        data = json.loads(p.read_text())
    except json.JSONDecodeError as exc:
        raise DaddyError(f"case file {str(p)!r} is not valid JSON: {exc}") from exc
    return case_from_dict(data)


def case_from_dict(d: dict) -> Case:
    """Validate and normalise a case description (see the module docstring for the fields)."""
    def need(key):
        if key not in d:
            raise DaddyError(f"case field {key!r} is missing")
        return d[key]

    name = str(need("name"))
    system = need("system")
    if system not in SYSTEMS:
        raise DaddyError(f"case field 'system' must be one of {SYSTEMS}, got {system!r}")
    state_units = d.get("state_units", "normalized")
    if state_units not in STATE_UNITS:
        raise DaddyError(f"case field 'state_units' must be one of {STATE_UNITS}, got {state_units!r}")
    stages = need("stages")
    if not (isinstance(stages, int) and stages >= 1):
        raise DaddyError(f"case field 'stages' must be a positive integer, got {stages!r}")
    moved = sorted(set(d.get("solver", {})) & set(PROBLEM_KEYS))
    if moved:
        raise DaddyError(f"case field 'solver.{moved[0]}' belongs in 'problem' (problem settings: "
                         f"{', '.join(PROBLEM_KEYS)})")
    unknown = sorted(set(d.get("solver", {})) - set(SOLVER_KEYS))
    if unknown:
        raise DaddyError(f"case field 'solver.{unknown[0]}' is not a case setting (solver settings: "
                         f"{', '.join(SOLVER_KEYS)}; other solver options are SolverOptions "
                         "fields, the same for every case)")
    x0 = _vector(need("x0"), "x0", 6)
    xt = _vector(need("x_target"), "x_target", 6)

    if system == "double_integrator":
        units = SYSTEM_UNITS[system]()
        spacecraft = None
        dur = d.get("stage_duration")
        if not (isinstance(dur, (int, float)) and dur > 0 and math.isfinite(dur)):
            raise DaddyError(f"case field 'stage_duration' must be a positive number, got {dur!r}")
        tof = float(dur) * stages
    else:
        spacecraft = Spacecraft(**d.get("spacecraft", {}))
        units = SYSTEM_UNITS[system](spacecraft.wet_mass_kg)
        tof_days = need("tof_days")
        if not (isinstance(tof_days, (int, float)) and tof_days > 0 and math.isfinite(tof_days)):
            raise DaddyError(f"case field 'tof_days' must be a positive number, got {tof_days!r}")
        tof = float(units.time(tof_days * DAY_S))
        x0 = _to_normalised(x0, state_units, units, "x0")
        xt = _to_normalised(xt, state_units, units, "x_target")
        m0 = spacecraft.wet_mass_kg / units.mu_kg
        x0 = np.append(x0, m0)
        xt = np.append(xt, m0)
    return Case(name=name, description=str(d.get("description", "")), system=system, units=units,
                spacecraft=spacecraft, x0=x0, x_target=xt, tof=tof, stages=stages,
                problem=dict(d.get("problem", {})), solver=dict(d.get("solver", {})))


def _vector(v, name: str, size: int) -> np.ndarray:
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError) as exc:
        raise DaddyError(f"case field {name!r} must be a list of {size} numbers") from exc
    if a.shape != (size,) or not np.all(np.isfinite(a)):
        raise DaddyError(f"case field {name!r} must be {size} finite numbers, got {v!r}")
    return a


def _to_normalised(x: np.ndarray, state_units: str, units: Units, name: str) -> np.ndarray:
    if state_units == "normalized":
        return x
    if state_units == "km_km_s":
        return np.concatenate([x[:3] / units.lu_km, x[3:] / units.vu_km_s])
    a_km, e, i, raan, argp, nu = x
    if not a_km > 0:
        raise DaddyError(f"case field '{name}[0]' (a, km) must be > 0 for an orbit, got {a_km!r}")
    if not 0 <= e < 1:
        raise DaddyError(f"case field '{name}[1]' (e) must be in [0, 1) for an orbit (the "
                         f"elements describe closed orbits), got {e!r}")
    if not 0 <= i < 180:
        raise DaddyError(f"case field '{name}[2]' (i, deg) must be in [0, 180): the equinoctial "
                         "elements' tan(i/2) is singular for a retrograde equatorial orbit "
                         f"(i = 180 deg), got {i!r}")
    if a_km * (1 - e) <= EARTH_RADIUS_KM:
        raise DaddyError(f"case field {name!r}: perigee radius a (1 - e) = {a_km * (1 - e):.1f} "
                         f"km is inside the Earth ({EARTH_RADIUS_KM} km)")
    deg = math.pi / 180.0
    return models.keplerian_to_equinoctial(a_km / units.lu_km, e, i * deg, raan * deg, argp * deg,
                                           nu * deg)
