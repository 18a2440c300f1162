"""The warm-start shift: the remaining problem of a plan in flight, from a new state at a new
time, and the arrival phase's stages and terminal constraints. ROS-free.

Stages already executed are dropped and the time to go is kept: the first remaining stage is
shortened to end on the plan's stage boundary, or merged into the next when shorter than
MIN_STAGE_FRACTION of a stage, except in an arrival plan (boundaries and lengths on the
scenario's grid, ``frames``: time, or the true longitude of Earth-centred scenarios, whose
time to go is then the arrival-time constraint's). Fewer than MIN_STAGES_LEFT stages are split
into that many (``split_stages``), so that enough controls remain for the terminal
constraints: the arrival phase, which every re-plan of an arrival plan stays in
(``Plan.arrival``), whatever number of stages it leaves.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from daddy_core.da import functions as dm
from daddy_core.dynamics.units import Units
from daddy_core.errors import DaddyError
from daddy_core.problem import Problem
from daddy_core.solver import WarmStart

from .checks import InputRejected
from .frames import CartesianGrid, LongitudeGrid
from .plan import TIME_TOLERANCE_S, Code, Plan

# a first remaining stage shorter than this fraction of a nominal stage is merged into the next
MIN_STAGE_FRACTION = 0.25
MIN_STAGES_LEFT = 4  # a re-plan keeps at least this many stages to the end (split)
ARRIVAL_SPEED_SCALE_M_S = 0.01  # a position one arrival tolerance off weighs as 1 cm/s


@dataclass
class Shifted:
    """The remaining problem and what the plan lends its solve.

    Attributes:
        problem: from the new state, with the remaining stages (normalised).
        start: the plan's controls, duals, rho and stage maps for those stages (None without
            a plan: a cold solve).
        arrival: the arrival phase (stages split, the position aimed within the tolerance).
    """

    problem: Problem
    start: WarmStart | None = None
    arrival: bool = False


def shift_plan(base: Problem, plan: Plan | None, t_s: float, x_cart: np.ndarray,
               grid: CartesianGrid | LongitudeGrid, units: Units,
               arrival_tolerance_m: float = 0.0) -> Shifted:
    """The remaining problem of ``plan`` (stages of ``base``) from the estimate x_cart = [r,
    v, m] (normalised) at time t_s (see the module docstring), cut where ``grid`` places the
    estimate (time, or true longitude for Earth-centred scenarios); without a plan, the full
    problem from it. In the arrival phase the terminal position is aimed within
    ``arrival_tolerance_m`` of the target (``arrival_constraints``)."""
    x0, s0 = grid.state(x_cart, t_s, plan)
    if plan is None:
        return Shifted(base.with_x0(x0, t_start=grid.problem_grid(base.stage_dt, s0)[1]))
    bounds, lengths = grid.ends(plan)                              # stage ends on the grid
    tolerance = TIME_TOLERANCE_S * float(np.median(lengths / plan.stage_dt_s))
    k0 = int(np.searchsorted(bounds, s0 + tolerance, side="right"))
    if k0 >= len(lengths) or t_s + TIME_TOLERANCE_S >= plan.end_s:
        raise InputRejected("the plan has ended: no stage remains after header.stamp",
                            Code.PLAN_ENDED)
    first = bounds[k0] - s0
    dts = lengths[k0:].copy()
    U = plan.solution.U[k0:].copy()
    lam = np.asarray(plan.solution.duals.get("lam", []), float)
    lam = lam[:, k0:] if lam.ndim == 2 and lam.shape[1] == len(plan.stage_dt_s) else None
    nominal = float(np.median(lengths))
    maps = plan.solution.stage_maps
    nodes = plan.solution.X[k0:].copy()   # the plan's states at the remaining stage ends
    # (an arrival plan keeps a short first stage: merged, it would fly the next one's thrust)
    if first < MIN_STAGE_FRACTION * nominal and len(dts) > 1 and not plan.arrival:
        nodes = nodes[1:]
        dts = dts[1:]
        dts[0] += first
        U = U[1:]
        lam = None if lam is None else lam[:, 1:]
        maps = None if maps is None else maps.tail(k0 + 1, first_valid=False)
    else:
        maps = None if maps is None else maps.tail(
            k0, first_valid=abs(first - dts[0]) <= tolerance)
        dts[0] = first
    arrival = len(dts) < MIN_STAGES_LEFT or plan.arrival
    if arrival:
        # split what is left into MIN_STAGES_LEFT stages flying the plan's thrust
        dts, idx = split_stages(dts, MIN_STAGES_LEFT)
        U = U[idx]
        maps = nodes = None
        lam = None if lam is None else lam[:, idx]
    duals = None if lam is None else {"lam": lam, "lam_t": plan.solution.duals.get("lam_t", [])}
    problem = base.with_x0(x0, *grid.problem_grid(dts, s0))
    if arrival:
        problem = arrival_constraints(problem, arrival_tolerance_m, units, U)
    if nodes is not None:
        nodes[0] = problem.x0
    return Shifted(problem, WarmStart(U, duals, plan.solution.rho, maps, nodes), arrival)


def split_stages(dts: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """At least n stages spanning the stages dts (K,): the longest stage (the first of those
    equal to round-off) halved until there are n. Returns the new lengths and, for each, the
    index of the stage it lies in, so that the plan's controls U[idx] fly the same schedule:
    the re-plan starts from the plan in force exactly, whatever its thrust does between the
    stages."""
    dts, idx = list(np.asarray(dts, float)), list(range(len(dts)))
    while len(dts) < n:
        k = int(np.argmax(np.array(dts) >= (1.0 - 1e-9) * max(dts)))   # equal to round-off
        dts[k:k + 1] = [0.5 * dts[k]] * 2
        idx[k:k + 1] = [idx[k]] * 2
    return np.array(dts), np.array(idx)


def arrival_constraints(problem: Problem, tolerance_m: float, units: Units,
                        U: np.ndarray) -> Problem:
    """The arrival phase's terminal constraints (with ``tolerance_m`` > 0): the velocity exact,
    the position exactly at the aim point (``arrival_aim``): where the plan's controls U (N, nu)
    flown from the problem's start arrive, brought into the tolerance's ball about the target.
    In the last hours a position error of the order of the navigation error cannot be removed
    at any acceptable cost, and demanding it makes the problem infeasible and the best-effort
    plans trade velocity for it; a position merely kept within the ball leaves the plan free
    to drift inside it towards whatever saves a fraction of a gram, so the arrival point would
    depend on how often the node re-plans (docs/design-notes.md, the arrival aim point). The
    aim point is unique and unbiased: the re-plans null the velocity and leave a position
    error inside the tolerance alone.

    The position rows are (r - r_aim) s / tolerance with s = 1 cm/s in normalised speed units:
    a position one tolerance off weighs as much as a 1 cm/s velocity miss wherever terminal
    violations are compared (solver tolerances, the planner's best-effort choice).
    """
    gt, _ = problem.terminal_constraints(problem.x_target)
    if not tolerance_m or gt is None or gt.shape != (6,) or problem.time_index is not None:
        return problem   # (an Earth-centred arrival is an orbit, not a position)
    R = float(units.length(tolerance_m))
    weight = arrival_weight(units, R)
    aim = arrival_aim(problem, U, R)

    def arrival_rows(x, xt):
        return dm.concatenate([(x[:3] - aim) * weight, x[3:6] - xt[3:6]])

    return replace(problem, g_teq=arrival_rows)


def arrival_weight(units: Units, radius: float) -> float:
    """The weight of the arrival phase's position rows (``arrival_constraints``): 1 cm/s in
    normalised speed units per ``radius`` (the tolerance, normalised length), per normalised
    length."""
    return float(units.speed(ARRIVAL_SPEED_SCALE_M_S)) / radius


def arrival_aim(problem: Problem, U: np.ndarray, radius: float) -> np.ndarray:
    """(3,) the arrival phase's aim point [normalised]: the position where the controls U (N,
    nu) flown from the problem's start arrive, radially projected onto the ball of ``radius``
    about the target's position when outside it (the target itself if the flight does not
    stay finite, or its integration fails)."""
    target = np.asarray(problem.x_target[:3], float)
    try:
        with np.errstate(all="ignore"):
            end = problem.rollout(np.asarray(U, float))[-1, :3]
    except (ArithmeticError, DaddyError):
        return target
    if not np.all(np.isfinite(end)):
        return target
    off = end - target
    dist = float(np.linalg.norm(off))
    return end if dist <= radius else target + off * (radius / dist)
