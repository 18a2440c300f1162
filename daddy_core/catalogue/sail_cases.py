"""The solar-sail cases of Leemans, Carzana and Heiligers (many-revolution solar-sail DDP) as
data: JSON files in ``cases/`` with ``"system": "earth_sail"`` (or any user file), loaded into
``SailCase`` and solved by ``solve_sail`` (issue 45).

A sail case maximises the semi-major axis after a number of revolutions, with no terminal
constraint (the paper's objective). Its fields:

- ``x0``: the initial orbit, [a km, e, i deg, RAAN deg, argp deg, true anomaly deg] (the
  initial phase is argp + true anomaly from the node);
- ``beta``: the sail's lightness number (> 0);
- ``epoch``: the start, ISO 8601 UTC (taken as TT: 69 s, far below the ephemeris' accuracy);
- ``sun``: ``"ephemeris"`` (the Sun moves, ``ephemeris.sun_position_km``) or
  ``{"fixed_direction": [x, y, z]}`` (the Sun held at 1 AU along that direction);
- ``steering``: ``"free"`` (cone and clock, two controls) or ``"in_plane"`` (the clock angle
  held at 90 deg: the normal stays in the plane of the sunlight and the equator);
- ``eclipse`` (optional): ``{"shadow": "cylinder", "width_km": W}``, the Earth's cylindrical
  shadow smoothed over W km (``sail.sunlight``; reported with every result);
- ``perturbations`` (optional): any of ``j2, j3, j4`` (the paper's Table 1 zonals),
  ``moon``, ``sun`` (third-body gravity from the ephemeris);
- ``revolutions`` and ``stages_per_revolution``: the stages are equal arcs of true longitude.

Solved with the Hess sweep and the trust region (``SAIL_METHOD``, ``sail_options``: why in the
design notes, "Solar sails"), from the locally optimal steering law held per
stage (``steering_law``), which is also the baseline every result reports.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from datetime import datetime, timezone
from enum import Enum

import numpy as np

from ..dynamics import ephemeris, models, sail
from ..dynamics.earth_sail import EarthForces, Sail, sail_sundman
from ..dynamics.units import (AU_KM, MU_MOON_KM3_S2, MU_SUN_KM3_S2, SAIL_EARTH_RADIUS_KM,
                              SAIL_EARTH_ZONALS, Units, earth_sail_units)
from .. import trajectory_output
from ..trajectory_output import J2000
from ..errors import DaddyError
from ..problem import Problem, flow_step
from ..solver import Globalization, Method, Solution, SolverOptions, solve

SYSTEM = "earth_sail"
SAIL_KEYS = ("name", "description", "source", "system", "x0", "beta", "epoch", "sun",
             "steering", "eclipse", "perturbations", "revolutions", "stages_per_revolution")
ECLIPSE_KEYS = ("shadow", "width_km")
# the steering law's cone angle is held below this: edge-on (90 deg) is w = inf
LAW_MAX_CONE_RAD = math.radians(89.0)
SAIL_METHOD = Method.HESSDYN
# DDP's stop on the relative cost decrease: the objective ~ -da / a0 is 1e-5..1e-2 and its
# last metres come at ~1e-6 relative per iteration (design notes, "Solar sails")
SAIL_TOL_DDP = 1e-7


class SailSteering(Enum):
    """Which sail angles the controls move."""

    FREE = "free"           # cone and clock: u = [w1, w2] (``sail.sail_normal``)
    IN_PLANE = "in_plane"   # the clock held at 90 deg: u = [w], w = tan(cone), signed


class SailPerturbation(str, Enum):
    """A force a sail case may add to point-mass gravity and the sail."""

    J2 = "j2"
    J3 = "j3"
    J4 = "j4"
    MOON = "moon"
    SUN = "sun"


class SailGuess(Enum):
    """The initial controls of a sail solve."""

    STEERING_LAW = "steering_law"   # the locally optimal law held per stage (the baseline)
    SUN_FACING = "sun_facing"       # cone 0 everywhere (the alpha = 0)


@dataclass(frozen=True)
class SailCase:
    """A loaded sail case, normalised (``units.earth_sail_units``; module docstring).

    Attributes:
        x0: (6,) initial [p, f, g, h, k, t] (t = 0 at ``epoch_s``); t_start: its true
            longitude [rad].
        epoch_s: the start, seconds past J2000.
        fixed_sun: (3,) the Sun's normalised position when held fixed, else None.
        eclipse_width_km: the shadow's smoothing width, or None for no eclipses.
    """

    name: str
    description: str
    units: Units
    beta: float
    epoch_s: float
    x0: np.ndarray
    t_start: float
    revolutions: float
    stages_per_revolution: int
    steering: SailSteering = SailSteering.FREE
    fixed_sun: np.ndarray | None = None
    eclipse_width_km: float | None = None
    perturbations: frozenset = frozenset()
    source: str = ""
    system: str = field(default=SYSTEM, init=False)

    @property
    def stages(self) -> int:
        return max(1, round(self.revolutions * self.stages_per_revolution))

    @property
    def nu(self) -> int:
        return 2 if self.steering is SailSteering.FREE else 1

    @property
    def a0_km(self) -> float:
        return float(_semi_major_axis(self.x0) * self.units.lu_km)

    def sun_position(self, t):
        """The Sun's normalised ECI position (a list of 3) at normalised time t."""
        if self.fixed_sun is not None:
            return [float(c) for c in self.fixed_sun]
        scale = 1.0 / self.units.lu_km
        return [c * scale for c in ephemeris.sun_position_km(self.epoch_s + t * self.units.tu_s)]

    def moon_position(self, t):
        scale = 1.0 / self.units.lu_km
        return [c * scale for c in ephemeris.moon_position_km(self.epoch_s + t * self.units.tu_s)]

    def sail_model(self) -> Sail:
        u = self.units
        width = self.eclipse_width_km
        return Sail(self.beta * MU_SUN_KM3_S2 * u.tu_s ** 2 / u.lu_km ** 3, self.sun_position,
                    shadow_radius=None if width is None else SAIL_EARTH_RADIUS_KM / u.lu_km,
                    shadow_width=0.0 if width is None else width / u.lu_km,
                    clock=None if self.steering is SailSteering.FREE else 0.5 * math.pi)

    def forces(self) -> EarthForces:
        u = self.units
        zonals = tuple(j if p in self.perturbations else 0.0 for j, p in zip(
            SAIL_EARTH_ZONALS, (SailPerturbation.J2, SailPerturbation.J3, SailPerturbation.J4)))
        bodies = []
        km3_s2 = u.tu_s ** 2 / u.lu_km ** 3
        if SailPerturbation.MOON in self.perturbations:
            bodies.append((MU_MOON_KM3_S2 * km3_s2, self.moon_position))
        if SailPerturbation.SUN in self.perturbations:
            bodies.append((MU_SUN_KM3_S2 * km3_s2, self.sun_position))
        return EarthForces(u.gm, SAIL_EARTH_RADIUS_KM / u.lu_km, zonals, tuple(bodies))

    def rhs(self):
        return sail_sundman(self.units.gm, self.sail_model(), self.forces())

    def problem(self, stages: int | None = None) -> Problem:
        """The optimal-control problem: maximise the final osculating semi-major axis, J =
        a0 / a_N - 1 (dimensionless, no constant offset: ~ -da / a0), no constraints."""
        N = self.stages if stages is None else int(stages)
        if N < 1:
            raise DaddyError(f"stages must be >= 1, got {N}")
        rhs = self.rhs()
        a0 = _semi_major_axis(self.x0)

        def stage_cost(x, u, dt, hom=(0.0, 1.0)):
            return 0.0 * u[0]

        def terminal_cost(x, x_target):
            return a0 * (1.0 - x[1] * x[1] - x[2] * x[2]) / x[0] - 1.0

        span = 2.0 * math.pi * self.revolutions
        return Problem(name=self.name, x0=self.x0.copy(), x_target=self.x0.copy(),
                       stage_dt=np.full(N, span / N), step=flow_step(rhs),
                       stage_cost=stage_cost, terminal_cost=terminal_cost, nu=self.nu,
                       units=self.units, rhs=rhs, t_start=self.t_start, time_index=5)

    # ------------------------------------------------------------------ results in km
    def cartesian(self, X: np.ndarray, L: np.ndarray) -> np.ndarray:
        """(K, 6) normalised ECI position and velocity of states X (K, 6) at true longitudes L."""
        return models.mee_to_cartesian(X[:, :5].T, L, self.units.gm).T

    def delta_a_km(self, X: np.ndarray, L_end: float) -> dict:
        """The final semi-major axis gain [km]: ``osculating`` (the two-body energy, the
        objective) and, with J2 among the perturbations, ``j2_energy`` (the energy with the J2
        potential, -gm / 2E: free of J2's periodic swing of the osculating a)."""
        lu = self.units.lu_km
        gains = {"osculating": float((_semi_major_axis(X[-1]) - _semi_major_axis(X[0])) * lu)}
        if SailPerturbation.J2 not in self.perturbations:
            return gains
        ends = self.cartesian(X[[0, -1]], np.array([self.t_start, L_end]))
        a_j2 = [_j2_energy_a(rv, self.units.gm, SAIL_EARTH_ZONALS[0],
                             SAIL_EARTH_RADIUS_KM / lu) for rv in ends]
        gains["j2_energy"] = float((a_j2[1] - a_j2[0]) * lu)
        return gains


