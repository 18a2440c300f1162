"""The paper's optimal-control problems (eq. 14, 17-21) built from a catalogue ``Case``: its
dynamics, the pseudo-Huber stage cost of the fuel homotopy, the terminal cost, the thrust and
dry-mass bounds, and the normalisation units."""
from __future__ import annotations

import math
from dataclasses import dataclass

from ..da import functions as dm
from ..errors import DaddyError
from ..fuel import FuelStageCost, pseudo_huber_stage_cost
from ..problem import Problem, flow_step
from . import free_time
from .cases import DOUBLE_INTEGRATOR_TERMINAL, Case
from .phased_cases import phased_problem


def low_thrust_costs(residual, u_max: float, dt_avg: float, stage_gain: float,
                     terminal_gain: float):
    """Paper/reference-code costs for low-thrust transfers.

    Stage cost (eq. 14 with the reference's scaling): ``fuel.pseudo_huber_stage_cost`` with
    w = u dt / (dt_avg u_max), h = 0 energy-optimal, delta -> 0 fuel-optimal.
    Terminal cost: terminal_gain / 2 * |residual(x, x_t)|^2, the residual of the terminal
    equality constraints (e.g. the position and velocity miss).
    """
    stage_cost = pseudo_huber_stage_cost(u_max, dt_avg, stage_gain)

    def terminal_cost(x, xt):
        e = residual(x, xt)
        return dm.dot(e, e) * (0.5 * terminal_gain)

    return stage_cost, terminal_cost


CARTESIAN_LABELS = ("x", "y", "z", "vx", "vy", "vz")
ORBIT_LABELS = ("p", "f", "g", "h", "k", "arrival time")


def _cartesian_miss(x, xt):
    """Position and velocity miss (6,) of a Cartesian state."""
    return x[:6] - xt[:6]


def _orbit_miss(x, xt):
    """The miss of an Earth-centred arrival [p, f, g, h, k, t] (Sundman-transformed state): the
    orbit's elements and the time of flight as a fraction of it (arrival anywhere on the
    target orbit at t = ToF)."""
    return dm.stack([x[0] - xt[0], x[1] - xt[1], x[2] - xt[2], x[3] - xt[3], x[4] - xt[4],
                     (x[5] - xt[5]) * (1.0 / xt[5])])


@dataclass(frozen=True)
class SundmanStageCost(FuelStageCost):
    """A fuel stage cost written for stage durations, on stages of true longitude: the duration
    of a stage of angle dL is taken as dL p^(3/2) / sqrt(gm), exact on a circular orbit (dt/dL =
    r^2 / sqrt(gm p)); on an eccentric one the weighting is off by the factor (1 + e cos nu)^-2
    of the stage, which leaves the dynamics, the mass and the constraints exact and weights
    thrust along the orbit slightly differently than propellant does."""

    cost: FuelStageCost
    gm: float

    def _duration(self, x, dL):
        return dL * (x[0] * dm.sqrt(x[0]) * self.gm ** -0.5)

    def __call__(self, x, u, dL, hom=(0.0, 1.0)):
        return self.cost(x, u, self._duration(x, dL), hom)

    def propellant(self, x, thrust, dL):
        return self.cost.propellant(x, thrust, self._duration(x, dL))


def sundman_stage_cost(stage_cost: FuelStageCost, gm: float) -> SundmanStageCost:
    """``stage_cost`` on stages of true longitude (``SundmanStageCost``)."""
    return SundmanStageCost(stage_cost, float(gm))


def keep_out(units, r_min_km: float):
    """g_path(x, u) = r_min - |r - r_body| <= 0 [LU]: a keep-out sphere of radius r_min_km
    around the Moon (Earth-Moon CR3BP, at (1 - mu, 0, 0)) or the Sun (heliocentric two-body, at
    the origin), for ``Problem.g_path``: held along the whole trajectory, its margin in LU."""
    if not (isinstance(r_min_km, (int, float)) and math.isfinite(r_min_km) and r_min_km > 0):
        raise DaddyError(f"r_min_km must be a positive distance in km, got {r_min_km!r}")
    centre = {"earth_moon_cr3bp": 1.0 - units.gm, "sun_two_body": 0.0}.get(units.name)
    if centre is None:
        raise DaddyError(f"r_min_km: no keep-out body for the {units.name} system (the Moon "
                         "in earth_moon_cr3bp, the Sun in sun_two_body)")
    r_min = r_min_km / units.lu_km

    def g_path(x, u):
        dx = x[0] - centre
        return dm.stack([r_min - dm.sqrt(dx * dx + x[1] * x[1] + x[2] * x[2])])
    return g_path


