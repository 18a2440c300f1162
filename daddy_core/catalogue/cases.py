"""The paper's test cases as data: JSON files in ``cases/`` (or any user file), loaded into ``Case``.

A case file holds the system name, the initial and target states (in the units named by
``state_units``: ``normalized``, ``km_km_s`` or ``keplerian_km_deg`` = [a km, e, i, RAAN, argp,
true anomaly deg]), the time of flight in days (or ``stage_duration`` for dimensionless
systems), the stage count, the spacecraft, and two groups of settings used in the paper:
``problem`` (what defines the optimal-control problem: cost gains, the integrator tolerance of
the stage maps) and ``solver`` (how it is solved: tolerances, regularisation bound, homotopy
steps, the initial thrust guess).

Earth-centred cases (``earth_equinoctial``) are staged in the true longitude L, not in time (a
Sundman transformation, ``models.equinoctial_sundman``): their state is [p, f, g, h, k, t, m],
the stages are ``stages_per_revolution`` equal arcs of L over ``revolutions`` revolutions
(optional: by default the revolutions a spacecraft makes in the time of flight at the mean of
the initial and target mean motions), and the arrival is the target orbit (p, f, g, h, k) at
t = ToF anywhere along it: the target's true anomaly is not used. ``perturbations`` (optional)
lists the forces beyond point-mass gravity and thrust: ``["j2"]``, the Earth's oblateness.
Before any iteration the transfer is checked against what the thruster can do (``edelbaum``).
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, replace
from enum import Enum
from pathlib import Path

import numpy as np

from ..dynamics import models
from ..dynamics.units import (DAY_S, EARTH_J2, EARTH_J2_RADIUS_KM, EARTH_RADIUS_KM, SYSTEM_UNITS,
                              Spacecraft, Units)
from ..errors import DaddyError
from . import sail_cases
from .edelbaum import check_reachable

CASES_DIR = Path(__file__).with_name("cases")
SYSTEMS = tuple(SYSTEM_UNITS)
STATE_UNITS = ("normalized", "km_km_s", "keplerian_km_deg")
PROBLEM_KEYS = ("stage_cost_gain", "terminal_cost_gain", "integrator_tol", "tof_window",
                "revolutions_window", "terminal")
# the double integrator's terminal condition (problem.terminal): the position, or every component
DOUBLE_INTEGRATOR_TERMINAL = {"position": 3, "state": 6}
# a case's solver section: the paper's per-case settings (``solver.case_options``), no others
SOLVER_KEYS = ("tol_ddp", "tol_aul", "tol_newton", "rho_max", "homotopy", "u_guess_n")
HOMOTOPY_KEYS = ("h", "delta")
SPACECRAFT_KEYS = ("wet_mass_kg", "dry_mass_kg", "max_thrust_n", "isp_s", "g0_m_s2")
# every top-level field a case file may have (which apply depends on its system)
CASE_KEYS = ("name", "description", "source", "system", "state_units", "x0", "x_target",
             "tof_days", "stages", "stage_duration", "stages_per_revolution", "revolutions",
             "perturbations", "spacecraft", "problem", "solver", "phases", "closed_loop")
# fields that are not case settings, and where they are set instead
_SET_ELSEWHERE = {"r_min_km": "it is not a case setting: give it to problem_from_case(case, "
                              "r_min_km=...) or `daddy solve --r-min-km`",
                  **{k: "it belongs in the 'solver' section" for k in SOLVER_KEYS}}


class Perturbation(str, Enum):
    """A force an Earth-centred case may add to point-mass gravity and thrust."""

    J2 = "j2"   # the Earth's oblateness (``units.EARTH_J2``)


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
        revolutions: Earth-centred cases: the revolutions of the transfer (the stages span
            2 pi revolutions of true longitude); None for cases staged in time.
        t_start: the true longitude of x0 for Earth-centred cases [rad], else 0.
        perturbations: the forces beyond point-mass gravity and thrust (Earth-centred cases).
        stages_per_revolution: Earth-centred cases: the stage density (None otherwise).
        phases: a multi-phase case's ``phased_cases.PhaseSpec``s (empty for one phase).
        closed_loop: the mission's defaults for a closed-loop campaign's sections (e.g. its
            navigation errors and success criteria: ``daddy_sim.campaigns`` validates them).
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
    revolutions: float | None = None
    t_start: float = 0.0
    perturbations: frozenset = frozenset()
    stages_per_revolution: int | None = None
    phases: tuple = ()
    closed_loop: dict = field(default_factory=dict)

    @property
    def staged_in_angle(self) -> bool:
        """The stages are arcs of true longitude (Sundman-transformed), not durations."""
        return self.revolutions is not None

    def with_revolutions(self, revolutions: float) -> "Case":
        """The same Earth-centred transfer over another total angle (its stage density kept):
        the arrival anywhere on the target orbit makes the angle a free choice, which
        ``catalogue.revolutions.search_revolutions`` searches."""
        if not self.staged_in_angle:
            raise DaddyError(f"case {self.name!r} is staged in time: only Earth-centred cases "
                             "have a number of revolutions")
        if not (revolutions > 0 and math.isfinite(revolutions)):
            raise DaddyError(f"revolutions must be a positive number, got {revolutions!r}")
        return replace(self, revolutions=float(revolutions),
                       stages=max(1, round(revolutions * self.stages_per_revolution)))

    def stage_lengths(self, stages: int | None = None) -> np.ndarray:
        """(N,) equal stage lengths: normalised durations, or angles [rad] for Earth-centred
        cases; ``stages`` overrides N (the span -- ToF or revolutions -- stays)."""
        N = self.stages if stages is None else int(stages)
        if N < 1:
            raise DaddyError(f"stages must be >= 1, got {N}")
        span = 2 * math.pi * self.revolutions if self.staged_in_angle else self.tof
        return np.full(N, span / N)

    def rhs(self) -> models.Dynamics | None:
        """Continuous right-hand side rhs(t, x, u) (Earth-centred cases: rhs(L, x, u), the true
        longitude L the independent variable), or None for a discrete system."""
        if self.system == "double_integrator":
            return None
        c = self.spacecraft.exhaust_speed(self.units)
        if self.system == "sun_two_body":
            return models.two_body(self.units.gm, c)
        if self.system == "earth_moon_cr3bp":
            return models.cr3bp(self.units.gm, c)
        return models.equinoctial_sundman(self.units.gm, c, *self._j2())

    def cartesian_rhs(self) -> models.Dynamics | None:
        """The right-hand side in time of the Cartesian state [r, v, m] (normalised), thrust as
        ``rhs`` takes it: ``rhs`` itself for the Cartesian systems, ``models.earth_cartesian``
        (thrust in RTN) for Earth-centred ones -- what a navigation estimate is propagated with."""
        if not self.staged_in_angle:
            return self.rhs()
        return models.earth_cartesian(self.units.gm, self.spacecraft.exhaust_speed(self.units),
                                      *self._j2())

    def cold_guess(self, stages: int) -> np.ndarray:
        """(stages, 3) initial controls of a cold solve: the case's ``solver.u_guess_n`` (the
        paper's 1e-6 N by default) on every component, normalised for a spacecraft (as it is
        for the double integrator's accelerations)."""
        guess = self.solver.get("u_guess_n", 1e-6)
        if self.spacecraft is not None:
            guess = float(self.units.thrust(guess))
        return np.full((int(stages), 3), guess)

    def cartesian_x0(self) -> np.ndarray:
        """The initial state as ``cartesian_rhs`` takes it, [r, v, m] (7,) normalised."""
        if not self.staged_in_angle:
            return self.x0.copy()
        return np.append(models.mee_to_cartesian(self.x0[:5], self.t_start, self.units.gm),
                         self.x0[6])

    def _j2(self) -> tuple[float, float]:
        """(J2, its reference radius normalised) of an Earth-centred case; zeros without J2."""
        if Perturbation.J2 not in self.perturbations:
            return 0.0, 0.0
        return EARTH_J2, EARTH_J2_RADIUS_KM / self.units.lu_km


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


