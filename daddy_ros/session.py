"""One guidance session, ROS-free: what the node does between its messages. Accepted estimates
go into the request queue and get their thrust command from the plan in force -- or, when the
re-plan policy (``self_trigger``) asks for a re-plan, after it; a worker thread serves the
queue's requests with ``GuidancePlanner.replan``; plans are adopted (the bundled nominal at the
first estimate), persisted after every new plan and restored after a crash.

The node hands the session an ``Outputs`` (its publishers and diagnostics) and translates
messages; the session never sees a message type.
"""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np

from daddy_core.errors import DaddyError

from .checks import InputRejected, StampGuard
from .config import PlannerConfig, TriggerConfig
from .feedback import FeedbackLaws
from .plan import TIME_TOLERANCE_S, Code, Level, Plan
from .plan_fit import PlanFit
from .planner import GuidancePlanner
from .request_queue import RequestQueue
from .self_trigger import Reason, ReplanTrigger

if TYPE_CHECKING:   # (a plain dataclass of the estimate; its module also converts messages)
    from .conversions import OdometryState as StateEstimate


class Outputs(Protocol):
    """What a session publishes: the plan (schedule and path), thrust commands [N] for an
    estimate's stamp, diagnostic events, and the last solve (for the health status)."""

    def publish_plan(self, plan: Plan, stamp: float | None) -> None: ...

    def publish_thrust(self, thrust_n: np.ndarray, stamp: float) -> None: ...

    def diag(self, level: Level, code: Code, message: str, values: dict, stamp,
             log_every_s: float | None = None) -> None: ...

    def solved(self, level: Level, reason: str, solve_s: float | None) -> None: ...


@dataclass(frozen=True)
class SolveReport:
    """How one re-plan ended, for the requests it served: its id, level, code and reason, the
    planner's outcome (None when no solve ran) and the plan in force afterwards."""

    request_id: str
    level: Level
    code: Code
    reason: str
    outcome: object
    plan: Plan | None


