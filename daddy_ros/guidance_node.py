"""The rclpy guidance node ``daddy_guidance``: a thin layer over GuidancePlanner.

Callbacks only translate messages; re-optimisations run on a worker thread so subscriptions keep
being served, and triggers arriving during a solve are coalesced into one follow-up solve on the
newest state. See msg_docs/ for the interface contract.
"""
from __future__ import annotations

import math
import os
import signal
import sys
import threading
import time
from pathlib import Path

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import InertiaStamped, Vector3Stamped
from nav_msgs.msg import Odometry
from nav_msgs.msg import Path as PathMsg
from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                SetParametersResult)
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.executors import SingleThreadedExecutor
from rclpy.lifecycle import LifecycleNode, State, TransitionCallbackReturn
from rclpy.node import Node
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy,
                       qos_profile_sensor_data)
from rclpy.signals import SignalHandlerOptions
from rclpy.subscription import Subscription
from std_msgs.msg import Header
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory

from daddy_core.catalogue import list_cases, load_case
from daddy_core.errors import DaddyError

from . import conversions as cv
from .checks import InputRejected
from .config import NodeConfig, PlannerConfig, TriggerConfig, bundled_plan, parameters
from .plan import Code, Level
from .planner import GuidancePlanner
from .request_queue import RequestQueue
from .self_trigger import ReplanTrigger
from .spin import SpinThread, spin_guarded

NODE_NAME = "daddy_guidance"
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL, history=HistoryPolicy.KEEP_LAST)
RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                      history=HistoryPolicy.KEEP_LAST)

NAMES = {p.name for p in parameters()}
RUNTIME = {p.name for p in parameters() if p.runtime}   # time_budget_s, staleness_s


def _descriptor(p) -> ParameterDescriptor:
    """The ROS descriptor of a ``config`` parameter: its description, read_only for the
    ``static`` ones, its range where it has bounds, and when it may change."""
    when = ("settable in every state" if p.runtime else "fixed at construction" if p.static
            else "settable while unconfigured")
    d = ParameterDescriptor(description=p.description, read_only=p.static,
                            additional_constraints=when)
    if p.bounds is not None:
        lo, hi = p.bounds
        if isinstance(p.default, float):
            d.floating_point_range = [FloatingPointRange(from_value=float(lo), to_value=float(hi),
                                                         step=0.0)]
        else:
            d.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=1)]
    return d