def load_thrust_case(name_or_path: str | Path) -> Case:
    """``load_case`` for a consumer of thrust cases (the guidance node): a DaddyError naming a
    solar-sail case as such."""
    case = load_case(name_or_path)
    if isinstance(case, sail_cases.SailCase):
        raise DaddyError(f"case {case.name!r} is a solar-sail case (no thruster, no mass): the "
                         f"guidance node flies thrust cases; solve it with `daddy solve "
                         f"{case.name}`")
    if case.phases:
        raise DaddyError(f"case {case.name!r} has phases: the guidance node flies one-phase "
                         f"thrust cases; solve it with `daddy solve {case.name}`")
    return case


def case_from_dict(d: dict) -> Case:
    """Validate and normalise a case description (see the module docstring for the fields);
    a solar-sail case (``"system": "earth_sail"``) becomes a ``sail_cases.SailCase``."""
    if isinstance(d, dict) and d.get("system") == sail_cases.SYSTEM:
        return sail_cases.sail_case_from_dict(d)
    def need(key):
        if key not in d:
            raise DaddyError(f"case field {key!r} is missing")
        return d[key]

    _known_keys(d, CASE_KEYS, "")
    for section, keys in (("problem", PROBLEM_KEYS),
                          ("spacecraft", SPACECRAFT_KEYS)):
        if not isinstance(d.get(section, {}), dict):
            raise DaddyError(f"case field {section!r} must be an object")
        _known_keys(d.get(section, {}), keys, f"{section}.")
    if not isinstance(d.get("solver", {}), dict):
        raise DaddyError("case field 'solver' must be an object")
    hom = d.get("solver", {}).get("homotopy")
    if hom is not None:
        if not isinstance(hom, dict):
            raise DaddyError("case field 'solver.homotopy' must be an object {\"h\": [...], "
                             "\"delta\": [...]}")
        _known_keys(hom, HOMOTOPY_KEYS, "solver.homotopy.")
    name = str(need("name"))
    system = need("system")
    if system not in SYSTEMS:
        raise DaddyError(f"case field 'system' must be one of {SYSTEMS}, got {system!r}")
    state_units = d.get("state_units", "normalized")
    if state_units not in STATE_UNITS:
        raise DaddyError(f"case field 'state_units' must be one of {STATE_UNITS}, got {state_units!r}")
    phases = ()
    if "phases" in d:
        from .phased_cases import phases_from_list
        phases = phases_from_list(d["phases"], system)
        for key in ("stages", "stage_duration"):
            if key in d:
                raise DaddyError(f"case field {key!r}: a phased case gives each phase's "
                                 "'stages' and 'stage_duration' in 'phases'")
    terminal = d.get("problem", {}).get("terminal")
    if terminal is not None and (system != "double_integrator" or not isinstance(terminal, str)
                                 or terminal not in DOUBLE_INTEGRATOR_TERMINAL):
        raise DaddyError(f"case field 'problem.terminal' is for the double_integrator system, "
                         f"one of {tuple(DOUBLE_INTEGRATOR_TERMINAL)}; got {terminal!r} "
                         f"(system {system!r})")
    if phases:
        stages = sum(p.stages for p in phases)
    elif system != "earth_equinoctial":
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
    if "perturbations" in d and system != "earth_equinoctial":
        raise DaddyError("case field 'perturbations' is for Earth-centred cases (system "
                         f"'earth_equinoctial'); this case's system is {system!r}")
    x0 = _vector(need("x0"), "x0", 6)
    xt = _vector(need("x_target"), "x_target", 6)

    if phases:
        units = SYSTEM_UNITS[system]()
        spacecraft = None
        tof = sum(p.stages * p.stage_duration for p in phases)
    elif system == "double_integrator":
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
        m0 = spacecraft.wet_mass_kg / units.mu_kg
        if system == "earth_equinoctial":
            return _earth_case(d, name, units, spacecraft, x0, xt, state_units, tof, m0)
        x0 = np.append(_to_normalised(x0, state_units, units, "x0"), m0)
        xt = np.append(_to_normalised(xt, state_units, units, "x_target"), m0)
    return Case(name=name, description=str(d.get("description", "")), system=system, units=units,
                spacecraft=spacecraft, x0=x0, x_target=xt, tof=tof, stages=stages,
                problem=dict(d.get("problem", {})), solver=dict(d.get("solver", {})),
                phases=phases, closed_loop=_closed_loop(d))


