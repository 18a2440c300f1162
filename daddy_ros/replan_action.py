"""The node's Replan action (``daddy_interfaces/action/Replan``, msg_docs/replan_action.md): a
re-plan as a goal with feedback, result and cancel, as nav2's planner servers offer theirs.

A goal queues a re-plan in the session (coalesced with the other requests as the topic and the
service are: the solve that serves it may serve them too), feeds back the solver's progress
every ``FEEDBACK_PERIOD_S`` and returns the solve's outcome and the plan in force. A cancel
stops the running solve within one solver iteration, the plan in force kept, unless other
goals still wait for that solve: then, as for a goal whose solve has not started, the goal is
answered CANCELLED at once and the solve goes on for the others.

Callbacks are coroutines awaiting the worker (``spin.pause``), so one single-threaded executor
serves the goals, the estimates and the service together. The action needs the
daddy_interfaces package (interfaces/build.py); without it the node offers none and says so.
"""
from __future__ import annotations

import threading
import time
import uuid

from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.qos import QoSProfile, ReliabilityPolicy

from . import conversions as cv
from .plan import Code, Level
from .spin import pause

try:
    from daddy_interfaces.action import Replan
except ImportError:   # not built: the node runs without its action
    Replan = None

ACTION_NAME = "~/replan_action"
FEEDBACK_PERIOD_S = 0.2   # feedback while a goal waits or its solve runs [s]
POLL_S = 0.05             # how often a goal looks at the worker [s]
# the action's goal, cancel and result services: a burst of goals (a GNC client re-trying, a
# campaign) must queue, not overflow the services' default depth of 10 (seen: 9 of 20 goals
# sent within 20 ms never answered; reliability campaign, action row)
SERVICE_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
FIGURES = ("homotopy_step", "homotopy_steps", "aul_iteration", "ddp_iterations", "cost",
           "max_violation", "line")


def available() -> bool:
    """Whether the daddy_interfaces package is importable."""
    return Replan is not None