# ------------------------------------------------------------------------- steering law
def law_controls(case: SailCase, x: np.ndarray, L: float) -> np.ndarray:
    """(nu,) the locally optimal steering law's controls at state x (6,), true longitude L: the
    normal in the plane of the sunlight and the velocity, at the cone angle that maximises the
    acceleration along the velocity (``sail.locally_optimal_cone``: the instantaneous rate of
    energy gain), held below ``LAW_MAX_CONE_RAD``. In-plane steering takes the velocity's
    component in the plane of its fixed clock angle."""
    rv = models.mee_to_cartesian(x[:5], L, case.units.gm)
    r_sun = np.asarray(case.sun_position(x[5]), float)
    s_hat = rv[:3] - r_sun
    s_hat /= np.linalg.norm(s_hat)
    v_hat = rv[3:] / np.linalg.norm(rv[3:])
    _, p, q = (np.asarray(a, float) for a in sail.sail_frame(s_hat))
    side = np.array([v_hat @ p, v_hat @ q])
    if case.steering is SailSteering.IN_PLANE:
        side[0] = 0.0
    norm = float(np.hypot(*side))
    if norm == 0.0:
        return np.zeros(case.nu)
    theta = math.atan2(norm, float(v_hat @ s_hat))
    tan_cone = math.tan(min(float(sail.locally_optimal_cone(theta)), LAW_MAX_CONE_RAD))
    w = tan_cone * side / norm
    return w if case.steering is SailSteering.FREE else w[1:]