class GuidanceNode(LifecycleNode):
    """The guidance node as a managed (lifecycle) node, as nav2's servers are:

    - unconfigured: parameters declared (every one settable); nothing subscribed.
    - configure: the scenario loaded and checked, the planner built, subscriptions and the
      Trigger service created, a persisted plan restored. A bad parameter fails the transition
      with an ERROR diagnostic naming it (the node stays unconfigured).
    - activate: estimates and requests are served, re-plans run, ``thrust_command`` is published.
    - deactivate: no thrust commands and no re-plans; estimates and requests are dropped
      (requests with an ERROR diagnostic); the last plan stays latched on its topics.
    - cleanup / shutdown: the worker stopped, subscriptions and service destroyed.

    ``autostart`` (default true) configures and activates in the constructor, so a plain start
    behaves as before; a failed configuration then raises DaddyError.
    """

    def __init__(self, separate_service_node: bool = False, namespace: str | None = None,
                 **overrides):
        """``separate_service_node``: host the blocking Trigger service on a helper node
        ``daddy_guidance_service`` in this node's namespace, to be spun on its own executor
        (``run`` does this; ``self.service_node``); False hosts it here in a reentrant callback
        group, which needs a multi-threaded executor. ``namespace``: in-process instances side
        by side (a command line sets it with ``-r __ns:=/sc1``); ``overrides``: parameter
        defaults."""
        super().__init__(NODE_NAME, namespace=namespace)
        for p in parameters():
            try:
                self.declare_parameter(p.name, overrides.get(p.name, p.default), _descriptor(p))
            except (InvalidParameterValueException, InvalidParameterTypeException) as exc:
                self.destroy_node()
                raise DaddyError(f"parameter {p.name}: {exc}") from exc
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.service_node = Node(f"{NODE_NAME}_service", namespace=self.get_namespace(),
                                 use_global_arguments=False, start_parameter_services=False,
                                 enable_rosout=False) if separate_service_node else None
        self.fqn = self.get_fully_qualified_name()
        self._last_solve: tuple = ()    # the last solve: (level, reason, solve s, unix time)
        self.planner: GuidancePlanner | None = None
        self.queue = RequestQueue()
        self.replans = 0
        self._active = False
        self._worker: threading.Thread | None = None
        self._entities: list = []   # (owner node, subscription or service) made at configure
        self._replan_on_first_estimate = False
        self._configure_error = ""
        self._configured = False
        self.trigger: ReplanTrigger | None = None   # made at configure (self_replan)
        self._withheld: list[float] = []   # estimate stamps whose thrust waits for a re-plan
        self._withheld_lock = threading.Lock()
        g = lambda n: self.get_parameter(n).value  # noqa: E731
        # outputs exist in every state: diagnostics always, the plan latched across deactivation,
        # thrust commands only while active (a lifecycle publisher)
        self.pub_schedule = self.create_publisher(JointTrajectory, g("schedule_topic"), LATCHED)
        self.pub_path = self.create_publisher(PathMsg, g("path_topic"), LATCHED)
        self.pub_thrust = self.create_lifecycle_publisher(Vector3Stamped, g("thrust_topic"),
                                                          RELIABLE)
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", RELIABLE)
        period = g("diagnostics_period_s")   # (its descriptor's range: 0-3600 s)
        if period > 0.0:   # live health: an aggregator never sees the node stale between events
            self.create_timer(period, self._health)
        if g("autostart"):
            if self.trigger_configure() is not TransitionCallbackReturn.SUCCESS:
                raise DaddyError(self._configure_error or "configure failed")
            self.trigger_activate()

    def interface_topics(self) -> dict:
        """{absolute topic: (message class, QoS)} of every topic the node reads or writes, with
        the QoS it uses (for a recorder: the latched outputs are transient local)."""
        g = lambda n: self.resolve_topic_name(self.get_parameter(n).value)  # noqa: E731
        return {g("state_topic"): (Odometry, qos_profile_sensor_data),
                g("mass_topic"): (InertiaStamped, qos_profile_sensor_data),
                g("request_topic"): (Header, RELIABLE),
                g("schedule_topic"): (JointTrajectory, LATCHED),
                g("path_topic"): (PathMsg, LATCHED),
                g("thrust_topic"): (Vector3Stamped, RELIABLE),
                "/diagnostics": (DiagnosticArray, RELIABLE)}

    @property
    def lifecycle_state(self) -> str:
        """The current lifecycle state's label (unconfigured, inactive, active, finalized)."""
        return self._state_machine.current_state[1]

    # ------------------------------------------------------------------ lifecycle
    def on_configure(self, state: State) -> TransitionCallbackReturn:
        g = lambda n: self.get_parameter(n).value  # noqa: E731
        try:
            self.planner = GuidancePlanner(config=PlannerConfig(
                **{f: g(f) for f in PlannerConfig.__dataclass_fields__ if self.has_parameter(f)}))
        except DaddyError as exc:
            self._configure_error = str(exc)
            self._diag(Level.ERROR, Code.CONFIGURE_FAILED, f"configure failed: {exc}",
                       {"field": "parameters"}, None)
            return TransitionCallbackReturn.FAILURE
        cfg = NodeConfig(**{f: g(f) for f in NodeConfig.__dataclass_fields__})
        policy = TriggerConfig(**{f: g(f) for f in TriggerConfig.__dataclass_fields__})
        self.trigger = ReplanTrigger.for_planner(self.planner, policy)
        self.frame_id = cfg.frame_id
        self.plan_file = cfg.plan_file or self._bundled_plan()
        self.persist_file = cfg.persist_file
        self.queue = RequestQueue()
        sub_group = MutuallyExclusiveCallbackGroup()
        owner = self.service_node or self
        self._entities = [
            (self, self.create_subscription(Odometry, cfg.state_topic, self._on_state,
                                            qos_profile_sensor_data, callback_group=sub_group)),
            (self, self.create_subscription(InertiaStamped, cfg.mass_topic, self._on_mass,
                                            qos_profile_sensor_data, callback_group=sub_group)),
            # requests in their own group: a request flood must not delay the estimates
            (self, self.create_subscription(Header, cfg.request_topic, self._on_request,
                                            RELIABLE,
                                            callback_group=MutuallyExclusiveCallbackGroup())),
            (owner, owner.create_service(Trigger, self.resolve_service_name("~/replan"),
                                         self._on_service,
                                         callback_group=ReentrantCallbackGroup()))]
        self._worker = threading.Thread(target=self._work, name="daddy_replan", daemon=True)
        self._worker.start()
        if self.persist_file and Path(self.persist_file).exists():
            self._restore()
        self._configured = True
        self.get_logger().info(f"daddy_guidance configured: scenario {self.planner.case.name}, "
                               f"method {self.planner.method}, frame {self.frame_id}")
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: State) -> TransitionCallbackReturn:
        self._active = True
        self.get_logger().info("daddy_guidance ready: active")
        return super().on_activate(state)

    def on_deactivate(self, state: State) -> TransitionCallbackReturn:
        self._active = False
        self.get_logger().info("daddy_guidance inactive: no thrust commands, no re-plans")
        return super().on_deactivate(state)

    def on_cleanup(self, state: State) -> TransitionCallbackReturn:
        self._teardown()
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: State) -> TransitionCallbackReturn:
        self._active = False
        self._teardown()
        return TransitionCallbackReturn.SUCCESS

    def _teardown(self) -> None:
        """Stop the worker and destroy what configure made. The planner object stays (a solve
        still finishing after the 5 s join may use it); the next configure builds a new one."""
        self.stop()
        for owner, entity in self._entities:
            if isinstance(entity, Subscription):
                owner.destroy_subscription(entity)
            else:
                owner.destroy_service(entity)
        self._entities = []
        self._configured = False

    # ------------------------------------------------------------------ parameters
    def _bundled_plan(self) -> str:
        p = bundled_plan(self.planner.case.name, self.planner.config.fuel_optimal)
        # (the bundled plans have the case's own stages and no keep-out)
        same = not self.planner.config.stages and self.planner.base_problem.g_path is None
        return str(p) if p is not None and same else ""

    def _on_set_parameters(self, params):
        """Runtime updates: the ``runtime`` parameters of ``config`` (time_budget_s and
        staleness_s, positive finite floats) in every state; every other declared parameter
        only while unconfigured (configure reads them). A rejected update changes nothing."""
        why = next((r for r in map(self._parameter_problem, params) if r), None)
        if why:
            self._diag(Level.WARN, Code.PARAMETER_REJECTED, f"parameter update rejected: {why}",
                       {"field": "parameters"}, None)
            return SetParametersResult(successful=False, reason=why)
        if self._configured:
            self.planner.update(**{p.name: p.value for p in params if p.name in RUNTIME})
        return SetParametersResult(successful=True)

    def _parameter_problem(self, p) -> str:
        if p.name in RUNTIME:
            if not (isinstance(p.value, float) and math.isfinite(p.value) and p.value > 0):
                return f"{p.name} must be a positive finite float, got {p.value!r}"
            return ""
        if p.name == "scenario" and isinstance(p.value, str):
            try:
                load_case(p.value)
            except DaddyError:
                return (f"scenario {p.value!r} is unknown (known: {', '.join(list_cases())}); "
                        "scenario is also read-only once configured")
        if p.name in NAMES and self.has_parameter(p.name) and self._configured:
            return f"{p.name} is read-only once configured (clean the node up to change it)"
        return ""

    # ------------------------------------------------------------------ inputs
    def _reject(self, topic: str, reason: str, stamp: float,
                code: Code = Code.INPUT_REJECTED) -> None:
        """An input that is not used: ERROR diagnostic naming the field; nothing else changes."""
        self._diag(Level.ERROR, code, f"input rejected: {reason}",
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
            est = cv.odometry_to_state(msg)
            self.planner.checks.check_estimate(est.pos_m, est.vel_m_s, stamp)
        except InputRejected as exc:
            self._reject("state_estimate", str(exc), stamp, exc.code)
            return
        self.queue.add_state(est.pos_m, est.vel_m_s, stamp, est.pos_sigma_m, est.vel_sigma_m_s)
        plan = self.planner.plan or self._adopt_nominal()
        # an estimate that triggers a re-plan gets its thrust command after it (_finish)
        if plan is not None and not self._self_triggered(est, stamp, plan):
            self.pub_thrust.publish(cv.thrust_command(
                plan.command_at(stamp, est.pos_m, est.vel_m_s), stamp, self.frame_id))
        self._maybe_replan_after_restart()

    def _self_triggered(self, est, stamp: float, plan) -> bool:
        """Ask the re-plan policy (``self_trigger``) about an accepted estimate; when a re-plan
        is due, queue it and withhold the estimate's thrust command until it has finished."""
        mass = self.queue.mass_for(stamp)
        if self.trigger is None or mass is None:
            return False
        reason = self.trigger.observe(stamp, est.pos_m, est.vel_m_s, mass, plan)
        if reason is None:
            return False
        with self._withheld_lock:
            self._withheld.append(stamp)
        self.queue.enqueue(f"self-{reason}-{stamp:.3f}", stamp)
        return True

    def _on_mass(self, msg: InertiaStamped):
        if not self._active:
            return
        mass, stamp = float(msg.inertia.m), cv.stamp_to_s(msg.header.stamp)
        try:
            self.planner.checks.check_mass(mass, stamp)
        except InputRejected as exc:
            self._reject("mass_estimate", str(exc), stamp, exc.code)
            return
        self.queue.add_mass(stamp, mass)
        if self.planner.plan is None:
            self._adopt_nominal()
        self._maybe_replan_after_restart()

    def _maybe_replan_after_restart(self):
        if self._replan_on_first_estimate and self.queue.has_estimates():
            self._replan_on_first_estimate = False
            self.queue.enqueue("restart", None)

    def _restore(self):
        """Start-up after a crash: adopt the persisted plan and re-plan at the first estimate."""
        try:
            plan = self.planner.restore_plan(self.persist_file)
        except DaddyError as exc:
            self._diag(Level.ERROR, Code.PLAN_FILE_ERROR, f"persist_file not restored: {exc}",
                       {"field": "persist_file"}, None)
            return
        self._publish_plan(plan, None)
        self._replan_on_first_estimate = True
        self._diag(Level.WARN, Code.RESTORED,
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

    def _adopt_nominal(self):
        """Adopt the nominal plan at the first estimate (state and mass both received)."""
        state = self.queue.state_for(None)
        plan_file = self.plan_file
        if not plan_file or state is None or not self.queue.has_estimates():
            return None
        stamp = state.stamp_s
        try:
            plan = self.planner.load_plan(plan_file, stamp)
        except Exception as exc:
            self._diag(Level.ERROR, Code.PLAN_FILE_ERROR, f"cannot load plan_file: {exc}", {},
                       stamp)
            self.plan_file = ""
            return None
        self._publish_plan(plan, stamp)
        self._persist()
        self._diag(Level.OK, Code.PLAN_ADOPTED, f"adopted nominal plan {Path(plan_file).name}",
                   {"request_id": "nominal"}, stamp)
        return plan

    def _on_request(self, msg: Header):
        if not self._active:
            self._diag(Level.ERROR, Code.NOT_ACTIVE,
                       f"request rejected: the node is {self.lifecycle_state}, not active",
                       {"request_id": msg.frame_id or "topic"},
                       cv.stamp_to_s(msg.stamp) or None, log_every_s=1.0)
            return
        self.queue.enqueue(msg.frame_id or "topic", cv.stamp_to_s(msg.stamp))

    def _on_service(self, request, response):
        if not self._active:
            response.success = False
            response.message = f"ERROR: the node is {self.lifecycle_state}, not active"
            return response
        target = self.queue.enqueue(f"service-{time.monotonic_ns()}", None)
        # the next solve to start absorbs this request (coalescing); wait for it to finish
        done, (level, reason, stored) = self.queue.wait_done(
            target, self.planner.time_budget_s * 3 + 10)
        response.success = done and stored and level is not Level.ERROR
        response.message = f"{level}: {reason}" if done else "timed out waiting for the solve"
        return response

    # ------------------------------------------------------------------ worker
    def _work(self):
        while True:
            req = self.queue.take()
            if req is None:
                return
            try:
                self._replan_once(req.request_id, req.stamp_s)
            except Exception as exc:  # never let the worker die
                self._finish(req.request_id, None, Level.ERROR, Code.INTERNAL_ERROR,
                             f"internal error: {exc!r}", None)
            finally:
                self.queue.done()

    def _replan_once(self, request_id, request_stamp):
        started = {"solve_start_unix_s": f"{time.time():.6f}"}
        try:
            state = self.queue.state_for(request_stamp)
        except InputRejected as exc:
            self._finish(request_id, None, Level.ERROR, exc.code, f"input rejected: {exc}",
                         request_stamp, started)
            return
        now = request_stamp if request_stamp is not None else (state.stamp_s if state else None)
        mass = None if state is None else self.queue.mass_for(state.stamp_s)
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
        try:
            out = self.planner.replan(pos, vel, mass, stamp, request_id,
                                      now_s=request_stamp)
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

    def _health(self) -> None:
        """The periodic status: lifecycle state, the plan's age and the time to its next stage
        (mission time of the newest estimate), the last solve. Its message never repeats the
        last solve's reason (that is in the values): a periodic message must not read as a
        new event."""
        values = {"lifecycle_state": self.lifecycle_state}
        level, message = Level.OK, self.lifecycle_state
        plan = self.planner.plan if self._configured else None
        newest = self.queue.state_for(None) if self._configured else None
        if plan is not None:
            values.update(plan_epoch_s=f"{plan.epoch_s:.3f}",
                          plan_max_violation=f"{plan.max_violation:.3e}")
            if newest is not None:
                now = newest.stamp_s
                ends = plan.end_times_s
                nxt = ends[ends > now]
                values["plan_age_s"] = f"{now - plan.epoch_s:.3f}"
                values["time_to_next_stage_s"] = f"{nxt[0] - now:.3f}" if nxt.size else "none"
        if self._last_solve:
            lvl, reason, solve_s, wall = self._last_solve
            values.update(last_solve_level=str(lvl), last_solve_reason=reason[:200],
                          last_solve_time_s=f"{solve_s:.4f}" if solve_s is not None else "",
                          last_solve_age_s=f"{time.time() - wall:.1f}")
        values.update(solves=str(self.queue.finished), coalesced=str(self.queue.coalesced))
        if not self._configured:
            level = Level.WARN
        elif self._active and plan is None:
            level, message = Level.WARN, "active: no plan yet"
        elif self._active and self._last_solve and self._last_solve[0] is Level.ERROR:
            level, message = Level.WARN, "active: the last re-plan failed; last valid plan in force"
        elif self._active:
            message = "active: plan in force"
        else:
            message = "inactive: no thrust commands, no re-plans"
        self.pub_diag.publish(cv.diagnostics(level, message, values,
                                             self.get_clock().now().nanoseconds * 1e-9,
                                             self.fqn, kind="health"))

    def _finish(self, request_id, out, level: Level, code: Code, reason: str, stamp,
                extra=None):
        plan = self.planner.plan
        if plan is not None:
            self._publish_plan(plan, stamp if out is not None and out.ok else None)
        values = {"request_id": request_id, "method": self.planner.method,
                  "warm_start": "yes" if out is not None and out.warm_start else "no",
                  **(extra or {})}
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
                values["keep_out_margin_km"] = f"{margin * self.planner.units.lu_km:.3f}"
        self._diag(level, code, reason, values, stamp)
        self._last_solve = (level, reason, out.solve_time_s if out is not None else None,
                            time.time())
        self._release_withheld(plan)
        self.queue.record(level, reason, bool(out is not None and out.ok))

    def _release_withheld(self, plan) -> None:
        """The thrust commands withheld for the estimates that triggered this re-plan (or were
        coalesced into it), from the plan now in force; none while inactive."""
        with self._withheld_lock:
            stamps, self._withheld = self._withheld, []
        if plan is None or not self._active:
            return
        for s in stamps:
            try:
                est = self.queue.state_for(s)   # the estimate of that stamp (RTN plans turn)
            except InputRejected:
                continue
            self.pub_thrust.publish(cv.thrust_command(plan.command_at(s, est.pos_m, est.vel_m_s),
                                                      s, self.frame_id))

    def adopt_plan(self, plan) -> None:
        """Make ``plan`` the current plan and publish it (e.g. a nominal computed elsewhere)."""
        self.planner.set_plan(plan)
        self._publish_plan(plan, plan.epoch_s)
        self._persist()
        self._diag(Level.OK, Code.PLAN_ADOPTED, "adopted a plan",
                   {"request_id": plan.request_id or "adopted"}, plan.epoch_s)

    # ------------------------------------------------------------------ outputs
    def _publish_plan(self, plan, stamp):
        self.pub_schedule.publish(cv.plan_to_joint_trajectory(
            plan, f"{self.frame_id}_rtn" if plan.thrust_rtn else self.frame_id, stamp))
        self.pub_path.publish(cv.plan_to_path(plan, self.frame_id))

    def _diag(self, level: Level, code: Code, message: str, values: dict, stamp,
              log_every_s=None):
        """Publish one DiagnosticStatus with its result ``code`` among its values; non-OK ones
        are also logged (at most once per log_every_s seconds when given, so a flood of bad
        inputs does not flood the log)."""
        if stamp is None:   # no message time to refer to: the node's clock
            stamp = self.get_clock().now().nanoseconds * 1e-9
        self.pub_diag.publish(cv.diagnostics(level, message, {"code": code, **values}, stamp,
                                             self.fqn))
        # rclpy fixes a call site's filters at its first call: one call site per filter
        if level is not Level.OK and log_every_s:
            self.get_logger().warning(f"{level}: {message}", throttle_duration_sec=log_every_s)
        elif level is not Level.OK:
            self.get_logger().warning(f"{level}: {message}")

    @property
    def coalesced(self) -> int:
        """Requests merged into a later solve so far."""
        return self.queue.coalesced

    def stop(self):
        """Stop the solver worker (the solve in progress, if any, finishes first)."""
        self.queue.stop()
        if self._worker is not None:
            self._worker.join(timeout=5.0)
            self._worker = None


def run(node_factory, args=None) -> int:
    """Spin a node with our own SIGINT/SIGTERM handling and a clean shutdown sequence.

    The node's callbacks run on a single-threaded executor (rclpy's multi-threaded executor
    busy-polls, taking CPU the solver worker needs); a blocking service hosted on ``node.service_node`` gets its own executor
    thread so it never stalls the subscriptions.
    """
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    try:
        node = node_factory()
    except DaddyError as exc:   # a bad parameter (unknown scenario, unreadable plan file, ...)
        print(f"guidance_node: {exc}", file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    side = getattr(node, "service_node", None)
    side_executor = None
    if side is not None:
        side_executor = SpinThread(side)
    def report(exc):
        if hasattr(node, "_diag"):
            node._diag(Level.ERROR, Code.INTERNAL_ERROR, f"internal error in a callback: {exc!r}",
                       {}, None)

    try:
        spin_guarded(executor, stop, report)
    finally:
        if hasattr(node, "stop"):
            node.stop()
        for ex in (executor, side_executor):
            if ex is not None:
                ex.shutdown(timeout_sec=2.0)
        node.destroy_node()
        if side is not None:
            side.destroy_node()
        rclpy.try_shutdown()
    return 0


def main(args=None) -> int:
    return run(lambda: GuidanceNode(separate_service_node=True), args)


if __name__ == "__main__":
    raise SystemExit(main())
