"""ROS-free guidance: re-optimise the plan in force from a state estimate, and keep the last
valid plan. The rclpy node (guidance_node.py) and the closed-loop demo both drive this class.

A re-plan: input checks (``checks``) -> the shift of the plan to the estimate's time
(``shift``) -> the solver options for that kind of solve (``replan_policy``) -> solve ->
assessment (``assessment``) -> the thrust-margin ladder while the target is out of reach ->
adopt the new plan or keep the last valid one (``plan``).

Times are seconds on the caller's clock (message stamps); states are SI in the problem's frame
(position m, velocity m/s), masses kg, thrust N.
"""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from daddy_core.catalogue import load_thrust_case, problem_from_case
from daddy_core.path_constraints import dense_margin
from daddy_core.errors import DaddyError
from daddy_core.problem import Problem
from daddy_core.solver import Solution, WarmStart, preload, solve
from daddy_core.solver.deadline import CancelFlag, Deadline
from daddy_core.solver.stage_maps import StageMaps, expand_dynamics

from .assessment import Assessment, assess
from .checks import EstimateChecks
from .config import PlannerConfig
from .frames import grid_of
from .plan import Code, Level, Plan, ReplanOutcome, read_plan_file, write_plan_file
from .replan_policy import LADDER_MIN_GAIN, ReplanPolicy, lowest_rung, margin_ratings
from .shift import Shifted, shift_plan


# the settings the solver options of each kind of re-plan are made of (``ReplanPolicy.of``)
POLICY_SETTINGS = ("tol_aul", "tol_newton", "time_budget_s", "polish", "restore_first")

# a solve started with less than this left of the re-plan's budget gets this much (the
# solver's own clock needs a positive budget; a re-plan may overrun by it)
MIN_SOLVE_BUDGET_S = 1e-3


@dataclass(frozen=True)
class _Run:
    """One re-plan's deadline (its budget and cancel flag), the solver's progress callback
    (or None) and the budget [s]."""

    deadline: Deadline
    progress: object
    budget_s: float


@dataclass
class _Attempt:
    """One solve and its assessment."""

    sol: Solution
    problem: Problem
    verdict: Assessment
    failed_rungs: tuple = ()   # "rung k: why" of ladder rungs that raised or were not tried