def _closed_loop(d: dict) -> dict:
    """The case's ``closed_loop`` section: a mapping of mappings (its fields are checked where
    a campaign reads them)."""
    section = d.get("closed_loop", {})
    if not (isinstance(section, dict) and all(isinstance(v, dict) for v in section.values())):
        raise DaddyError("case field 'closed_loop' must be an object of objects (campaign "
                         "sections, e.g. {\"success\": {\"miss_km\": 1000.0}})")
    return {k: dict(v) for k, v in section.items()}


def _earth_case(d: dict, name: str, units: Units, spacecraft: Spacecraft, x0: np.ndarray,
                xt: np.ndarray, state_units: str, tof: float, m0: float) -> Case:
    """An Earth-centred case staged in true longitude (see the module docstring)."""
    if "stages" in d:
        raise DaddyError("case field 'stages': Earth-centred cases are staged in true longitude; "
                         "give 'stages_per_revolution' (and optionally 'revolutions') instead")
    spr = d.get("stages_per_revolution")
    if not (isinstance(spr, int) and spr >= 4):
        raise DaddyError(f"case field 'stages_per_revolution' must be an integer >= 4, got {spr!r}")
    if state_units == "km_km_s":
        raise DaddyError("case field 'state_units': Earth-centred cases take 'keplerian_km_deg' "
                         "or 'normalized' (modified equinoctial [p, f, g, h, k, L]) states")
    mee0, L0 = _earth_elements(x0, state_units, units, "x0")
    mee_t, _ = _earth_elements(xt, state_units, units, "x_target")
    revs = d.get("revolutions")
    if revs is None:
        revs = tof / (2 * math.pi) * 0.5 * (_mean_motion(mee0, units.gm) + _mean_motion(mee_t, units.gm))
    elif not (isinstance(revs, (int, float)) and revs > 0 and math.isfinite(revs)):
        raise DaddyError(f"case field 'revolutions' must be a positive number, got {revs!r}")
    stages = max(1, round(revs * spr))
    perturbations = _perturbations(d.get("perturbations", []))
    check_reachable(mee0, mee_t, units, spacecraft, tof, Perturbation.J2 in perturbations)
    return Case(name=name, description=str(d.get("description", "")), system="earth_equinoctial",
                units=units, spacecraft=spacecraft, x0=np.concatenate([mee0, [0.0, m0]]),
                x_target=np.concatenate([mee_t, [tof, m0]]), tof=tof, stages=stages,
                problem=dict(d.get("problem", {})), solver=dict(d.get("solver", {})),
                revolutions=float(revs), t_start=L0, perturbations=perturbations,
                stages_per_revolution=spr, closed_loop=_closed_loop(d))