def steering_law(case: SailCase, problem: Problem) -> tuple[np.ndarray, np.ndarray]:
    """The law held per stage (evaluated at each stage's start, constant over the stage),
    flown with the problem's own stage flow: (X (N+1, 6), U (N, nu))."""
    N = problem.N
    X = np.empty((N + 1, problem.nx))
    U = np.empty((N, problem.nu))
    X[0] = problem.x0
    L = problem.stage_t0
    for k in range(N):
        U[k] = law_controls(case, X[k], float(L[k]))
        X[k + 1] = problem.stage_flow(X[k], U[k], k)
    return X, U


def continuous_law(case: SailCase, rtol: float = 1e-11) -> np.ndarray:
    """(6,) the final state of the steering law flown continuously (re-evaluated at every
    integrator step, DOP853): the law's own optimum-free bound on what a stage-held law loses."""
    from scipy.integrate import solve_ivp   # (importing the catalogue keeps scipy.integrate out)
    rhs = case.rhs()

    def f(L, x):
        return np.asarray(rhs(L, x, law_controls(case, x, L)), float)

    span = (case.t_start, case.t_start + 2.0 * math.pi * case.revolutions)
    flown = solve_ivp(f, span, case.x0, method="DOP853", rtol=rtol, atol=rtol * 1e-2)
    if not flown.success:
        raise DaddyError(f"the continuous steering law's propagation failed: {flown.message}")
    return flown.y[:, -1]