class GuidanceSession:
    """The planner, the request queue, the re-plan policy and the worker of one configured node.

    plan_file: the nominal plan adopted at the first estimate ('' none); persist_file: where the
    plan in force is kept for crash recovery ('' none); active: whether thrust may be commanded
    (a callable: the node's lifecycle state); laws: the feedback laws flown at stage boundaries
    instead of re-plans (``feedback``), or None."""

    def __init__(self, planner: GuidancePlanner, trigger: ReplanTrigger | None, plan_file: str,
                 persist_file: str, outputs: Outputs, active, laws: FeedbackLaws | None = None):
        self.planner, self.trigger, self.out, self.active = planner, trigger, outputs, active
        self.laws = laws
        self.laws_served = 0
        self.plan_file, self.persist_file = plan_file, persist_file
        self.queue = RequestQueue()
        self.replans = 0
        self._withheld: list[float] = []   # estimate stamps whose thrust waits for a re-plan
        self._withheld_lock = threading.Lock()
        # estimate stamps that came before any plan, or before the plan in force was published
        self._unanswered: list[float] = []
        # the plan last published (or in force when the session began): no thrust is
        # commanded from a plan before it is published (``_unpublished``)
        self._published: Plan | None = planner.plan
        self._cancel = (0, threading.Event())   # (solve number, its cancel flag)
        self.figures: dict = {}             # the running solve's progress (``ProgressLine``)
        self._replan_on_first_estimate = False
        self.fit = PlanFit(planner.case, planner.config.fit_position_m,
                           planner.config.fit_velocity_m_s)
        self.stamps = StampGuard(planner.config.max_stamp_jump_stages,
                                 planner.config.stamp_jump_confirmations)
        self._worker = threading.Thread(target=self._work, name="daddy_replan", daemon=True)
        self._worker.start()
        if persist_file and Path(persist_file).exists():
            self._restore()

    # ------------------------------------------------------------------ inputs
    def on_state(self, est: StateEstimate, stamp: float) -> None:
        """An estimate whose frame the node has checked (InputRejected naming the field when
        the planner's checks refuse it)."""
        self.planner.checks.check_estimate(est.pos_m, est.vel_m_s, stamp)
        new_clock = self.stamps.accept(stamp, "state_estimate", self.planner.plan)
        self.queue.add_state(est.pos_m, est.vel_m_s, stamp, est.pos_sigma_m, est.vel_sigma_m_s)
        plan = self.planner.plan or self._adopt_nominal()
        if plan is None:   # (no mass yet, or no plan at all): answered when one comes
            with self._withheld_lock:
                self._unanswered.append(stamp)
        elif new_clock:
            self._replan_on_new_clock(stamp)
        else:
            self._answer(est, stamp, plan)
        self._maybe_replan_after_restart()

    def _answer(self, est: StateEstimate, stamp: float, plan: Plan) -> None:
        """The thrust command of an accepted estimate: at once from the plan, or withheld for
        a re-plan (the plan does not fit it, or the re-plan policy wants one: _finish answers
        it)."""
        if self._unpublished(plan, stamp):
            return
        if self._fits(est, stamp, plan) and not self._self_triggered(est, stamp, plan):
            self.out.publish_thrust(plan.command_at(stamp, est.pos_m, est.vel_m_s), stamp)

    def _unpublished(self, plan: Plan, stamp: float) -> bool:
        """Whether ``plan`` is one the worker has stored but not yet published (a re-plan
        between its solve and ``_finish``): the estimate is then answered by ``_finish`` after
        the plan is published (``_answer_unanswered``), so a client holds the plan a thrust
        command comes from before the command."""
        with self._withheld_lock:
            if plan is self._published:
                return False
            self._unanswered.append(stamp)
            return True

    def _publish(self, plan: Plan, stamp: float | None) -> None:
        """Publish ``plan`` (schedule and path) and mark it as the plan commands may come
        from."""
        self.out.publish_plan(plan, stamp)
        with self._withheld_lock:
            self._published = plan

    def _answer_unanswered(self, plan: Plan) -> None:
        """The estimates that came before any plan (mass and state may arrive in either order)
        or before the plan in force was published, answered by the one now in force."""
        with self._withheld_lock:
            stamps, self._unanswered = self._unanswered, []
        for s in stamps:
            try:
                est = self.queue.state_for(s)
            except InputRejected:
                continue
            self._answer(est, s, plan)

    def _fits(self, est: StateEstimate, stamp: float, plan: Plan) -> bool:
        """Whether the plan fits the estimate (``plan_fit``); if not, an ERROR
        PLAN_DOES_NOT_FIT, the estimate's thrust command withheld and a re-plan from it
        queued: no thrust is commanded from a plan that does not fit the state."""
        fit = self.fit.check(plan, stamp, est.pos_m, est.vel_m_s)
        if fit.fits:
            return True
        self.out.diag(Level.ERROR, Code.PLAN_DOES_NOT_FIT,
                      f"the plan in force is {fit.position_m / 1e3:.6g} km, "
                      f"{fit.velocity_m_s:.6g} m/s from the estimate (fit_position_m, "
                      "fit_velocity_m_s): thrust withheld, re-planning from it",
                      fit.values(stamp), stamp, log_every_s=1.0)
        self._withhold_for_replan(f"fit-{stamp:.3f}", stamp)
        return False

    def _withhold_for_replan(self, request_id: str, stamp: float) -> None:
        """Queue a re-plan from the estimate of ``stamp``; its thrust command waits for it
        (``_release_withheld``)."""
        with self._withheld_lock:
            self._withheld.append(stamp)
        self.queue.enqueue(request_id, stamp)

    def _replan_on_new_clock(self, stamp: float) -> None:
        """Estimates in a row set a new flight clock (``checks.StampGuard``): the plan's stage
        and the re-plan policy's prediction belong to the old one, so the node re-plans from
        this estimate, withholding its thrust command until then, and says so (WARN)."""
        self.out.diag(Level.WARN, Code.CLOCK_CHANGED,
                      f"{self.stamps.confirmations} state estimates in a row set a new flight "
                      f"clock ({stamp:.3f} s): re-planning from the last",
                      {"request_id": f"clock-{stamp:.3f}"}, stamp)
        self._withhold_for_replan(f"clock-{stamp:.3f}", stamp)

    def on_mass(self, mass: float, stamp: float) -> None:
        self.planner.checks.check_mass(mass, stamp)
        self.queue.add_mass(stamp, mass)
        if self.planner.plan is None and self._adopt_nominal() is not None:
            self._answer_unanswered(self.planner.plan)
        self._maybe_replan_after_restart()

    def request(self, request_id: str, stamp: float | None, cold: bool = False,
                time_budget_s: float | None = None) -> int:
        """Queue a re-plan request (``cold``: from the scenario's cold guess; ``time_budget_s``:
        its budget, None: the node's); returns the number of the solve that will serve it
        (``report_of``, ``cancel``)."""
        return self.queue.enqueue(request_id, stamp, cold, time_budget_s)

    def reconfigure(self, changes: dict, settings: TriggerConfig) -> None:
        """Parameters changed while configured (``config``: the runtime ones): the planner's
        (``GuidancePlanner.update``: the staleness test at once, the solver's settings at the
        next re-plan), the plan-fit and stamp tests at the next estimate, and the re-plan policy
        and feedback laws from ``settings`` at the next estimate (their prediction kept).
        A DaddyError, and nothing changed, when the planner refuses them."""
        planner = {k: v for k, v in changes.items() if k in PlannerConfig.__dataclass_fields__}
        if planner:
            self.planner.update(**planner)
        cfg = self.planner.changed_config()
        self.fit = PlanFit(self.planner.case, cfg.fit_position_m, cfg.fit_velocity_m_s)
        self.stamps.stages = cfg.max_stamp_jump_stages
        self.stamps.confirmations = cfg.stamp_jump_confirmations
        if not any(k in TriggerConfig.__dataclass_fields__ for k in changes):
            return
        if self.trigger is not None and settings.self_replan:
            self.trigger.settings = settings   # (its prediction of the schedule is kept)
        else:
            self.trigger = ReplanTrigger.for_planner(self.planner, settings)
        if self.laws is not None and self.laws.order == settings.feedback_order:
            self.laws.position_m = settings.feedback_position_m   # (the built laws are kept)
            self.laws.velocity_m_s = settings.feedback_velocity_m_s
        else:   # (built for the plan in force when first served)
            self.laws = FeedbackLaws.for_planner(self.planner, settings)

    def cancel(self, number: int) -> bool:
        """Cancel solve ``number`` if it is running: it stops within one iteration and the
        plan in force is kept. False when it is not running (not started, or finished). (Each
        solve has its own flag: a late cancel cannot reach the next solve.)"""
        running, flag = self._cancel
        if running != number or not self.queue.running(number):
            return False
        flag.set()
        return True

    def report_of(self, number: int) -> SolveReport | None:
        return self.queue.report_of(number)

    def _progress(self, line) -> None:
        """The running solve's progress line: its figures are kept for the action feedback."""
        figures = getattr(line, "figures", None)
        self.figures = {**self.figures, **(figures or {}), "line": str(line).strip()}

    def _self_triggered(self, est: StateEstimate, stamp: float, plan: Plan) -> bool:
        """Ask the re-plan policy about an accepted estimate; when a re-plan is due, queue it
        and withhold the estimate's thrust command until it has finished -- unless it is a
        stage boundary's and the plan's feedback law serves it (``_fly_law``)."""
        mass = self.mass_at(stamp, plan)
        if self.trigger is None or mass is None:
            return False
        reason = self.trigger.observe(stamp, est.pos_m, est.vel_m_s, mass, plan)
        if reason is None:
            return False
        if reason is Reason.STAGE and self._fly_law(est, stamp, mass, plan):
            return False
        self._withhold_for_replan(f"self-{reason}-{stamp:.3f}", stamp)
        return True

    def mass_at(self, stamp: float, plan: Plan | None) -> float | None:
        """The spacecraft's mass [kg] at a state estimate's time: the mass estimate of that
        time, or the newest before it carried to it by the plan's consumption in between (a
        state and a mass estimate of one epoch come on two topics, in either order: a state
        taken with the mass of the estimate before ran the re-plan policy and the feedback law
        on a mass a stage's propellant too high; docs/design-notes.md, the mass of an
        estimate's time)."""
        sample = self.queue.mass_sample_for(stamp)
        if sample is None:
            return None
        t_mass, mass = sample
        if plan is not None and stamp - t_mass > TIME_TOLERANCE_S:
            then, now = plan.mass_at(t_mass), plan.mass_at(stamp)
            if then is not None and now is not None:
                mass += now - then
        return mass

    def _fly_law(self, est: StateEstimate, stamp: float, mass: float, plan: Plan) -> bool:
        """The stage's thrust from the plan's feedback law where the estimate is inside the
        laws' validity: the prediction restarts from the estimate, the schedule with the law's
        thrust is published, an OK event with code FEEDBACK_LAW says so. False: re-plan."""
        if self.laws is None:
            return False
        served = self.laws.serve(plan, stamp, est.pos_m, est.vel_m_s, mass)
        if served is None:
            return False
        self.trigger.replanned(stamp, est.pos_m, est.vel_m_s, mass)
        self.laws_served += 1
        self._publish(plan, None)
        self.out.diag(Level.OK, Code.FEEDBACK_LAW,
                      f"stage {served.stage}: thrust from the plan's feedback law",
                      {"request_id": f"law-{stamp:.3f}", "stage": str(served.stage),
                       "deviation_position_m": f"{served.position_m:.3f}",
                       "deviation_velocity_m_s": f"{served.velocity_m_s:.6f}",
                       "thrust_n": " ".join(f"{v:.9g}" for v in served.thrust_n),
                       "evaluation_s": f"{served.evaluation_s:.6f}"}, stamp)
        return True

    def _maybe_replan_after_restart(self) -> None:
        if self._replan_on_first_estimate and self.queue.has_estimates():
            self._replan_on_first_estimate = False
            self.queue.enqueue("restart", None)

    # ------------------------------------------------------------------ plans
    def _restore(self) -> None:
        """Start-up after a crash: adopt the persisted plan and re-plan at the first estimate."""
        try:
            plan = self.planner.restore_plan(self.persist_file)
        except DaddyError as exc:
            self.out.diag(Level.ERROR, Code.PLAN_FILE_ERROR, f"persist_file not restored: {exc}",
                          {"field": "persist_file"}, None)
            return
        self._publish(plan, None)
        self._replan_on_first_estimate = True
        self.out.diag(Level.WARN, Code.RESTORED,
                      f"restored the persisted plan (epoch {plan.epoch_s:.3f} s); re-planning "
                      "at the first estimate", {"request_id": "restored"}, plan.epoch_s)

    def _persist(self) -> str:
        """Write the current plan to persist_file (if set); returns a problem or ''."""
        if not self.persist_file:
            return ""
        try:
            self.planner.save_plan(self.persist_file)
        except (OSError, ValueError) as exc:
            return f"persist_file not written: {exc}"
        return ""

    def _adopt_nominal(self) -> Plan | None:
        """Adopt the nominal plan at the first estimate (state and mass both received)."""
        state = self.queue.state_for(None)
        plan_file = self.plan_file
        if not plan_file or state is None or not self.queue.has_estimates():
            return None
        stamp = state.stamp_s
        try:
            plan = self.planner.load_plan(plan_file, stamp)
        except Exception as exc:
            self.out.diag(Level.ERROR, Code.PLAN_FILE_ERROR, f"cannot load plan_file: {exc}", {},
                          stamp)
            self.plan_file = ""
            return None
        self._publish(plan, stamp)
        self._persist()
        self.out.diag(Level.OK, Code.PLAN_ADOPTED, f"adopted nominal plan {Path(plan_file).name}",
                      {"request_id": "nominal"}, stamp)
        return plan

    def adopt_plan(self, plan: Plan) -> None:
        """Make ``plan`` the current plan and publish it (e.g. a nominal computed elsewhere)."""
        self.planner.set_plan(plan)
        self._publish(plan, plan.epoch_s)
        self._persist()
        self.out.diag(Level.OK, Code.PLAN_ADOPTED, "adopted a plan",
                      {"request_id": plan.request_id or "adopted"}, plan.epoch_s)

    # ------------------------------------------------------------------ worker
    def _work(self) -> None:
        while True:
            req = self.queue.take()
            if req is None:
                return
            self._cancel = (self.queue.started, threading.Event())   # (take() numbered it)
            self.figures = {}
            try:
                self._replan_once(req.request_id, req.stamp_s, req.cold, req.time_budget_s)
            except Exception as exc:  # never let the worker die
                self._finish(req.request_id, None, Level.ERROR, Code.INTERNAL_ERROR,
                             f"internal error: {exc!r}", None)
            finally:
                self.queue.done()

    def _replan_once(self, request_id: str, request_stamp: float | None, cold: bool = False,
                     time_budget_s: float | None = None) -> None:
        started = {"solve_start_unix_s": f"{time.time():.6f}"}
        try:
            state = self.queue.state_for(request_stamp)
        except InputRejected as exc:
            self._finish(request_id, None, Level.ERROR, exc.code, f"input rejected: {exc}",
                         request_stamp, started)
            return
        now = request_stamp if request_stamp is not None else (state.stamp_s if state else None)
        mass = None if state is None else self.mass_at(state.stamp_s, self.planner.plan)
        if state is None or mass is None:
            self._finish(request_id, None, Level.ERROR, Code.NO_ESTIMATE,
                         "no valid state_estimate and mass_estimate yet", now, started)
            return
        pos, vel, stamp = state.pos_m, state.vel_m_s, state.stamp_s
        if self.trigger is not None:   # the prediction restarts from the estimate solved from
            self.trigger.replanned(stamp, pos, vel, mass)
        started["state_stamp_s"] = f"{stamp:.9f}"
        for key, sigma in (("state_position_sigma_m", state.pos_sigma_m),
                           ("state_velocity_sigma_m_s", state.vel_sigma_m_s)):
            if sigma is not None:   # from the estimate's covariances, where it gave them
                started[key] = f"{sigma:.6g}"
        # a plan that does not fit the estimate is no warm start either (a restarted node's
        # nominal days into the flight): solved cold from the estimate
        plan = self.planner.plan
        misfit = plan is not None and not self.fit.check(plan, stamp, pos, vel).fits
        watch = dict(time_budget_s=time_budget_s, cancel=self._cancel[1],
                     progress=self._progress)
        try:
            out = self.planner.replan(pos, vel, mass, stamp, request_id, now_s=request_stamp,
                                      cold=cold or misfit, **watch)
            if misfit and not out.ok and out.code is not Code.CANCELLED:
                # the cold start's fallback: the warm start from the plan in force (a plan
                # solved from the estimate fits it, whichever start found it), where the cold
                # solve failed (docs/design-notes.md: cold re-plan, warm fallback)
                out = self.planner.replan(pos, vel, mass, stamp, request_id,
                                          now_s=request_stamp, cold=False, **watch)
        except InputRejected as exc:
            self._finish(request_id, None, Level.ERROR, exc.code, f"input rejected: {exc}", now,
                         started)
            return
        self.replans += 1
        if out.ok:
            why = self._persist()
            if why:
                out.level, out.reason = Level.WARN, f"{out.reason}; {why}"
        self._finish(request_id, out, out.level, out.code, out.reason, stamp, started)
        if self.laws is not None and out.ok:   # the new plan's laws, off the estimates' path
            self.laws.prepare(self.planner.plan)

    def _finish(self, request_id, out, level: Level, code: Code, reason: str, stamp,
                extra=None) -> None:
        plan = self.planner.plan
        if plan is not None:
            self._publish(plan, stamp if out is not None and out.ok else None)
        values = solve_values(request_id, self.planner.method, out, plan,
                              self.planner.units.lu_km, extra or {})
        self.out.diag(level, code, reason, values, stamp)
        self.out.solved(level, reason, out.solve_time_s if out is not None else None)
        self._release_withheld(plan)
        self.queue.record(SolveReport(request_id, level, code, reason, out, plan))

    def _release_withheld(self, plan: Plan | None) -> None:
        """The thrust commands withheld for the estimates that triggered this re-plan (or were
        coalesced into it), from the plan now in force; none while inactive."""
        with self._withheld_lock:
            stamps, self._withheld = self._withheld, []
        if plan is None or not self.active():
            return
        self._answer_unanswered(plan)
        for s in stamps:
            try:
                est = self.queue.state_for(s)   # the estimate of that stamp (RTN plans turn)
            except InputRejected:
                continue
            fit = self.fit.check(plan, s, est.pos_m, est.vel_m_s)
            if fit.fits:
                self.out.publish_thrust(plan.command_at(s, est.pos_m, est.vel_m_s), s)
                continue
            # the re-plan failed and the plan in force is far from the estimate: the safe value
            self.out.publish_thrust(np.zeros(3), s)
            self.out.diag(Level.ERROR, Code.PLAN_DOES_NOT_FIT,
                          f"zero thrust: no plan fits the estimate (the plan in force is "
                          f"{fit.position_m / 1e3:.6g} km, {fit.velocity_m_s:.6g} m/s from it)",
                          fit.values(s), s)

    def stop(self) -> None:
        """Stop the worker (the solve in progress, if any, finishes first)."""
        self.queue.stop()
        if self._worker is not None:
            self._worker.join(timeout=5.0)
            self._worker = None


def solve_values(request_id: str, method: str, out, plan, lu_km: float, extra: dict) -> dict:
    """The values of a finished re-plan's diagnostic: the request, the solve (``out``: its
    ``ReplanOutcome``, or None when none ran) and the plan in force."""
    values = {"request_id": request_id, "method": method,
              "warm_start": "yes" if out is not None and out.warm_start else "no", **extra}
    if out is not None:
        values.update({"solve_time_s": f"{out.solve_time_s:.4f}",
                       "iterations": str(out.iterations),
                       "plan_kept": "no" if out.ok else "yes"})
    if plan is not None:
        values.update({"max_violation": f"{plan.max_violation:.3e}",
                       "final_mass_kg": f"{plan.states_si[-1, 6]:.4f}",
                       "thrust_bound_n": f"{plan.thrust_bound_n:.6g}"})
        margin = plan.solution.min_path_margin
        if margin is not None:   # a keep-out scenario: its margin in km
            values["keep_out_margin_km"] = f"{margin * lu_km:.3f}"
    return values