def _known_keys(d: dict, known: tuple, prefix: str) -> None:
    """A DaddyError naming the first key of ``d`` not in ``known`` (and where it belongs, for a
    field that is set elsewhere), with the known ones."""
    unknown = sorted(set(d) - set(known))
    if not unknown:
        return
    key = unknown[0]
    where = _SET_ELSEWHERE.get(key)
    hint = f": {where}" if where else ""
    raise DaddyError(f"case field '{prefix}{key}' is unknown{hint} (known: {', '.join(known)})")


def _perturbations(names) -> frozenset:
    """A case file's ``perturbations`` list -> the set of ``Perturbation``s."""
    known = [p.value for p in Perturbation]
    if not isinstance(names, list) or any(n not in known for n in names):
        raise DaddyError(f"case field 'perturbations' must be a list of {known}, got {names!r}")
    return frozenset(Perturbation(n) for n in names)


def _mean_motion(mee: np.ndarray, gm: float) -> float:
    """Mean motion sqrt(gm / a^3) of the orbit of modified equinoctial elements [p, f, g, ...]."""
    a = mee[0] / (1.0 - mee[1] ** 2 - mee[2] ** 2)
    return math.sqrt(gm / a ** 3)


def _earth_elements(x: np.ndarray, state_units: str, units: Units, name: str):
    """A case file's Earth-centred state -> modified equinoctial [p, f, g, h, k] (normalised)
    and the true longitude [rad]."""
    if state_units == "normalized":
        p, f, g = x[0], x[1], x[2]
        if not (p > 0 and f * f + g * g < 1):
            raise DaddyError(f"case field {name!r}: modified equinoctial elements need p > 0 and "
                             f"f^2 + g^2 < 1 (a closed orbit), got {x[:3].tolist()}")
        return np.array(x[:5], float), float(x[5])
    _check_keplerian(x, name)
    a_km, e, i, raan, argp, nu = x
    deg = math.pi / 180.0
    return models.keplerian_to_mee(a_km / units.lu_km, e, i * deg, raan * deg, argp * deg,
                                   nu * deg)


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
    raise DaddyError(f"case field 'state_units': 'keplerian_km_deg' is for Earth-centred cases "
                     f"(system 'earth_equinoctial'); this case's {name} is Cartesian")


def _check_keplerian(x: np.ndarray, name: str) -> None:
    """Each Keplerian element of a case file's state [a km, e, i deg, ...], named when wrong."""
    a_km, e, i = x[:3]
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