# --------------------------------------------------------------------------------- solve
def sail_options(**sections) -> SolverOptions:
    """The sail solve's options: the trust region (the many-revolution paper's, sec. III.F)
    and DDP's relative-decrease stop at ``SAIL_TOL_DDP`` on top of ``SolverOptions``' defaults;
    ``sections`` as SolverOptions takes them."""
    ddp = {"globalization": Globalization.TRUST_REGION.value, "tol": SAIL_TOL_DDP,
           **sections.pop("ddp", {})}
    return SolverOptions(ddp=ddp, **sections)


@dataclass
class SailResult:
    """A sail solve: the DDP ``solution``, its semi-major axis gains (``SailCase.delta_a_km``)
    and those of the steering law held per stage (its states ``law_X`` (N+1, 6)) next to them."""

    case: SailCase
    solution: Solution
    delta_a_km: dict
    law_delta_a_km: dict
    guess: SailGuess
    law_X: np.ndarray = field(repr=False, default=None)

    def report(self) -> dict:
        c = self.case
        return {"case": c.name, "beta": c.beta, "revolutions": c.revolutions,
                "stages": c.stages, "steering": c.steering.value, "guess": self.guess.value,
                "eclipse_width_km": c.eclipse_width_km,
                "perturbations": sorted(p.value for p in c.perturbations),
                "a0_km": c.a0_km, "delta_a_km": self.delta_a_km,
                "steering_law_delta_a_km": self.law_delta_a_km,
                "converged": self.solution.converged, "reason": self.solution.reason}


def solve_sail(case: SailCase, guess: SailGuess = SailGuess.STEERING_LAW,
               options: SolverOptions | None = None, progress=None,
               method: Method | str = SAIL_METHOD) -> SailResult:
    """Maximise the case's final semi-major axis from ``guess``; the steering law held per
    stage is flown either way, as the baseline."""
    problem = case.problem()
    X_law, U_law = steering_law(case, problem)
    L_end = float(problem.t_start + np.sum(problem.stage_dt))
    U0 = U_law if guess is SailGuess.STEERING_LAW else np.zeros_like(U_law)
    t0 = time.process_time()
    sol = solve(problem, U0, method=method, fuel_optimal=False, polish=True,
                options=options or sail_options(), case_name=case.name, progress=progress)
    sol.runtime_s.setdefault("cpu", time.process_time() - t0)
    return SailResult(case, sol, case.delta_a_km(sol.X, L_end),
                      case.delta_a_km(X_law, L_end), guess, X_law)


