"""The rclpy guidance node ``daddy_guidance``: a managed (lifecycle) node over a ROS-free
``GuidanceSession``, as nav2's servers are built. Callbacks only translate messages; the
session's worker thread runs the re-optimisations, so subscriptions keep being served. Its
parameters come from ``config`` (``parameters``), its topics from ``interface``, its reports go
through ``diagnostics``. See msg_docs/ for the interface contract.
"""
from __future__ import annotations

import math
import time

import numpy as np
from geometry_msgs.msg import InertiaStamped
from nav_msgs.msg import Odometry
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.lifecycle import LifecycleNode, State, TransitionCallbackReturn
from rcl_interfaces.msg import SetParametersResult
from rclpy.subscription import Subscription
from std_msgs.msg import Header
from std_srvs.srv import Trigger

from daddy_core.errors import DaddyError

from . import bond
from . import conversions as cv
from . import interface as io
from . import parameters
from . import replan_action
from .checks import InputRejected
from .config import NodeConfig, PlannerConfig, TriggerConfig, bundled_plan
from .diagnostics import DiagnosticsReporter
from .plan import Code, Level, Plan
from .planner import GuidancePlanner
from .feedback import FeedbackLaws
from .self_trigger import ReplanTrigger
from .session import GuidanceSession, SolveReport
from .spin import pause, run_node

NODE_NAME = io.NODE_NAME