class ReplanActionServer:
    """The Replan action of ``node`` (a GuidanceNode): ``session()`` the configured session or
    None, ``active()`` whether the node is active, ``frame_id()`` its frame."""

    def __init__(self, node, session, active, frame_id):
        self.node, self.session, self.active, self.frame_id = node, session, active, frame_id
        self._waiting: dict[int, set] = {}   # solve number -> the goals waiting for it
        self._lock = threading.Lock()
        self.server = ActionServer(
            node, Replan, node.resolve_service_name(ACTION_NAME), self._execute,
            goal_callback=self._on_goal, cancel_callback=self._on_cancel,
            callback_group=ReentrantCallbackGroup(), goal_service_qos_profile=SERVICE_QOS,
            result_service_qos_profile=SERVICE_QOS, cancel_service_qos_profile=SERVICE_QOS)

    def destroy(self) -> None:
        self.server.destroy()

    # ------------------------------------------------------------------ goal and cancel
    def _on_goal(self, goal) -> GoalResponse:
        """Every goal is accepted; one the node cannot serve (inactive, wrong frame, bad
        budget) is answered at once with its code (a result says why, a rejection does not)."""
        return GoalResponse.ACCEPT

    def _on_cancel(self, goal_handle) -> CancelResponse:
        return CancelResponse.ACCEPT

    def _refusal(self, goal) -> tuple[Code, str] | None:
        if not self.active() or self.session() is None:
            return Code.NOT_ACTIVE, "the node is not active"
        if goal.header.frame_id not in ("", self.frame_id()):
            return (Code.INPUT_REJECTED, f"goal.header.frame_id {goal.header.frame_id!r} is "
                    f"not {self.frame_id()!r}")
        budget = goal.time_budget_s
        if not (budget == budget and 0.0 <= budget <= 3600.0):
            return (Code.INPUT_REJECTED, f"goal.time_budget_s {budget!r} is not in [0, 3600] s "
                    "(0: the node's time_budget_s)")
        return None

    # ------------------------------------------------------------------ execution
    async def _execute(self, goal_handle):
        goal = goal_handle.request
        request_id = goal.request_id or f"action-{uuid.UUID(bytes=bytes(goal_handle.goal_id.uuid))}"
        refusal = self._refusal(goal)
        if refusal is not None:
            goal_handle.abort()
            return _result(request_id, refusal[0], Level.ERROR, refusal[1])
        session, t0 = self.session(), time.monotonic()
        stamp = cv.stamp_to_s(goal.header.stamp) or None
        number = session.request(request_id, stamp, goal.cold, goal.time_budget_s or None)
        me = bytes(goal_handle.goal_id.uuid)
        with self._lock:
            self._waiting.setdefault(number, set()).add(me)
        last_feedback, cancelling = -1.0, False
        try:
            while session.report_of(number) is None:
                if goal_handle.is_cancel_requested and not cancelling:
                    cancelling = True
                    early = self._cancel(session, number, me)
                    if early is not None:
                        goal_handle.canceled()
                        return _result(request_id, Code.CANCELLED, Level.WARN, early,
                                       plan=session.planner.plan, frame_id=self.frame_id())
                if time.monotonic() - last_feedback >= FEEDBACK_PERIOD_S:
                    last_feedback = time.monotonic()
                    goal_handle.publish_feedback(self._feedback(session, number, t0))
                if session.queue.stopped():
                    goal_handle.abort()
                    return _result(request_id, Code.NOT_ACTIVE, Level.ERROR,
                                   "the node stopped before the solve finished")
                await pause(self.node, POLL_S)
        finally:
            with self._lock:
                self._waiting.get(number, set()).discard(me)
        report = session.report_of(number)
        result = _result(request_id, report.code, report.level, report.reason,
                         report.outcome, report.plan, self.frame_id())
        if goal_handle.is_cancel_requested and report.code is Code.CANCELLED:
            goal_handle.canceled()
        elif report.outcome is not None and report.outcome.ok:
            goal_handle.succeed()
        else:
            goal_handle.abort()
        return result

    def _cancel(self, session, number: int, me: bytes) -> str | None:
        """A cancel request of the goal ``me`` served by solve ``number``: the solve is stopped
        only when no other goal still waits for it; None when it was (its report answers the
        goal), else why the goal is answered at once (the solve not started, or going on for
        the other goals)."""
        with self._lock:
            others = self._waiting.get(number, set()) - {me}
            self._waiting.get(number, set()).discard(me)
        if others:
            return (f"cancelled; the solve goes on for the {len(others)} other goal(s) it "
                    "serves: the plan in force is kept for this goal")
        if session.cancel(number):
            return None
        return "cancelled before its solve started: the plan in force is kept"

    def _feedback(self, session, number: int, t0: float):
        fb = Replan.Feedback(state="QUEUED" if session.queue.waiting(number) else "SOLVING",
                             elapsed_s=time.monotonic() - t0)
        figures = session.figures if fb.state == "SOLVING" else {}
        for name in FIGURES:
            if name in figures:
                kind = type(getattr(fb, name))
                setattr(fb, name, kind(figures[name]) if kind is not str
                        else figures[name][:500])
        return fb


def _result(request_id: str, code: Code, level: Level, message: str, outcome=None, plan=None,
            frame_id: str = ""):
    """The goal's result: the outcome, the solve's figures and the plan in force."""
    r = Replan.Result(request_id=request_id, code=str(code), level=ord(cv.LEVELS[level]),
                      message=message[:500], solve_time_s=-1.0)
    if outcome is not None:
        r.plan_stored = bool(outcome.ok)
        r.solve_time_s = float(outcome.solve_time_s)
        r.iterations = int(outcome.iterations.get("ddp", 0))
        r.warm_start = bool(outcome.warm_start)
    if plan is not None:
        r.schedule = cv.plan_to_joint_trajectory(plan, cv.schedule_frame(plan, frame_id))
        r.final_mass_kg = float(plan.states_si[-1, 6])
        r.max_violation = float(plan.max_violation)
    return r