# ---------------------------------------------------------------------------- case files
def sail_case_from_dict(d: dict) -> SailCase:
    """Validate and normalise a sail case description (module docstring); a DaddyError naming
    the field otherwise."""
    unknown = sorted(set(d) - set(SAIL_KEYS))
    if unknown:
        raise DaddyError(f"case field {unknown[0]!r} is unknown for a sail case (known: "
                         f"{', '.join(SAIL_KEYS)})")
    for key in ("name", "x0", "beta", "epoch", "revolutions", "stages_per_revolution"):
        if key not in d:
            raise DaddyError(f"case field {key!r} is missing")
    units = earth_sail_units()
    beta = d["beta"]
    if not (isinstance(beta, (int, float)) and beta > 0 and math.isfinite(beta)):
        raise DaddyError(f"case field 'beta' (the lightness number) must be a positive number, "
                         f"got {beta!r}")
    epoch_s = _epoch_seconds(d["epoch"])
    x0, L0 = _initial_orbit(d["x0"], units)
    revs = d["revolutions"]
    if not (isinstance(revs, (int, float)) and revs > 0 and math.isfinite(revs)):
        raise DaddyError(f"case field 'revolutions' must be a positive number, got {revs!r}")
    spr = d["stages_per_revolution"]
    if not (isinstance(spr, int) and spr >= 4):
        raise DaddyError(f"case field 'stages_per_revolution' must be an integer >= 4, got "
                         f"{spr!r}")
    try:
        steering = SailSteering(d.get("steering", "free"))
    except ValueError:
        raise DaddyError(f"case field 'steering' must be one of "
                         f"{[s.value for s in SailSteering]}, got {d.get('steering')!r}") from None
    known = [p.value for p in SailPerturbation]
    names = d.get("perturbations", [])
    if not isinstance(names, list) or any(n not in known for n in names):
        raise DaddyError(f"case field 'perturbations' must be a list of {known}, got {names!r}")
    return SailCase(name=str(d["name"]), description=str(d.get("description", "")),
                    units=units, beta=float(beta), epoch_s=epoch_s,
                    x0=np.append(x0, 0.0), t_start=L0, revolutions=float(revs),
                    stages_per_revolution=spr, steering=steering,
                    fixed_sun=_fixed_sun(d.get("sun", "ephemeris"), units),
                    eclipse_width_km=_eclipse_width(d.get("eclipse")),
                    perturbations=frozenset(SailPerturbation(n) for n in names),
                    source=str(d.get("source", "")))


def _epoch_seconds(text) -> float:
    try:
        t = datetime.fromisoformat(str(text))
    except ValueError:
        raise DaddyError(f"case field 'epoch' must be an ISO 8601 date-time (UTC), got "
                         f"{text!r}") from None
    t = t if t.tzinfo else t.replace(tzinfo=timezone.utc)
    seconds = (t - J2000).total_seconds()
    ephemeris.check_epoch(seconds, "case field 'epoch'")
    return seconds


def _initial_orbit(x0, units: Units) -> tuple[np.ndarray, float]:
    try:
        x = np.asarray(x0, dtype=float)
    except (TypeError, ValueError):
        x = None
    if x is None or x.shape != (6,) or not np.all(np.isfinite(x)):
        raise DaddyError(f"case field 'x0' must be 6 finite numbers [a km, e, i deg, RAAN deg, "
                         f"argp deg, true anomaly deg], got {x0!r}")
    a_km, e, i = x[:3]
    if not 0 <= e < 1:
        raise DaddyError(f"case field 'x0[1]' (e) must be in [0, 1), got {e!r}")
    if not 0 <= i < 180:
        raise DaddyError(f"case field 'x0[2]' (i, deg) must be in [0, 180), got {i!r}")
    if not a_km * (1 - e) > SAIL_EARTH_RADIUS_KM:
        raise DaddyError(f"case field 'x0': the perigee radius a (1 - e) = {a_km * (1 - e):.1f} km "
                         f"is inside the Earth ({SAIL_EARTH_RADIUS_KM} km)")
    deg = math.pi / 180.0
    mee, L = models.keplerian_to_mee(a_km / units.lu_km, e, i * deg, x[3] * deg, x[4] * deg,
                                     x[5] * deg)
    return np.asarray(mee, float), float(L)


def _fixed_sun(sun, units: Units) -> np.ndarray | None:
    if sun == "ephemeris":
        return None
    if not (isinstance(sun, dict) and set(sun) == {"fixed_direction"}):
        raise DaddyError("case field 'sun' must be \"ephemeris\" or {\"fixed_direction\": "
                         f"[x, y, z]}}, got {sun!r}")
    try:
        d = np.asarray(sun["fixed_direction"], dtype=float)
    except (TypeError, ValueError):
        d = np.zeros(0)
    if d.shape != (3,) or not (np.all(np.isfinite(d)) and np.linalg.norm(d) > 0):
        raise DaddyError(f"case field 'sun.fixed_direction' must be 3 finite numbers, not all "
                         f"zero, got {sun['fixed_direction']!r}")
    return d / np.linalg.norm(d) * (AU_KM / units.lu_km)