def problem_from_case(case: Case, integrator: str = "rk78", integrator_tol: float | None = None,
                      stages: int | None = None, max_thrust_n: float | None = None,
                      r_min_km: float | None = None, tof_window=None,
                      revolutions_window=None) -> Problem:
    """Build the paper's problem for a catalogue ``Case`` (costs, constraints, units).

    ``max_thrust_n`` overrides the spacecraft's thrust bound (e.g. a derated bound that leaves
    guidance a control margin); the cost scaling keeps the spacecraft's rating. ``r_min_km``
    (or the case's ``problem.r_min_km``; the argument wins) keeps the whole trajectory that
    far from the Moon (Earth-Moon CR3BP) or the Sun (heliocentric): ``keep_out``.
    ``tof_window`` [lower, upper] (or the case's ``problem.tof_window``; the argument wins), in
    the case's time unit: the time of flight free in it, the target moving on to the arrival
    (``free_time``). ``revolutions_window`` [lower, upper] (or ``problem.revolutions_window``):
    an Earth-centred case's arrival angle free in it, in revolutions.
    """
    window = free_time.window_of(case, tof_window)
    angles = free_time.revolutions_window_of(case, revolutions_window)
    s = case.problem
    dt = case.stage_lengths(stages)
    N = dt.size
    if case.system == "double_integrator":
        from ..dynamics.models import double_integrator_step as step
        rows = DOUBLE_INTEGRATOR_TERMINAL[s.get("terminal", "position")]

        def stage_cost(x, u, d, hom=(0.0, 1.0)):
            return u[0] * u[0] + u[1] * u[1] + u[2] * u[2]

        def miss(x, xt):   # the position, or every component (problem.terminal)
            return x[:rows] - xt[:rows]

        def terminal_cost(x, xt):
            e = miss(x, xt)
            return dm.dot(e, e)

        if case.phases:
            if window is not None or stages is not None:
                raise DaddyError(f"case {case.name!r} has phases: each phase's stages are in "
                                 "its case file, and a free time of flight is not built for "
                                 "phases (tof_window, stages)")
            return phased_problem(case, stage_cost, terminal_cost, miss)
        return _free(case, Problem(
            name=case.name, x0=case.x0, x_target=case.x_target, stage_dt=dt, step=step,
            stage_cost=stage_cost, terminal_cost=terminal_cost, g_teq=miss,
            units=case.units), window)

    sc = case.spacecraft
    units = case.units
    u_max = float(units.thrust(sc.max_thrust_n))
    u_bound = u_max if max_thrust_n is None else float(units.thrust(max_thrust_n))
    if not u_bound > 0:
        raise DaddyError(f"max_thrust_n must be positive, got {max_thrust_n!r}")
    m_dry = sc.dry_mass_kg / units.mu_kg
    miss = _orbit_miss if case.staged_in_angle else _cartesian_miss
    stage_cost, terminal_cost = low_thrust_costs(
        miss, u_max, case.tof / N, s.get("stage_cost_gain", 1e-2), s.get("terminal_cost_gain", 1e4))
    if case.staged_in_angle:
        stage_cost = sundman_stage_cost(stage_cost, units.gm)
    rhs = case.rhs()
    tol = integrator_tol if integrator_tol is not None else s.get("integrator_tol", 1e-13)

    def g_ineq(x, u, d):
        # thrust bound |u|^2 / u_max^2 - 1 <= 0 and dry mass m_dry - m <= 0 (paper eq. 18)
        return dm.stack([(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]) * (1.0 / u_bound ** 2) - 1.0,
                         m_dry - x[6]])

    r_min_km = s.get("r_min_km") if r_min_km is None else r_min_km
    g_path = None if r_min_km is None else keep_out(units, r_min_km)
    problem = Problem(
        name=case.name, x0=case.x0, x_target=case.x_target, stage_dt=dt, g_path=g_path,
        step=flow_step(rhs, integrator, tol), stage_cost=stage_cost, terminal_cost=terminal_cost,
        g_ineq=g_ineq, g_teq=miss, units=units, spacecraft=sc, u_max=u_bound, mass_index=6,
        rhs=rhs, t_start=case.t_start, time_index=5 if case.staged_in_angle else None,
        labels={"g_ineq": ("thrust bound", "dry mass"), "g_path": ("keep-out",),
                "g_teq": (ORBIT_LABELS if case.staged_in_angle else CARTESIAN_LABELS)})
    if angles is not None:
        if window is not None:
            raise DaddyError(f"{free_time.FIELD} and {free_time.REVOLUTIONS_FIELD}: an "
                             "Earth-centred case frees its arrival angle, not its time of "
                             "flight; give the revolutions window only")
        if stages is not None:
            raise DaddyError("stages: a free arrival angle keeps the case's stage count (the "
                             "stages stretch with the angle); give one or the other")
        return free_time.with_free_revolutions(case, problem, angles)
    return _free(case, problem, window)


def _free(case: Case, problem: Problem, window) -> Problem:
    """``problem``, its time of flight free in ``window`` where one is set."""
    return problem if window is None else free_time.with_free_tof(case, problem, window)
