"""ROS-free guidance logic: input checks, the warm-start shift, re-optimisation, and keeping the
last valid plan. The rclpy node (guidance_node.py) and the Monte Carlo demo both drive this class.

Times are seconds on the caller's clock (message stamps); states are SI in the problem's frame
(position m, velocity m/s), masses kg, thrust N.
"""
from __future__ import annotations

import json
import math
import os
import threading
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from daddy_core.errors import DaddyError
from daddy_core.catalogue import load_case, problem_from_case
from daddy_core.solver import Solution, WarmStart, case_options, solve
from daddy_core.da import functions as dm
from daddy_core.solver.stage_maps import StageMaps, expand_dynamics

# a first remaining stage shorter than this fraction of a nominal stage is merged into the next
MIN_STAGE_FRACTION = 0.25
ARRIVAL_SPEED_SCALE_M_S = 0.01  # a position one arrival tolerance off weighs as 1 cm/s (_arrival)
MIN_STAGES_LEFT = 4  # a re-plan keeps at least this many stages to the end (re-gridded)
# clock comparisons: times closer than this to a stage boundary count as on it [s]
TIME_TOLERANCE_S = 1e-6
# an estimate stamped up to this much after the request time is still usable [s]
FUTURE_TOLERANCE_S = 1.0
# relative thrust-bound excess (solver tolerance) saturated onto the bound rather than rejected
SATURATION_SLACK = 1e-3
PLAN_FORMAT = "daddy-plan-1"
# augmented-Lagrangian penalty a warm-started re-optimisation starts from (cold: options' 1)
WARM_MU_INIT = 1e5
# augmented-Lagrangian tolerance of a polished warm re-optimisation without an explicit tol_aul
WARM_TOL_AUL = 1e-5
# a warm re-optimisation's Newton steps hold inequalities within this of their bound on it (the
# thrust bound is |u|^2 / u_max^2 - 1 <= 0: |u| within 5e-5 relative of u_max); see __init__
WARM_ACTIVE_TOL = 1e-4
# thrust ratings a re-plan climbs through when the one below cannot meet the target, as the
# fraction of the thrust margin still held back (1: the derated bound, 0: the full rating)
MARGIN_LADDER = (1.0, 0.6, 0.3, 0.0)
# the climb stops when a rung leaves more than this fraction of the miss of the rung below
LADDER_MIN_GAIN = 0.9


class InputRejected(DaddyError):
    """A state estimate, mass or request that is not used; the message names the field."""


@dataclass
class Plan:
    """A valid control schedule anchored at ``epoch_s``.

    Attributes:
        epoch_s: time of the first stage start [s].
        stage_dt_s: (K,) stage durations [s].
        thrust_n: (K, 3) thrust per stage [N].
        states_si: (K+1, 7) predicted states (m, m/s, kg).
        solution: the Solution (normalised), for warm starts.
        request_id, solve_time_s, warm_start, max_violation: provenance for diagnostics.
        thrust_bound_n: the thrust bound the plan was optimised under [N] (a rung of the
            margin ladder, see ``GuidancePlanner``).
    """

    epoch_s: float
    stage_dt_s: np.ndarray
    thrust_n: np.ndarray
    states_si: np.ndarray
    solution: Solution
    request_id: str = ""
    solve_time_s: float = 0.0
    warm_start: bool = False
    max_violation: float = 0.0
    thrust_bound_n: float = 0.0

    @property
    def stage_start_s(self) -> np.ndarray:
        """(K,) stage start times relative to ``epoch_s``."""
        return np.concatenate([[0.0], np.cumsum(self.stage_dt_s)[:-1]])

    @property
    def end_s(self) -> float:
        return self.epoch_s + float(np.sum(self.stage_dt_s))

    def thrust_at(self, t_s: float) -> np.ndarray:
        """Thrust [N] of the stage containing time t (zero before the epoch or after the end)."""
        rel = t_s - self.epoch_s + TIME_TOLERANCE_S  # a time on a stage boundary opens the stage
        if rel < 0 or t_s + TIME_TOLERANCE_S >= self.end_s:
            return np.zeros(3)
        k = int(np.searchsorted(np.cumsum(self.stage_dt_s), rel, side="right"))
        return self.thrust_n[min(k, len(self.thrust_n) - 1)].copy()