def _eclipse_width(eclipse) -> float | None:
    if eclipse is None:
        return None
    if not isinstance(eclipse, dict):
        raise DaddyError(f"case field 'eclipse' must be an object {{\"shadow\": \"cylinder\", "
                         f"\"width_km\": W}}, got {eclipse!r}")
    unknown = sorted(set(eclipse) - set(ECLIPSE_KEYS))
    if unknown:
        raise DaddyError(f"case field 'eclipse.{unknown[0]}' is unknown (known: "
                         f"{', '.join(ECLIPSE_KEYS)})")
    if eclipse.get("shadow", "cylinder") != "cylinder":
        raise DaddyError(f"case field 'eclipse.shadow' must be \"cylinder\" (the smoothed "
                         f"cylindrical shadow), got {eclipse.get('shadow')!r}")
    w = eclipse.get("width_km")
    if not (isinstance(w, (int, float)) and w > 0 and math.isfinite(w)):
        raise DaddyError(f"case field 'eclipse.width_km' must be a positive number, got {w!r}")
    return float(w)


def _semi_major_axis(x) -> float:
    return x[0] / (1.0 - x[1] * x[1] - x[2] * x[2])


def _j2_energy_a(rv: np.ndarray, gm: float, j2: float, radius: float) -> float:
    """-gm / 2E with E = v^2 / 2 - gm / r + gm J2 R^2 P2(sin phi) / r^3 (the zonal J2 term of
    the potential), phi the latitude."""
    r = float(np.linalg.norm(rv[:3]))
    s = rv[2] / r
    energy = 0.5 * float(rv[3:] @ rv[3:]) - gm / r + gm * j2 * radius ** 2 * 0.5 * (3 * s * s - 1) / r ** 3
    return -gm / (2.0 * energy)


# -------------------------------------------------------------------------------- outputs
def sail_angles(case: SailCase, U: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N,) cone and (N,) clock angles [deg] of controls U (N, nu) (``sail.cone_clock``; an
    in-plane sail's cone signed by its side, its clock 90 deg)."""
    if case.steering is SailSteering.FREE:
        cone, clock = sail.cone_clock(U[:, 0], U[:, 1])
        return np.degrees(cone), np.degrees(clock)
    return np.degrees(np.arctan(U[:, 0])), np.full(len(U), 90.0)


def sunlight_at_nodes(case: SailCase, X: np.ndarray, L: np.ndarray) -> np.ndarray:
    """(K,) the smoothed sunlight fraction at states X (K, 6), true longitudes L (1 without
    eclipses)."""
    if case.eclipse_width_km is None:
        return np.ones(len(X))
    model = case.sail_model()
    rv = case.cartesian(X, L)
    return np.array([float(sail.sunlight(r[:3], case.sun_position(x[5]), model.shadow_radius,
                                         model.shadow_width)) for r, x in zip(rv, X)])


def write_sail_csv(result: SailResult, path) -> None:
    """The trajectory as CSV: node k, time [s], ECI position [m] and velocity [m/s], the
    Keplerian elements (``trajectory_output.earth_elements``), the sunlight fraction at the
    node, and the sail's cone and clock angles on stage k [deg] (empty at the last node)."""
    sol, case = result.solution, result.case
    L = trajectory_output.node_longitudes(sol)
    cone, clock = sail_angles(case, sol.U)
    cols = np.column_stack([np.arange(sol.N + 1), trajectory_output.node_times_s(sol),
                            trajectory_output.earth_cartesian_si(sol),
                            trajectory_output.earth_elements(sol),
                            sunlight_at_nodes(case, sol.X, L),
                            np.append(cone, np.nan), np.append(clock, np.nan)])
    header = ["k", "time_s", "x_m", "y_m", "z_m", "vx_m_s", "vy_m_s", "vz_m_s", "a_km", "e",
              "i_deg", "raan_deg", "argp_deg", "true_longitude_deg", "sunlight", "cone_deg",
              "clock_deg"]
    trajectory_output.write_rows(header, cols, path)