class GuidancePlanner:
    """Holds the scenario, the latest valid plan, and re-optimises on request (thread-safe).

    ``GuidancePlanner("earth_mars", thrust_margin=0)``: the scenario and any ``PlannerConfig``
    field by keyword (or a whole ``config``).
    """

    def __init__(self, scenario: str | None = None, config: PlannerConfig | None = None,
                 **overrides):
        if scenario is not None:
            overrides["scenario"] = scenario
        self.config = replace(config or PlannerConfig(), **overrides)
        cfg = self.config
        self.case = load_thrust_case(cfg.scenario)
        if self.case.spacecraft is None:
            raise DaddyError(f"scenario {cfg.scenario!r} has no spacecraft (mass) model for "
                             "guidance")
        self.units = self.case.units
        self.grid = grid_of(self.case)   # where an estimate lies on the stages (time or angle)
        self.rated_problems = self._ratings(cfg)
        self.base_problem = self.rated_problems[0]
        self.policy = ReplanPolicy.of(self.case, cfg)
        self.checks = EstimateChecks(self.case, cfg.staleness_s, cfg.mass_tolerance_kg)
        self._lock = threading.Lock()
        self._plan: Plan | None = None
        self._changes: dict = {}   # settings changed in flight, for the next re-plan
        preload()   # the first re-plan must not pay scipy's import (~0.5 s)

    def _ratings(self, cfg: PlannerConfig) -> list[Problem]:
        """The problem at each rung of the thrust-margin ladder, lowest rating first."""
        return [problem_from_case(self.case, stages=cfg.stages or None, max_thrust_n=rating,
                                  r_min_km=cfg.r_min_km or None)
                for rating in margin_ratings(self.case.spacecraft.max_thrust_n,
                                             cfg.thrust_margin)]

    @property
    def method(self) -> str:
        return self.config.method

    @property
    def time_budget_s(self) -> float:
        return self.config.time_budget_s

    def update(self, **changes) -> None:
        """Change settings in flight (``config``: the ``runtime`` parameters): the estimates'
        staleness test at once, the solver's settings and the thrust-margin ladder from the next
        re-plan on (the one running keeps its own). A DaddyError, and nothing changed, when the
        settings are not valid together."""
        with self._lock:
            replace(self.config, **self._changes, **changes)   # (validated now, applied later)
            self._changes = {**self._changes, **changes}
            if "staleness_s" in changes:
                self.checks.staleness_s = changes["staleness_s"]

    def changed_config(self) -> PlannerConfig:
        """The settings with the changes the next re-plan applies."""
        with self._lock:
            return replace(self.config, **self._changes)

    def _apply_changes(self) -> None:
        """(at the start of a re-plan) The settings changed since the last one."""
        with self._lock:
            changes, self._changes = self._changes, {}
        if not changes:
            return
        old, cfg = self.config, replace(self.config, **changes)
        if cfg.thrust_margin != old.thrust_margin:
            self.rated_problems = self._ratings(cfg)
            self.base_problem = self.rated_problems[0]
        if any(getattr(cfg, k) != getattr(old, k) for k in POLICY_SETTINGS):
            # (the warm homotopy step a loaded plan set is kept: ``load_plan``)
            self.policy = ReplanPolicy.of(self.case, cfg).with_warm(
                homotopy=self.policy.warm.homotopy)
        self.config = cfg

    # ------------------------------------------------------------------ plan access
    @property
    def plan(self) -> Plan | None:
        with self._lock:
            return self._plan

    def set_plan(self, plan: Plan) -> None:
        with self._lock:
            self._plan = plan

    def shift(self, plan: Plan | None, t_s: float, x_cart: np.ndarray) -> Shifted:
        """The remaining problem of ``plan`` from the Cartesian estimate x_cart = [r, v, m]
        (normalised) at time t_s."""
        return shift_plan(self.base_problem, plan, t_s, x_cart, self.grid, self.units,
                          self.config.arrival_tolerance_m)

    # ------------------------------------------------------------------ re-optimisation
    def replan(self, pos_m, vel_m_s, mass_kg, stamp_s: float, request_id: str = "",
               now_s: float | None = None, cold: bool = False,
               time_budget_s: float | None = None, cancel: CancelFlag | None = None,
               progress=None) -> ReplanOutcome:
        """Re-optimise from an estimate; store and return the new plan if it is valid.

        Never raises for solver trouble: a failed, non-finite or bound-violating result leaves
        the last valid plan in place and is reported as ERROR/WARN. Bad inputs raise
        InputRejected before anything is touched. time_budget_s: this re-plan's budget [s]
        (None: the configured one); cancel: a flag (``threading.Event``) that stops the solve
        within one iteration, the plan in force kept (Code.CANCELLED); progress: the solver's
        progress lines (``daddy_core.solver.progress.ProgressLine``).
        """
        x0 = self.checks.check_state(pos_m, vel_m_s, mass_kg, stamp_s, now_s)
        self._apply_changes()
        plan = None if cold else self.plan   # read once: another thread may adopt a plan
        shifted = self.shift(plan, stamp_s, x0)
        warm = shifted.start is not None
        start = shifted.start or WarmStart(self.case.cold_guess(shifted.problem.N))
        opts = self.policy.options(warm, arrival=shifted.arrival)
        # the current plan may already fly above the derating: start from the rung it was
        # solved on, or the lowest rating it keeps to, instead of failing on the bounds below
        rung = self._start_rung(plan, start.U) if warm else 0
        problem = self._rated(shifted.problem, rung)
        t0 = time.perf_counter()
        budget = self.time_budget_s if time_budget_s is None else time_budget_s
        # one budget for the whole re-plan, ladder included
        run = _Run(Deadline(t0 + budget, cancel), progress, budget)
        try:
            best = self._solve(problem, start, opts, run)
        except Exception as exc:  # a solver fault must never take the plan down
            return ReplanOutcome(False, Level.ERROR, f"solver raised {type(exc).__name__}: "
                                 f"{exc}", request_id, time.perf_counter() - t0, None,
                                 warm_start=warm, code=Code.SOLVER_FAILED)
        best = self._climb(best, rung, start.U, opts, run)
        if run.deadline.cancelled:
            return ReplanOutcome(False, Level.WARN, "cancelled: the plan in force is kept",
                                 request_id, time.perf_counter() - t0, None,
                                 best.sol.iterations, warm, Code.CANCELLED)
        return self._adopt(best, shifted.arrival, start.U, warm, stamp_s, request_id,
                           time.perf_counter() - t0, budget)

    def _solve(self, problem: Problem, start: WarmStart, opts, run: _Run) -> _Attempt:
        """Solve and assess; a polished result that is not safe (polishing an infeasible
        problem can push the thrust past its bound) falls back to the unpolished DDP result,
        which keeps the bound and minimises the terminal miss (time permitting)."""
        best = self._attempt(problem, start, opts, self.config.polish, run)
        if not best.verdict.safe and self.config.polish and run.deadline.left() > 0:
            U = best.verdict.U if np.all(np.isfinite(best.verdict.U)) else start.U
            best = self._attempt(problem, U, opts, False, run)
        return best

    def _attempt(self, problem: Problem, guess, opts, polish: bool, run: _Run) -> _Attempt:
        """One solve of ``problem`` from ``guess`` (controls or a WarmStart) in the time left
        of the re-plan ``run``, assessed."""
        left = run.deadline.left()
        opts = opts.with_(run=dict(time_budget_s=max(left, MIN_SOLVE_BUDGET_S)))
        sol = solve(problem, guess, method=self.method, fuel_optimal=None, polish=polish,
                    options=opts, case_name=self.case.name, progress=run.progress,
                    cancel=run.deadline.cancel)
        return _Attempt(sol, problem, assess(sol, problem, self._feasibility_tol))

    def _climb(self, best: _Attempt, rung: int, U_guess: np.ndarray, opts,
               run: _Run) -> _Attempt:
        """The thrust-margin ladder: while the target is out of reach, give up the next part
        of the margin (``replan_policy``), keeping a higher rung's result only where it is
        safe and misses less. Each rung solves in what is left of the re-plan's budget; when
        it is spent the ladder stops where it is (a re-plan answers within its budget, the
        next one climbs from the plan it stored)."""
        while not (best.verdict.safe and best.verdict.feasible) and \
                rung + 1 < len(self.rated_problems):
            if run.deadline.left() <= 0:
                best = replace(best, failed_rungs=best.failed_rungs + (
                    f"rung {rung + 1}: not tried, the {run.budget_s:.3g} s budget was "
                    "spent",))
                break
            rung += 1
            rated = self._rated(best.problem, rung)
            safe = best.verdict.safe
            try:
                trial = self._attempt(rated, best.verdict.U if safe else U_guess, opts,
                                      self.config.polish, run)
            except Exception as exc:  # noqa: BLE001  a solver fault on this rung: try the next
                best = replace(best, failed_rungs=best.failed_rungs + (
                    f"rung {rung}: {type(exc).__name__}: {exc}",))
                continue
            v = trial.verdict
            if v.safe and (v.feasible or not safe or v.miss < best.verdict.miss):
                # more thrust hardly reduced the miss: what is left is not a thrust deficit
                # (e.g. navigation error in the last minutes); stop climbing
                stalled = safe and not v.feasible and v.miss > LADDER_MIN_GAIN * best.verdict.miss
                best = replace(trial, failed_rungs=best.failed_rungs)
                if stalled:
                    break
        return best

    def _adopt(self, best: _Attempt, arrival: bool, U_guess: np.ndarray, warm: bool,
               stamp_s: float, request_id: str, dt: float, budget_s: float) -> ReplanOutcome:
        """Store the new plan if it may replace the one in force, and say why or why not."""
        sol, v = best.sol, best.verdict
        failed = (f" (thrust-margin ladder: {'; '.join(best.failed_rungs)})"
                  if best.failed_rungs else "")
        if not v.safe:
            return ReplanOutcome(False, Level.ERROR, v.reason + failed, request_id, dt, None,
                                 sol.iterations, warm, Code.UNSAFE_RESULT)
        if not v.feasible and warm:
            # a best-effort plan replaces the current one only if it is predicted to miss less
            old_miss = self.terminal_miss(best.problem, U_guess)
            if v.miss >= old_miss:
                return ReplanOutcome(False, Level.WARN, f"kept the current plan: {v.reason}, and "
                                     f"no better than flying it (miss {old_miss:.2e}){failed}",
                                     request_id, dt, None, sol.iterations, warm,
                                     Code.INFEASIBLE)
        # the controls as flown (saturated onto the bound), and their keep-out margin
        sol = replace(sol, U=v.U, min_path_margin=v.path_margin)
        plan = Plan.of(sol, v.X, stamp_s, self.units, best.problem.u_max, request_id, dt, warm,
                       arrival)
        self.set_plan(plan)
        level, reason, code = Level.OK, "re-optimised", Code.OK
        if not v.feasible:
            level, reason, code = (Level.WARN, f"best effort within the thrust bound: "
                                   f"{v.reason}{failed}", Code.INFEASIBLE)
        elif not sol.converged:
            level, reason, code = (Level.WARN, f"stored best feasible iterate: {sol.reason}",
                                   Code.NOT_CONVERGED)
        if dt > budget_s:
            level, code = Level.WARN, Code.BUDGET_EXCEEDED
            reason = (f"solve took {dt:.3g} s, over the {budget_s:.3g} s budget "
                      f"({reason})")
        return ReplanOutcome(True, level, reason, request_id, dt, plan, sol.iterations, warm,
                             code)

    @property
    def _feasibility_tol(self) -> float:
        """Terminal constraints met to the solver's final tolerance (with slack)."""
        cold = self.policy.cold
        return max(1e-8, 10 * cold.newton.tol) if self.config.polish else 10 * cold.aul.tol

    def _start_rung(self, plan: Plan, U: np.ndarray) -> int:
        """Where a warm re-plan of ``plan`` (its controls U for the remaining stages) climbs
        the margin ladder from: the rung the plan was solved on, or the lowest rung U keeps
        to if higher. Rationale: an exact fuel plan solved on rung r + 1 can fit rung r's
        bound (its arcs held at rung r's thrust, ``exact_start``) though rung r could not meet
        the target; re-planning from rung r again failed at every re-plan of the last days of
        a halo flight (350-850 ms each; design notes: sticky margin rung)."""
        solved_on = sum(1 for p in self.rated_problems[1:]
                        if self.units.thrust_n(p.u_max) <= plan.thrust_bound_n * (1 + 1e-9))
        return max(solved_on, self._rung_for(U))

    def _rung_for(self, U: np.ndarray) -> int:
        """The lowest rung of the margin ladder whose bound the controls U (K, 3) keep to."""
        peak = float(np.max(np.linalg.norm(U, axis=1)))
        return int(lowest_rung(peak, [p.u_max for p in self.rated_problems]))

    def _rated(self, problem: Problem, rung: int) -> Problem:
        """``problem`` with the thrust bound of ``rated_problems[rung]``."""
        rated = self.rated_problems[rung]
        return replace(problem, u_max=rated.u_max, g_ineq=rated.g_ineq)

    @staticmethod
    def terminal_miss(problem: Problem, U) -> float:
        """Predicted max |terminal constraint| when flying U from the problem's x0."""
        return problem.terminal_violation(problem.rollout(U)[-1])

    # ------------------------------------------------------------------ nominal plans
    def load_plan(self, path: str | Path, epoch_s: float) -> Plan:
        """Adopt a stored solution (JSON) as the plan starting at epoch_s. Warm re-plans then
        optimise the cost that solution was optimised for (its last pseudo-Huber step,
        ``Solution.fuel_step``, when it is fuel-optimal like the planner; the case's last step
        for a plan whose exact fuel end game ran from the energy step), not the case's current
        last step: re-planning a plan for another cost re-shapes it in flight, and the closed
        loop loses arrival margin."""
        sol = Solution.from_json(path)
        if sol.U.shape[0] != self.base_problem.N:
            raise DaddyError(f"plan file {path} has {sol.U.shape[0]} stages, scenario has "
                             f"{self.base_problem.N}")
        if self.base_problem.g_path is not None:   # a keep-out scenario: held between nodes?
            problem = self.base_problem.with_x0(sol.X[0], sol.stage_dt, sol.t_start)
            margin = dense_margin(problem, sol.X, sol.U).margin
            if not margin >= -1e-6:
                raise DaddyError(f"plan file {path} violates the scenario's keep-out between "
                                 f"the nodes by {-margin * self.units.lu_km:.3f} km (dense "
                                 "re-propagation)")
            sol.min_path_margin = margin
        if self.config.fuel_optimal and sol.fuel_optimal and sol.fuel_step:
            self.policy = self.policy.with_warm(homotopy=(sol.fuel_step,))
        return self._adopt_solution(sol, epoch_s, "nominal")

    def _adopt_solution(self, sol: Solution, epoch_s: float, request_id: str,
                        arrival: bool = False) -> Plan:
        """Make a stored solution (stages starting at epoch_s; ``arrival``: one of the arrival
        phase) the current plan, with its stage maps expanded now (one batched call) so that
        the first re-optimisation from it is as fast as the later ones."""
        if sol.stage_maps is None:
            try:
                problem = self.base_problem.with_x0(sol.X[0], sol.stage_dt, sol.t_start)
                sol.stage_maps = StageMaps.of(expand_dynamics(problem, sol.X[:-1], sol.U),
                                              sol.X, sol.U, self.policy.warm.eps_da)
            except (DaddyError, ValueError, ArithmeticError):
                sol.stage_maps = None   # re-optimisations then roll out and expand afresh
        bound = self.rated_problems[self._rung_for(sol.U)].u_max
        plan = Plan.of(sol, sol.X, epoch_s, self.units, bound, request_id, arrival=arrival)
        self.set_plan(plan)
        return plan

    # ------------------------------------------------------------------ persistence
    def save_plan(self, path: str | Path) -> None:
        """Write the current plan (epoch, provenance and solution) atomically to ``path``."""
        plan = self.plan
        if plan is not None:
            write_plan_file(path, plan, self.case.name)

    def restore_plan(self, path: str | Path) -> Plan:
        """Adopt a plan written by ``save_plan`` (same scenario; its epoch is kept). Raises
        DaddyError naming what is wrong with the file."""
        sol, epoch, request_id, arrival = read_plan_file(
            path, self.case.name, self.base_problem.N, self.case.spacecraft.max_thrust_n)
        return self._adopt_solution(sol, epoch, request_id, arrival)