@dataclass
class ReplanOutcome:
    """What one re-optimisation produced (ok: a new valid plan was stored)."""

    ok: bool
    level: str          # "OK", "WARN" or "ERROR"
    reason: str
    request_id: str
    solve_time_s: float
    plan: Plan | None
    iterations: dict = field(default_factory=dict)
    warm_start: bool = False


class GuidancePlanner:
    """Holds the scenario, the latest valid plan, and re-optimises on request (thread-safe)."""

    def __init__(self, scenario: str = "halo_l2_l1", method: str = "dyn", polish: bool = True,
                 fuel_optimal: bool = True, stages: int = 0, time_budget_s: float = 60.0,
                 staleness_s: float = 600.0, tol_aul: float | None = None,
                 tol_newton: float | None = None, mass_tolerance_kg: float = 1e-6,
                 thrust_margin: float = 0.05, restore_first: bool = True,
                 arrival_tolerance_m: float = 0.0):
        self.case = load_case(scenario)
        if self.case.spacecraft is None:
            raise DaddyError(f"scenario {scenario!r} has no spacecraft (mass) model for guidance")
        self.method = method
        self.polish = bool(polish)
        if not (math.isfinite(arrival_tolerance_m) and arrival_tolerance_m >= 0.0):
            raise DaddyError(f"arrival_tolerance_m must be a finite number >= 0, got "
                             f"{arrival_tolerance_m!r}")
        self.arrival_tolerance_m = float(arrival_tolerance_m)
        self.fuel_optimal = bool(fuel_optimal)
        self.units = self.case.units
        if not 0.0 <= thrust_margin < 1.0:
            raise DaddyError(f"thrust_margin must be in [0, 1), got {thrust_margin!r}")
        # plans keep a thrust margin for closed-loop corrections and give it up rung by rung
        # (MARGIN_LADDER) only as far as the target demands: a fuel-optimal plan rides its
        # bound, so a plan that took the full rating at once had nothing left for the next
        # execution error (Monte Carlo failures, velocity misses 1.1-1.9 cm/s)
        rating = self.case.spacecraft.max_thrust_n
        self.rated_problems = [
            problem_from_case(self.case, stages=stages or None,
                              max_thrust_n=rating * (1.0 - thrust_margin * held))
            for held in (MARGIN_LADDER if thrust_margin > 0 else (0.0,))]
        self.base_problem = self.rated_problems[0]
        overrides = {}
        if tol_aul:
            overrides["tol_aul"] = tol_aul
        if tol_newton:
            overrides["tol_newton"] = tol_newton
        self.options = case_options(self.case, self.fuel_optimal, time_budget_s=time_budget_s,
                                    **overrides)
        # re-optimisations run the last homotopy step only (the plan is already fuel-optimal)
        # The warm start is converged already: the tol_ddp test may stop DDP after 1 iteration,
        # and the penalty resumes high (WARM_MU_INIT) next to the carried-over multipliers -- with
        # mu = 1 the first DDP pass trades the constraints away (halo: violation 1e-3 -> 1.8)
        # and the solve needs > 120 s instead of ~36 s.
        # From the warm start: shortened DDP steps raise the Quu damping instead of crawling
        # (halo warm replan 33 s -> ~4 s) and rho carries over between solves. restore_first:
        # Newton first restores feasibility, so that a solve stopped by its time budget still
        # flies a feasible plan from the new state (costs ~0.3 s on Earth-Mars).
        # A polished re-optimisation stops the AUL at WARM_TOL_AUL unless tol_aul is given:
        # Newton takes the constraints to tol_newton anyway, and from the converged warm start
        # the AUL rounds down to 1e-6 changed the cost by ~1e-5 relative (Earth-Mars ~5 g of
        # propellant, halo < 1 g, 4 perturbed states each) for a third of the re-plan time
        # (halo: 4 AUL / 9 DDP iterations -> 1 / 1).
        # Newton treats inequalities within WARM_ACTIVE_TOL of their bound as active: the AUL
        # leaves a fuel-optimal plan's full-thrust arcs up to ~1e-5 inside the bound, Newton's
        # first min-norm step (with them inactive at the options' 1e-6) pushed them past it and
        # the next iterations pulled them back (halo: active thrust bounds 16 -> 30 -> 31). Held
        # on the bound from the start, the halo re-plans of bench_replan take 3 Newton
        # iterations instead of 4-5 and end 0-2 g heavier.
        # Not used: SolverOptions.ddp_stop_on_prediction (DDP stops before a step whose
        # predicted decrease is below a tenth of tol_ddp). It makes the Earth-Mars bench
        # re-plan ~20 ms faster (no step, no polishing from the restored start), but the
        # closed-loop halo Monte Carlo (seeds 1-100) went 100/100 -> 99/100 (an arrival miss
        # of 1.90 cm/s; 1.05 and 1.16 cm/s at tol_ddp itself) and its median propellant
        # 26.765 -> 26.802 kg: the skipped steps are what keeps the plans optimal.
        warm_tol_aul = tol_aul or (max(WARM_TOL_AUL, self.options.tol_aul) if self.polish
                                   else self.options.tol_aul)
        self.replan_options = self.options.with_(homotopy=self.options.homotopy[-1:],
                                                 ddp_min_iter=1, mu_init=WARM_MU_INIT,
                                                 short_step=0.5, carry_rho=True,
                                                 restore_warm_start=bool(restore_first),
                                                 tol_aul=warm_tol_aul, polish_from_ddp_maps=True,
                                                 newton_active_tol=max(WARM_ACTIVE_TOL,
                                                                       self.options.newton_active_tol))
        self.time_budget_s = time_budget_s
        self.staleness_s = staleness_s
        self.mass_tolerance_kg = mass_tolerance_kg
        self._lock = threading.Lock()
        self._plan: Plan | None = None

    # ------------------------------------------------------------------ plan access
    @property
    def plan(self) -> Plan | None:
        with self._lock:
            return self._plan

    def set_plan(self, plan: Plan) -> None:
        with self._lock:
            self._plan = plan

    # ------------------------------------------------------------------ conversions
    def state_to_normalised(self, pos_m, vel_m_s, mass_kg) -> np.ndarray:
        u = self.units
        return np.concatenate([u.length(pos_m), u.speed(vel_m_s), [u.mass(mass_kg)]])

    def states_to_si(self, X: np.ndarray) -> np.ndarray:
        u = self.units
        out = np.empty_like(X)
        out[:, :3] = u.length_m(X[:, :3])
        out[:, 3:6] = u.speed_m_s(X[:, 3:6])
        out[:, 6] = u.mass_kg(X[:, 6])
        return out

    # ------------------------------------------------------------------ input checks
    def check_estimate(self, pos_m, vel_m_s, stamp_s: float) -> None:
        """Raise InputRejected (naming the field) for a state estimate that cannot be used at any
        time: non-finite, unset stamp, or outside the scenario's domain."""
        pos = np.asarray(pos_m, dtype=float)
        vel = np.asarray(vel_m_s, dtype=float)
        if pos.shape != (3,) or not np.all(np.isfinite(pos)):
            raise InputRejected("state_estimate.pose.pose.position is not 3 finite numbers")
        if vel.shape != (3,) or not np.all(np.isfinite(vel)):
            raise InputRejected("state_estimate.twist.twist.linear is not 3 finite numbers")
        self._check_stamp(stamp_s, "state_estimate")
        u = self.units
        self._check_domain(np.concatenate([u.length(pos), u.speed(vel)]))

    def check_mass(self, mass_kg, stamp_s: float | None = None) -> None:
        """Raise InputRejected unless dry mass < mass_kg <= wet mass (+ tolerance)."""
        if mass_kg is None or not math.isfinite(mass_kg):
            raise InputRejected("mass_estimate.inertia.m is missing or not finite")
        sc = self.case.spacecraft
        if mass_kg <= sc.dry_mass_kg:
            raise InputRejected(f"mass_estimate.inertia.m = {mass_kg:.6g} kg is not above the dry "
                                f"mass {sc.dry_mass_kg:.6g} kg")
        if mass_kg > sc.wet_mass_kg + self.mass_tolerance_kg:
            raise InputRejected(f"mass_estimate.inertia.m = {mass_kg:.6g} kg exceeds the wet mass "
                                f"{sc.wet_mass_kg:.6g} kg")
        if stamp_s is not None:
            self._check_stamp(stamp_s, "mass_estimate")

    @staticmethod
    def _check_stamp(stamp_s: float, topic: str) -> None:
        if not math.isfinite(stamp_s) or stamp_s <= 0.0:
            raise InputRejected(f"{topic}.header.stamp is unset, negative or not finite "
                                f"({stamp_s!r} s)")

    def check_state(self, pos_m, vel_m_s, mass_kg, stamp_s: float, now_s: float | None = None):
        """All checks of one estimate used at time now_s; returns the normalised state (7,).
        Raises InputRejected (naming the field) for an estimate the planner must not use."""
        self.check_estimate(pos_m, vel_m_s, stamp_s)
        self.check_mass(mass_kg)
        if now_s is not None:
            if stamp_s > now_s + FUTURE_TOLERANCE_S:
                raise InputRejected(f"state_estimate.header.stamp is {stamp_s - now_s:.3g} s in "
                                    "the future of the request")
            if now_s - stamp_s > self.staleness_s:
                raise InputRejected(f"state_estimate.header.stamp is stale ({now_s - stamp_s:.3g}"
                                    f" s old, bound staleness_s = {self.staleness_s:.3g} s)")
        return self.state_to_normalised(np.asarray(pos_m, float), np.asarray(vel_m_s, float),
                                        mass_kg)

    def _check_domain(self, x: np.ndarray) -> None:
        sys = self.case.system
        r = x[:3]
        if sys == "earth_moon_cr3bp":
            mu = self.units.gm
            moon_radius = 1737.4 / self.units.lu_km
            earth_radius = 6378.1 / self.units.lu_km
            if np.linalg.norm(r - [1 - mu, 0, 0]) < moon_radius:
                raise InputRejected("state_estimate.pose.pose.position is inside the Moon")
            if np.linalg.norm(r + [mu, 0, 0]) < earth_radius:
                raise InputRejected("state_estimate.pose.pose.position is inside the Earth")
            if np.linalg.norm(r) > 5.0 or np.linalg.norm(x[3:6]) > 10.0:
                raise InputRejected("state_estimate (position or velocity) is far outside the "
                                    "Earth-Moon domain")
        elif sys == "sun_two_body":
            if not 0.05 < np.linalg.norm(r) < 50.0 or np.linalg.norm(x[3:6]) > 10.0:
                raise InputRejected("state_estimate (position or velocity) is outside the "
                                    "heliocentric domain")

    # ------------------------------------------------------------------ shift (warm start)
    def shifted_problem(self, plan: Plan | None, t_s: float, x0: np.ndarray):
        """The remaining problem from state x0 at time t, and the warm-start controls.

        Drops the stages already executed, keeps the remaining time to go (the first remaining
        stage is shortened to end on the plan's stage boundary, or merged into the next when
        shorter than MIN_STAGE_FRACTION of a stage; fewer than MIN_STAGES_LEFT stages are
        re-gridded into that many: the arrival phase, whose terminal position may keep
        ``arrival_tolerance_m`` from the target, see ``_arrival``). Without a plan, the full
        scenario from x0.
        Returns (problem, U_guess (K, 3) normalised or None, duals for those stages or None,
        the plan's stage maps for those stages (``StageMaps``) or None).
        """
        base = self.base_problem
        if plan is None:
            return base.with_x0(x0), None, None, None
        tu = self.units.tu_s
        bounds = plan.epoch_s + np.cumsum(plan.stage_dt_s)          # stage end times
        k0 = int(np.searchsorted(bounds, t_s + TIME_TOLERANCE_S, side="right"))
        if k0 >= len(plan.stage_dt_s):
            raise InputRejected("the plan has ended: no stage remains after header.stamp")
        first = bounds[k0] - t_s
        dts = plan.stage_dt_s[k0:].astype(float).copy()
        U = plan.solution.U[k0:].copy()
        lam = np.asarray(plan.solution.duals.get("lam", []), float)
        lam = lam[:, k0:] if lam.ndim == 2 and lam.shape[1] == len(plan.stage_dt_s) else None
        nominal = float(np.median(plan.stage_dt_s))
        maps = plan.solution.stage_maps
        if first < MIN_STAGE_FRACTION * nominal and len(dts) > 1:
            dts = dts[1:]
            dts[0] += first
            U = U[1:]
            lam = None if lam is None else lam[:, 1:]
            maps = None if maps is None else maps.tail(k0 + 1, first_valid=False)
        else:
            maps = None if maps is None else maps.tail(
                k0, first_valid=abs(first - dts[0]) <= TIME_TOLERANCE_S)
            dts[0] = first
        arrival = len(dts) < MIN_STAGES_LEFT   # the re-gridded last stages: arrival phase
        if arrival:
            # near the end, keep enough controls for the terminal constraints (6 of them, 3 per
            # stage): re-grid the time to go into MIN_STAGES_LEFT equal stages, warm-started
            # from the plan's stage at each new stage's midpoint
            total = float(np.sum(dts))
            mids = (np.arange(MIN_STAGES_LEFT) + 0.5) * total / MIN_STAGES_LEFT
            idx = np.minimum(np.searchsorted(np.cumsum(dts), mids), len(dts) - 1)
            dts = np.full(MIN_STAGES_LEFT, total / MIN_STAGES_LEFT)
            U = U[idx]
            maps = None
            lam = None if lam is None else lam[:, idx]
        duals = None if lam is None else {"lam": lam, "lam_t": plan.solution.duals.get("lam_t", [])}
        problem = base.with_x0(x0, dts / tu)
        return (self._arrival(problem) if arrival else problem), U, duals, maps

    # ------------------------------------------------------------------ re-optimisation
    def replan(self, pos_m, vel_m_s, mass_kg, stamp_s: float, request_id: str = "",
               now_s: float | None = None, cold: bool = False) -> ReplanOutcome:
        """Re-optimise from an estimate; store and return the new plan if it is valid.

        Never raises for solver trouble: a failed, non-finite or bound-violating result leaves
        the last valid plan in place and is reported as ERROR/WARN. Bad inputs raise
        InputRejected before anything is touched.
        """
        x0 = self.check_state(pos_m, vel_m_s, mass_kg, stamp_s, now_s)
        current = self.plan
        problem, U_guess, duals, maps = self.shifted_problem(None if cold else current,
                                                             stamp_s, x0)
        warm = U_guess is not None
        rung = 0
        if U_guess is None:
            U_guess = np.full((problem.N, 3), float(self.units.thrust(1e-6)))
            opts = self.options
        else:
            opts = self.replan_options
            if problem.N <= MIN_STAGES_LEFT:
                # the last stages (arrival phase, re-gridded): the full AUL tolerance and
                # polishing from fresh expansions (Monte Carlo arrival misses of 1.01 and
                # 1.39 cm/s otherwise, one run in 40 each), the case's Newton active set
                opts = opts.with_(tol_aul=self.options.tol_aul, polish_from_ddp_maps=False,
                                  newton_active_tol=self.options.newton_active_tol)
            # the current plan may already fly above the derating: start from the lowest rating
            # it keeps to instead of failing on the bounds below first
            rung = self._rung_for(U_guess)
            problem = self._rated(problem, rung)
        t0 = time.perf_counter()
        try:
            start = WarmStart(U_guess, duals, current.solution.rho if warm else None, maps)
            sol = solve(problem, start, method=self.method, fuel_optimal=None, polish=self.polish,
                        options=opts, case_name=self.case.name)
            safe, feasible, why, X, miss = self._assess(sol, problem)
            if not safe and self.polish:
                # polishing an infeasible problem can push the thrust past its bound: fall back
                # to the DDP result, which keeps the bound and minimises the terminal miss
                sol = solve(problem, sol.U if np.all(np.isfinite(sol.U)) else U_guess,
                            method=self.method, fuel_optimal=None, polish=False, options=opts,
                            case_name=self.case.name)
                safe, feasible, why, X, miss = self._assess(sol, problem)
        except Exception as exc:  # a solver fault must never take the plan down
            return ReplanOutcome(False, "ERROR", f"solver raised {type(exc).__name__}: {exc}",
                                 request_id, time.perf_counter() - t0, None, warm_start=warm)
        while not (safe and feasible) and rung + 1 < len(self.rated_problems):
            # the target is out of reach on this rating: give up the next part of the margin
            rung += 1
            rated = self._rated(problem, rung)
            try:
                sol2 = solve(rated, sol.U if safe else U_guess, method=self.method,
                             fuel_optimal=None, polish=self.polish, options=opts,
                             case_name=self.case.name)
                assessed = self._assess(sol2, rated)
            except Exception:  # keep the result on the lower rating
                continue
            if assessed[0] and (assessed[1] or not safe or assessed[4] < miss):
                stalled = safe and not assessed[1] and assessed[4] > LADDER_MIN_GAIN * miss
                sol, problem = sol2, rated
                safe, feasible, why, X, miss = assessed
                if stalled:
                    # more thrust hardly reduced the miss: what is left is not a thrust deficit
                    # (e.g. navigation error in the last minutes); stop climbing
                    break
        dt = time.perf_counter() - t0
        if not safe:
            return ReplanOutcome(False, "ERROR", why, request_id, dt, None, sol.iterations, warm)
        if not feasible and warm:
            # a best-effort plan replaces the current one only if it is predicted to miss less
            old_miss = self.terminal_miss(problem, U_guess)
            if miss >= old_miss:
                return ReplanOutcome(False, "WARN", f"kept the current plan: {why}, and no better "
                                     f"than flying it (miss {old_miss:.2e})", request_id, dt, None,
                                     sol.iterations, warm)
        plan = Plan(epoch_s=stamp_s, stage_dt_s=problem.stage_dt * self.units.tu_s,
                    thrust_n=sol.thrust_n.copy(), states_si=self.states_to_si(X),
                    solution=sol, request_id=request_id, solve_time_s=dt, warm_start=warm,
                    max_violation=sol.max_violation,
                    thrust_bound_n=float(self.units.thrust_n(problem.u_max)))
        self.set_plan(plan)
        level, reason = "OK", "re-optimised"
        if not feasible:
            level, reason = "WARN", f"best effort within the thrust bound: {why}"
        elif not sol.converged:
            level, reason = "WARN", f"stored best feasible iterate: {sol.reason}"
        if dt > self.time_budget_s:
            level, reason = "WARN", f"solve took {dt:.3g} s, over the {self.time_budget_s:.3g} s budget"
        return ReplanOutcome(True, level, reason, request_id, dt, plan, sol.iterations, warm)

    def _rung_for(self, U: np.ndarray) -> int:
        """The lowest rung of the margin ladder whose bound the controls U (K, 3) keep to."""
        peak = float(np.max(np.linalg.norm(U, axis=1)))
        rung = 0
        while rung + 1 < len(self.rated_problems) and \
                peak > self.rated_problems[rung].u_max * (1 + SATURATION_SLACK):
            rung += 1
        return rung

    def _rated(self, problem, rung: int):
        """``problem`` with the thrust bound of ``rated_problems[rung]``."""
        rated = self.rated_problems[rung]
        return replace(problem, u_max=rated.u_max, g_ineq=rated.g_ineq)

    def _assess(self, sol: Solution, problem):
        """(safe to fly, meets every constraint, reason, X, terminal miss). Safe: finite and
        within the thrust and mass bounds; feasible: also meets the terminal constraints. X is
        the trajectory of the (saturated) controls, miss its max |terminal constraint| (and at
        least the solver's DOP853 re-propagation miss).

        Thrust magnitudes over the bound by at most SATURATION_SLACK (relative; solver
        tolerance) are saturated onto it in place -- the engine cannot do more anyway.
        """
        U = sol.U
        if not (np.all(np.isfinite(U)) and np.all(np.isfinite(sol.X))):
            return False, False, "solution contains NaN or inf", None, np.inf
        umax = problem.u_max
        if umax is not None:
            mags = np.linalg.norm(U, axis=1)
            if np.max(mags) > umax * (1 + SATURATION_SLACK):
                return False, False, "solution violates the thrust bound", None, np.inf
            over = mags > umax
            U[over] *= (umax / mags[over])[:, None]
            excess = float(np.max(mags / umax)) - 1.0
        else:
            excess = 0.0
        if sol.repropagation_miss == np.inf:
            return False, False, "solution could not be re-propagated (DOP853)", None, np.inf
        # the solver's own trajectory, independently re-propagated (DOP853) by solve(), serves
        # as is; controls changed by the saturation beyond round-off are rolled out again
        if excess > 1e-9 or sol.repropagation_miss is None:
            X, repro = problem.rollout(U), 0.0
        else:
            X, repro = sol.X, sol.repropagation_miss
        if not np.all(np.isfinite(X)):
            return False, False, "solution propagates to a non-finite state", None, np.inf
        g, ni = problem.path_constraints(X[:-1].T, U.T, problem.stage_dt)
        if g is not None and ni and np.max(g[:ni]) > 1e-6:
            return (False, False, f"solution violates a path constraint by {np.max(g[:ni]):.2e}",
                    None, np.inf)
        miss = max(self._miss(problem, X), repro)
        # feasible: the terminal constraints met to the solver's final tolerance (with slack)
        tol = max(1e-8, 10 * self.options.tol_newton) if self.polish else 10 * self.options.tol_aul
        if miss > tol:
            return True, False, f"terminal constraint missed by {miss:.2e} (normalised)", X, miss
        return True, True, "", X, miss

    @staticmethod
    def _miss(problem, X) -> float:
        """Max terminal-constraint violation at the end of the trajectory X."""
        return problem.terminal_violation(X[-1])

    def _arrival(self, problem):
        """The arrival phase's terminal constraints (with ``arrival_tolerance_m`` > 0): the
        velocity exact, the position within the tolerance of the target. In the last hours a
        position error of the order of the navigation error cannot be removed at any acceptable
        cost, and demanding it makes the problem infeasible and the best-effort plans trade
        velocity for it.

        The ball is s (|r - r_t| / tolerance - 1) <= 0 with s = 1 cm/s in normalised speed
        units: a position one tolerance beyond the ball weighs as much as a 1 cm/s velocity
        miss wherever terminal violations are compared (solver tolerances, the planner's
        best-effort choice), and the constraint only turns active (Newton) within 10 % of R.
        """
        gt, _ = problem.terminal_constraints(problem.x_target)
        if not self.arrival_tolerance_m or gt is None or gt.shape != (6,):
            return problem
        R = float(self.units.length(self.arrival_tolerance_m))
        scale = float(self.units.speed(ARRIVAL_SPEED_SCALE_M_S))
        floor2 = (1e-3 * R) ** 2

        def position_ball(x, xt):
            d = x[:3] - xt[:3]
            return (dm.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2] + floor2) * (scale / R)
                    - scale)[None]

        return replace(problem, g_tineq=position_ball, g_teq=lambda x, xt: x[3:6] - xt[3:6])

    @classmethod
    def terminal_miss(cls, problem, U) -> float:
        """Predicted max |terminal constraint| when flying U from the problem's x0."""
        return cls._miss(problem, problem.rollout(U))

    # ------------------------------------------------------------------ nominal plans
    def load_plan(self, path: str | Path, epoch_s: float) -> Plan:
        """Adopt a stored solution (JSON) as the plan starting at epoch_s."""
        sol = Solution.from_json(path)
        if sol.U.shape[0] != self.base_problem.N:
            raise DaddyError(f"plan file {path} has {sol.U.shape[0]} stages, scenario has "
                             f"{self.base_problem.N}")
        return self._adopt_solution(sol, epoch_s, "nominal")

    def _adopt_solution(self, sol: Solution, epoch_s: float, request_id: str) -> Plan:
        """Make a stored solution (stages starting at epoch_s) the current plan, with its stage
        maps expanded now (one batched call) so that the first re-optimisation from it is as
        fast as the later ones."""
        if sol.stage_maps is None:
            try:
                problem = self.base_problem.with_x0(sol.X[0], sol.stage_dt)
                sol.stage_maps = StageMaps.of(expand_dynamics(problem, sol.X[:-1], sol.U,
                                                              sol.stage_dt),
                                              sol.X, sol.U, self.replan_options.eps_da)
            except (DaddyError, ValueError, FloatingPointError):
                sol.stage_maps = None   # re-optimisations then roll out and expand afresh
        bound = self.rated_problems[self._rung_for(sol.U)].u_max
        plan = Plan(epoch_s, sol.stage_dt * self.units.tu_s, sol.thrust_n.copy(),
                    self.states_to_si(sol.X), sol, request_id, 0.0, False, sol.max_violation,
                    float(self.units.thrust_n(bound)))
        self.set_plan(plan)
        return plan

    # ------------------------------------------------------------------ persistence
    def save_plan(self, path: str | Path) -> None:
        """Write the current plan (epoch, provenance and solution) atomically to ``path``."""
        plan = self.plan
        if plan is None:
            return
        data = {"format": PLAN_FORMAT, "scenario": self.case.name, "epoch_s": plan.epoch_s,
                "request_id": plan.request_id, "solution": plan.solution.to_dict()}
        path = Path(path)
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(json.dumps(data, allow_nan=False))
        os.replace(tmp, path)   # a crash mid-write leaves the previous file intact

    def restore_plan(self, path: str | Path) -> Plan:
        """Adopt a plan written by ``save_plan`` (same scenario; its epoch is kept). Raises
        DaddyError naming what is wrong with the file."""
        try:
            data = json.loads(Path(path).read_text())
            sol = Solution.from_dict(data["solution"])
            epoch = float(data["epoch_s"])
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise DaddyError(f"persisted plan {path}: unreadable ({exc!r})") from exc
        if data.get("format") != PLAN_FORMAT or data.get("scenario") != self.case.name:
            raise DaddyError(f"persisted plan {path} is not a {PLAN_FORMAT} plan of scenario "
                             f"{self.case.name!r}")
        thrust = sol.thrust_n
        if not (math.isfinite(epoch) and 1 <= len(thrust) <= self.base_problem.N
                and np.all(np.isfinite(thrust)) and np.all(np.isfinite(sol.X))):
            raise DaddyError(f"persisted plan {path} has a bad epoch, stage count or values")
        if np.max(np.linalg.norm(thrust, axis=1)) > \
                self.case.spacecraft.max_thrust_n * (1 + SATURATION_SLACK):
            raise DaddyError(f"persisted plan {path} violates the thrust bound")
        return self._adopt_solution(sol, epoch, str(data.get("request_id", "restored")))