class GuidanceNode(LifecycleNode):
    """The guidance node as a managed (lifecycle) node:

    - unconfigured: parameters declared (every one settable); nothing subscribed.
    - configure: the scenario loaded and checked, the planner and its session built,
      subscriptions, the Trigger service and the Replan action (``replan_action``: where the
      daddy_interfaces package is built) created, a persisted plan restored. A bad parameter
      fails the transition with an ERROR diagnostic naming it (the node stays unconfigured).
    - activate: estimates and requests are served, re-plans run, ``thrust_command`` is published.
    - deactivate: no thrust commands and no re-plans; estimates and requests are dropped
      (requests with an ERROR diagnostic); the last plan stays latched on its topics.
    - cleanup / shutdown: the worker stopped, subscriptions, service and action destroyed;
      after shutdown (finalized) ``when_finalized`` is called (``spin.run_node``: the process
      exits).

    ``autostart`` (default true) configures and activates in the constructor, so a plain start
    behaves as before; a failed configuration then raises DaddyError.
    """

    def __init__(self, namespace: str | None = None, **overrides):
        """``namespace``: in-process instances side by side (a command line sets it with
        ``-r __ns:=/sc1``); ``overrides``: parameter defaults. One node: the service and the
        action wait for the worker in coroutine callbacks, so a single-threaded executor
        serves everything."""
        super().__init__(NODE_NAME, namespace=namespace)
        try:
            parameters.declare(self, overrides)
        except DaddyError:
            self.destroy_node()
            raise
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.when_finalized = None   # called after the shutdown transition (``spin.run_node``)
        self.fqn = self.get_fully_qualified_name()
        self.planner: GuidancePlanner | None = None
        self.session: GuidanceSession | None = None
        self.frame_id = self._param("frame_id")
        self._active = False
        self._entities: list = []   # subscriptions and the service made at configure
        self.action: replan_action.ReplanActionServer | None = None
        self.bond: bond.Bond | None = None
        self._configure_error = ""
        # outputs exist in every state: diagnostics always, the plan latched across deactivation,
        # thrust commands only while active (a lifecycle publisher)
        self.pub_schedule = self._publisher(io.SCHEDULE)
        self.pub_path = self._publisher(io.PATH)
        self.pub_thrust = self.create_lifecycle_publisher(
            io.THRUST.msg_type, self._topic_name(io.THRUST), io.THRUST.qos)
        self.diagnostics = DiagnosticsReporter(
            self._publisher(io.DIAGNOSTICS), self.fqn, self.get_logger(),
            lambda: self.get_clock().now().nanoseconds * 1e-9)
        period = self._param("diagnostics_period_s")   # (its descriptor's range: 0-3600 s)
        if period > 0.0:   # live health: an aggregator never sees the node stale between events
            self.create_timer(period, self._health)
        if self._param("autostart"):
            if self.trigger_configure() is not TransitionCallbackReturn.SUCCESS:
                raise DaddyError(self._configure_error or "configure failed")
            self.trigger_activate()

    def _param(self, name: str):
        return self.get_parameter(name).value

    def _topic_name(self, topic: io.Topic) -> str:
        return topic.default if topic.parameter is None else self._param(topic.parameter)

    def _publisher(self, topic: io.Topic):
        return self.create_publisher(topic.msg_type, self._topic_name(topic), topic.qos)

    def interface_topics(self) -> dict:
        """{absolute topic: (message class, QoS)} of every topic the node reads or writes, with
        the QoS it uses (for a recorder: the latched outputs are transient local)."""
        return {self.resolve_topic_name(self._topic_name(t)): (t.msg_type, t.qos)
                for t in io.TOPICS}

    @property
    def lifecycle_state(self) -> str:
        """The current lifecycle state's label (unconfigured, inactive, active, finalized)."""
        return self._state_machine.current_state[1]

    @property
    def queue(self):
        return self.session.queue

    @property
    def replans(self) -> int:
        return 0 if self.session is None else self.session.replans

    @property
    def coalesced(self) -> int:
        """Requests merged into a later solve so far."""
        return 0 if self.session is None else self.session.queue.coalesced

    # ------------------------------------------------------------------ lifecycle
    def _config(self, cls, changes: dict | None = None):
        """A settings dataclass of ``config`` from the parameters (``changes``: new values)."""
        changes = changes or {}
        return cls(**{f: changes[f] if f in changes else self._param(f)
                      for f in cls.__dataclass_fields__ if self.has_parameter(f)})

    def on_configure(self, state: State) -> TransitionCallbackReturn:
        config = self._config
        try:
            self.planner = GuidancePlanner(config=config(PlannerConfig))
        except DaddyError as exc:
            self._configure_error = str(exc)
            self.diag(Level.ERROR, Code.CONFIGURE_FAILED, f"configure failed: {exc}",
                       {"field": "parameters"}, None)
            return TransitionCallbackReturn.FAILURE
        cfg = config(NodeConfig)
        self.frame_id = cfg.frame_id
        policy = config(TriggerConfig)
        self.session = GuidanceSession(self.planner, ReplanTrigger.for_planner(self.planner, policy),
                                       cfg.plan_file or self._bundled_plan(), cfg.persist_file,
                                       self, lambda: self._active,
                                       FeedbackLaws.for_planner(self.planner, policy))
        estimates = MutuallyExclusiveCallbackGroup()
        # requests in their own group: a request flood must not delay the estimates
        inputs = ((io.STATE, self._on_state, estimates), (io.MASS, self._on_mass, estimates),
                  (io.REQUEST, self._on_request, MutuallyExclusiveCallbackGroup()))
        self._entities = [
            *(self.create_subscription(t.msg_type, self._topic_name(t), callback, t.qos,
                                       callback_group=group)
              for t, callback, group in inputs),
            self.create_service(Trigger, self.resolve_service_name(io.REPLAN_SERVICE),
                                self._on_service, callback_group=ReentrantCallbackGroup())]
        if replan_action.available():
            self.action = replan_action.ReplanActionServer(
                self, lambda: self.session, lambda: self._active, lambda: self.frame_id)
        else:
            self.diag(Level.WARN, Code.NOT_BUILT,
                      "the daddy_interfaces package is not built: no Replan action (the topic "
                      "and the service serve re-plans; make interfaces builds it)", {}, None)
        self.get_logger().info(f"daddy_guidance configured: scenario {self.planner.case.name}, "
                               f"method {self.planner.method}, frame {self.frame_id}")
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: State) -> TransitionCallbackReturn:
        self._active = True
        self._form_bond()
        self.get_logger().info("daddy_guidance ready: active")
        return super().on_activate(state)

    def on_deactivate(self, state: State) -> TransitionCallbackReturn:
        self._active = False
        self._break_bond()
        self.get_logger().info("daddy_guidance inactive: no thrust commands, no re-plans")
        return super().on_deactivate(state)

    def _form_bond(self) -> None:
        """The bond with nav2's lifecycle manager (``bond``), as nav2's servers form it on
        activation; ``bond_heartbeat_period_s`` 0: none."""
        period = self._param("bond_heartbeat_period_s")
        if period <= 0.0 or self.bond is not None:
            return
        if not bond.available():
            self.diag(Level.WARN, Code.NOT_BUILT, "the bond message package is not built: no "
                      "bond with a lifecycle manager (make interfaces builds it)", {}, None)
            return
        self.bond = bond.Bond(self, self.get_name(), period, self._bond_broken)

    def _bond_broken(self, reason: str) -> None:
        self.diag(Level.WARN, Code.BOND_BROKEN, f"bond broken: {reason}; guidance goes on",
                  {"bond_id": self.get_name()}, None)

    def _break_bond(self) -> None:
        if self.bond is not None:
            self.bond.destroy()
            self.bond = None

    def on_cleanup(self, state: State) -> TransitionCallbackReturn:
        self._teardown()
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: State) -> TransitionCallbackReturn:
        self._active = False
        self._teardown()
        if self.when_finalized is not None:
            self.when_finalized()
        return TransitionCallbackReturn.SUCCESS

    def _teardown(self) -> None:
        """Stop the worker and destroy what configure made. The planner object stays (a solve
        still finishing after the 5 s join may use it); the next configure builds a new one."""
        self._break_bond()
        self.stop()
        for entity in self._entities:
            if isinstance(entity, Subscription):
                self.destroy_subscription(entity)
            else:
                self.destroy_service(entity)
        self._entities = []
        if self.action is not None:
            self.action.destroy()
            self.action = None
        self.session = None

    def _bundled_plan(self) -> str:
        p = bundled_plan(self.planner.case.name, self.planner.config.fuel_optimal)
        # (the bundled plans have the case's own stages and no keep-out)
        same = not self.planner.config.stages and self.planner.base_problem.g_path is None
        return str(p) if p is not None and same else ""

    def _on_set_parameters(self, params):
        """Updates (``parameters.verdict``); a rejected update changes nothing. While
        configured, the ``runtime`` parameters go to the session (``reconfigure``: the
        estimates' tests at once, the solver's settings at the next re-plan)."""
        result = parameters.verdict(params, self.has_parameter, self.session is not None)
        if result.successful and self.session is not None:
            changes = {p.name: p.value for p in params if p.name in parameters.RUNTIME}
            try:
                self.session.reconfigure(changes, self._config(TriggerConfig, changes))
            except DaddyError as exc:
                result = SetParametersResult(successful=False, reason=str(exc))
        if not result.successful:
            self.diag(Level.WARN, Code.PARAMETER_REJECTED,
                       f"parameter update rejected: {result.reason}", {"field": "parameters"},
                       None)
        return result

    # ------------------------------------------------------------------ inputs
    def _reject(self, topic: str, reason: str, stamp: float,
                code: Code = Code.INPUT_REJECTED) -> None:
        """An input that is not used: ERROR diagnostic naming the field; nothing else changes."""
        self.diag(Level.ERROR, code, f"input rejected: {reason}",
                   {"topic": topic, "stamp_s": f"{stamp:.9f}"},
                   stamp if math.isfinite(stamp) and stamp > 0 else None, log_every_s=1.0)

    def _on_state(self, msg: Odometry):
        if not self._active:   # inactive: estimates are not served (no thrust commands)
            return
        stamp, frame = cv.stamp_to_s(msg.header.stamp), msg.header.frame_id
        if frame != self.frame_id:
            self._reject("state_estimate", f"state_estimate.header.frame_id {frame!r} is not "
                         f"{self.frame_id!r}", stamp)
            return
        try:
            self.session.on_state(cv.odometry_to_state(msg), stamp)
        except InputRejected as exc:
            self._reject("state_estimate", str(exc), stamp, exc.code)

    def _on_mass(self, msg: InertiaStamped):
        if not self._active:
            return
        stamp = cv.stamp_to_s(msg.header.stamp)
        try:
            self.session.on_mass(float(msg.inertia.m), stamp)
        except InputRejected as exc:
            self._reject("mass_estimate", str(exc), stamp, exc.code)

    def _on_request(self, msg: Header):
        if not self._active:
            self.diag(Level.ERROR, Code.NOT_ACTIVE,
                       f"request rejected: the node is {self.lifecycle_state}, not active",
                       {"request_id": msg.frame_id or "topic"},
                       cv.stamp_to_s(msg.stamp) or None, log_every_s=1.0)
            return
        self.session.request(msg.frame_id or "topic", cv.stamp_to_s(msg.stamp))

    async def _on_service(self, request, response):
        """The Trigger service: a re-plan from the newest estimate, answered when it has
        finished (a coroutine: the estimates are served while it waits)."""
        session = self.session
        if not self._active or session is None:
            response.success = False
            response.message = f"ERROR: the node is {self.lifecycle_state}, not active"
            return response
        number = session.request(f"service-{time.monotonic_ns()}", None)
        # the next solve to start absorbs this request (coalescing); wait for it to finish
        end = time.monotonic() + self.planner.time_budget_s * 3 + 10
        report: SolveReport | None = None
        while report is None and time.monotonic() < end and not session.queue.stopped():
            await pause(self, replan_action.POLL_S)
            report = session.report_of(number)
        if report is None:
            response.success, response.message = False, "timed out waiting for the solve"
            return response
        stored = report.outcome is not None and report.outcome.ok
        response.success = stored and report.level is not Level.ERROR
        response.message = f"{report.level}: {report.reason}"
        return response

    def adopt_plan(self, plan: Plan) -> None:
        """Make ``plan`` the current plan and publish it (e.g. a nominal computed elsewhere)."""
        self.session.adopt_plan(plan)

    # ------------------------------------------------------------------ outputs (session.Outputs)
    def publish_plan(self, plan: Plan, stamp: float | None) -> None:
        self.pub_schedule.publish(cv.plan_to_joint_trajectory(
            plan, cv.schedule_frame(plan, self.frame_id), stamp))
        self.pub_path.publish(cv.plan_to_path(plan, self.frame_id))

    def publish_thrust(self, thrust_n: np.ndarray, stamp: float) -> None:
        self.pub_thrust.publish(cv.thrust_command(thrust_n, stamp, self.frame_id))

    def diag(self, level: Level, code: Code, message: str, values: dict, stamp,
             log_every_s: float | None = None) -> None:
        self.diagnostics.event(level, code, message, values, stamp, log_every_s)

    def solved(self, level: Level, reason: str, solve_s: float | None) -> None:
        self.diagnostics.solved(level, reason, solve_s)

    def _health(self) -> None:
        s = self.session
        self.diagnostics.health(self.lifecycle_state, s is not None, self._active,
                                None if s is None else self.planner.plan,
                                None if s is None else s.queue.state_for(None),
                                0 if s is None else s.queue.finished, self.coalesced)

    def report_internal_error(self, exc: BaseException) -> None:
        """An exception escaped a callback (``spin.run_node`` keeps spinning)."""
        self.diag(Level.ERROR, Code.INTERNAL_ERROR, f"internal error in a callback: {exc!r}",
                   {}, None)

    def stop(self) -> None:
        """Stop the session's worker (the solve in progress, if any, finishes first)."""
        if self.session is not None:
            self.session.stop()


def main(args=None) -> int:
    return run_node(GuidanceNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
