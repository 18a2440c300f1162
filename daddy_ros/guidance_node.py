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
from collections import deque
from pathlib import Path

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import InertiaStamped, Vector3Stamped
from nav_msgs.msg import Odometry
from nav_msgs.msg import Path as PathMsg
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy,
                       qos_profile_sensor_data)
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import Header
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory

from daddy_core.catalogue import list_cases, load_case
from daddy_core.errors import DaddyError

from . import conversions as cv
from .checks import FUTURE_TOLERANCE_S, InputRejected
from .config import NodeConfig, PlannerConfig, bundled_plan, parameters
from .plan import TIME_TOLERANCE_S
from .planner import GuidancePlanner
from .spin import SpinThread, spin_guarded

NODE_NAME = "daddy_guidance"
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL, history=HistoryPolicy.KEEP_LAST)
RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                      history=HistoryPolicy.KEEP_LAST)

NAMES = {p.name for p in parameters()}
RUNTIME = {p.name for p in parameters() if p.runtime}   # time_budget_s, staleness_s
STATE_HISTORY = 64   # accepted estimates kept to serve requests stamped in their past
# a request stamped after the newest estimate waits this long for the estimate of its time
# (topics are not ordered with each other: a request can overtake the estimate sent before it)
ESTIMATE_WAIT_S = 0.5


class GuidanceNode(Node):
    def __init__(self, service_node: Node | None = None, **overrides):
        """``service_node``: a helper node to host the blocking Trigger service on its own
        executor (``run`` does this); None hosts it here in a reentrant callback group, which
        needs a multi-threaded executor."""
        super().__init__(NODE_NAME)
        for p in parameters():
            self.declare_parameter(p.name, overrides.get(p.name, p.default),
                                   ParameterDescriptor(description=p.description))
        self.add_on_set_parameters_callback(self._on_set_parameters)
        g = lambda n: self.get_parameter(n).value  # noqa: E731
        self.planner = GuidancePlanner(config=PlannerConfig(
            **{f: g(f) for f in PlannerConfig.__dataclass_fields__ if self.has_parameter(f)}))
        cfg = NodeConfig(**{f: g(f) for f in NodeConfig.__dataclass_fields__})
        self.frame_id = cfg.frame_id
        self.plan_file = cfg.plan_file or self._bundled_plan()
        self._lock = threading.Lock()
        self._wake = threading.Condition(self._lock)
        self._states = deque(maxlen=STATE_HISTORY)   # accepted (pos, vel, stamp), arrival order
        self._masses = deque(maxlen=STATE_HISTORY)   # accepted (stamp, mass kg), arrival order
        self._pending = None        # (request_id, request_stamp, monotonic arrival) to solve
        self._busy = False
        self._n_started = 0         # solves started / finished (sequential, one worker)
        self._n_finished = 0
        self._last = ("ERROR", "no solve yet", False)   # (level, reason, new plan stored)
        self._stop = False
        self.replans = 0
        self.coalesced = 0
        self.persist_file = cfg.persist_file
        self._replan_on_first_estimate = False

        sub_group = MutuallyExclusiveCallbackGroup()
        self.create_subscription(Odometry, cfg.state_topic, self._on_state,
                                 qos_profile_sensor_data, callback_group=sub_group)
        self.create_subscription(InertiaStamped, cfg.mass_topic, self._on_mass,
                                 qos_profile_sensor_data, callback_group=sub_group)
        # requests in their own group: a request flood must not delay the estimates
        self.create_subscription(Header, cfg.request_topic, self._on_request, RELIABLE,
                                 callback_group=MutuallyExclusiveCallbackGroup())
        self.service_node = service_node
        (service_node or self).create_service(Trigger, self.resolve_service_name("~/replan"),
                                              self._on_service,
                                              callback_group=ReentrantCallbackGroup())
        self.pub_schedule = self.create_publisher(JointTrajectory, cfg.schedule_topic, LATCHED)
        self.pub_path = self.create_publisher(PathMsg, cfg.path_topic, LATCHED)
        self.pub_thrust = self.create_publisher(Vector3Stamped, cfg.thrust_topic, RELIABLE)
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", RELIABLE)
        self._worker = threading.Thread(target=self._work, name="daddy_replan", daemon=True)
        self._worker.start()
        if self.persist_file and Path(self.persist_file).exists():
            self._restore()
        self.get_logger().info(f"daddy_guidance ready: scenario {self.planner.case.name}, "
                               f"method {self.planner.method}, frame {self.frame_id}")

    # ------------------------------------------------------------------ parameters
    def _bundled_plan(self) -> str:
        p = bundled_plan(self.planner.case.name, self.planner.config.fuel_optimal)
        return str(p) if p is not None and not self.planner.config.stages else ""

    def _on_set_parameters(self, params):
        """Runtime updates: the ``runtime`` parameters of ``config`` (time_budget_s and
        staleness_s, positive finite floats); every other declared parameter is read-only after
        start-up. A rejected update changes nothing."""
        why = next((r for r in map(self._parameter_problem, params) if r), None)
        if why:
            self._diag("WARN", f"parameter update rejected: {why}", {"field": "parameters"}, None)
            return SetParametersResult(successful=False, reason=why)
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
                        "scenario is also read-only after start-up")
        if p.name in NAMES and self.has_parameter(p.name):
            return f"{p.name} is read-only after start-up"
        return ""

    # ------------------------------------------------------------------ inputs
    def _reject(self, topic: str, reason: str, stamp: float) -> None:
        """An input that is not used: ERROR diagnostic naming the field; nothing else changes."""
        self._diag("ERROR", f"input rejected: {reason}", {"topic": topic, "stamp_s": f"{stamp:.9f}"},
                   stamp if math.isfinite(stamp) and stamp > 0 else None, log_every_s=1.0)

    def _on_state(self, msg: Odometry):
        pos, vel, stamp, frame = cv.odometry_to_state(msg)
        if frame != self.frame_id:
            self._reject("state_estimate", f"state_estimate.header.frame_id {frame!r} is not "
                         f"{self.frame_id!r}", stamp)
            return
        try:
            self.planner.checks.check_estimate(pos, vel, stamp)
        except InputRejected as exc:
            self._reject("state_estimate", str(exc), stamp)
            return
        with self._lock:
            self._states.append((pos, vel, stamp))
            self._wake.notify_all()
        plan = self.planner.plan or self._adopt_nominal()
        if plan is not None:
            self.pub_thrust.publish(cv.thrust_command(plan.thrust_at(stamp), stamp, self.frame_id))
        self._maybe_replan_after_restart()

    def _on_mass(self, msg: InertiaStamped):
        mass, stamp = float(msg.inertia.m), cv.stamp_to_s(msg.header.stamp)
        try:
            self.planner.checks.check_mass(mass, stamp)
        except InputRejected as exc:
            self._reject("mass_estimate", str(exc), stamp)
            return
        with self._lock:
            self._masses.append((stamp, mass))
            self._wake.notify_all()
        if self.planner.plan is None:
            self._adopt_nominal()
        self._maybe_replan_after_restart()

    def _maybe_replan_after_restart(self):
        with self._lock:
            go = self._replan_on_first_estimate and self._states and self._masses
            if go:
                self._replan_on_first_estimate = False
        if go:
            self._enqueue("restart", None)

    def _restore(self):
        """Start-up after a crash: adopt the persisted plan and re-plan at the first estimate."""
        try:
            plan = self.planner.restore_plan(self.persist_file)
        except DaddyError as exc:
            self._diag("ERROR", f"persist_file not restored: {exc}", {"field": "persist_file"}, None)
            return
        self._publish_plan(plan, None)
        self._replan_on_first_estimate = True
        self._diag("WARN", f"restored the persisted plan (epoch {plan.epoch_s:.3f} s); re-planning "
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

    def _state_for(self, request_stamp: float | None):
        """The estimate a request is served from: the newest received (service requests), or the
        newest stamped at most FUTURE_TOLERANCE_S after the request's mission time (its stamp
        plus its wait in the queue; topic requests). Raises InputRejected when every stored
        estimate is in the future of that time."""
        with self._lock:
            states = list(self._states)
        if not states or request_stamp is None:
            return states[-1] if states else None
        usable = [s for s in states if s[2] <= request_stamp + FUTURE_TOLERANCE_S]
        if not usable:
            ahead = min(s[2] for s in states) - request_stamp
            raise InputRejected(f"every state_estimate is in the future of the request stamp "
                                f"(the oldest by {ahead:.3g} s)")
        return max(usable, key=lambda s: s[2])

    def _adopt_nominal(self):
        """Adopt the nominal plan at the first estimate (state and mass both received)."""
        state = self._state_for(None)
        with self._lock:
            mass, plan_file = bool(self._masses), self.plan_file
        if not plan_file or state is None or not mass:
            return None
        stamp = state[2]
        try:
            plan = self.planner.load_plan(plan_file, stamp)
        except Exception as exc:
            self._diag("ERROR", f"cannot load plan_file: {exc}", {}, stamp)
            self.plan_file = ""
            return None
        self._publish_plan(plan, stamp)
        self._persist()
        self._diag("OK", f"adopted nominal plan {Path(plan_file).name}", {"request_id": "nominal"},
                   stamp)
        return plan

    def _on_request(self, msg: Header):
        self._enqueue(msg.frame_id or "topic", cv.stamp_to_s(msg.stamp))

    def _enqueue(self, request_id: str, stamp_s: float | None) -> int:
        """Queue a re-optimisation; returns the number of the solve that will serve it."""
        with self._lock:
            if self._pending is not None or self._busy:
                self.coalesced += 1
            self._pending = (request_id, stamp_s, time.monotonic())
            self._wake.notify()
            return self._n_started + 1

    def _on_service(self, request, response):
        target = self._enqueue(f"service-{time.monotonic_ns()}", None)
        deadline = time.monotonic() + self.planner.time_budget_s * 3 + 10
        with self._lock:
            # the next solve to start absorbs this request (coalescing); wait for it to finish
            while self._n_finished < target and time.monotonic() < deadline and not self._stop:
                self._wake.wait(0.1)
            done = self._n_finished >= target
            level, reason, stored = self._last
        response.success = done and stored and level != "ERROR"
        response.message = f"{level}: {reason}" if done else "timed out waiting for the solve"
        return response

    # ------------------------------------------------------------------ worker
    def _work(self):
        while True:
            with self._lock:
                while self._pending is None and not self._stop:
                    self._wake.wait(0.2)
                if self._stop:
                    return
                request_id, request_stamp, arrived = self._pending
                self._pending = None
                self._wait_for_estimate(request_stamp)
                if request_stamp is not None:
                    # mission time now: the request stamp plus the time it waited in the queue
                    request_stamp += time.monotonic() - arrived
                self._busy = True
                self._n_started += 1
            try:
                self._replan_once(request_id, request_stamp)
            except Exception as exc:  # never let the worker die
                self._finish(request_id, None, "ERROR", f"internal error: {exc!r}", None)
            finally:
                with self._lock:
                    self._busy = False
                    self._n_finished += 1
                    self._wake.notify_all()

    def _wait_for_estimate(self, request_stamp: float | None) -> None:
        """(lock held) Wait up to ESTIMATE_WAIT_S for an estimate stamped near the request and
        for the mass estimate of the newest state's time (topics arrive in any order)."""
        end = time.monotonic() + ESTIMATE_WAIT_S

        def ready():
            if not self._states:
                return False
            newest = max(s[2] for s in self._states)
            if request_stamp is not None and newest < request_stamp - FUTURE_TOLERANCE_S:
                return False
            return any(m[0] >= newest - TIME_TOLERANCE_S for m in self._masses)

        while not self._stop and time.monotonic() < end and not ready():
            self._wake.wait(0.02)

    def _mass_for(self, stamp: float) -> float | None:
        """The mass estimate of the state's time: same stamp, else the newest before it, else
        the newest received (mass changes slowly; its own checks already passed)."""
        with self._lock:
            masses = list(self._masses)
        if not masses:
            return None
        before = [m for m in masses if m[0] <= stamp + TIME_TOLERANCE_S]
        return max(before)[1] if before else masses[-1][1]

    def _replan_once(self, request_id, request_stamp):
        started = {"solve_start_unix_s": f"{time.time():.6f}"}
        try:
            state = self._state_for(request_stamp)
        except InputRejected as exc:
            self._finish(request_id, None, "ERROR", f"input rejected: {exc}", request_stamp, started)
            return
        now = request_stamp if request_stamp is not None else (state[2] if state else None)
        mass = None if state is None else self._mass_for(state[2])
        if state is None or mass is None:
            self._finish(request_id, None, "ERROR", "no valid state_estimate and mass_estimate yet",
                         now, started)
            return
        pos, vel, stamp = state
        started["state_stamp_s"] = f"{stamp:.9f}"
        try:
            out = self.planner.replan(pos, vel, mass, stamp, request_id,
                                      now_s=request_stamp)
        except InputRejected as exc:
            self._finish(request_id, None, "ERROR", f"input rejected: {exc}", now, started)
            return
        self.replans += 1
        if out.ok:
            why = self._persist()
            if why:
                out.level, out.reason = "WARN", f"{out.reason}; {why}"
        self._finish(request_id, out, out.level, out.reason, stamp, started)

    def _finish(self, request_id, out, level, reason, stamp, extra=None):
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
        self._diag(level, reason, values, stamp)
        with self._lock:
            self._last = (level, reason, bool(out is not None and out.ok))

    def adopt_plan(self, plan) -> None:
        """Make ``plan`` the current plan and publish it (e.g. a nominal computed elsewhere)."""
        self.planner.set_plan(plan)
        self._publish_plan(plan, plan.epoch_s)
        self._persist()
        self._diag("OK", "adopted a plan", {"request_id": plan.request_id or "adopted"},
                   plan.epoch_s)

    # ------------------------------------------------------------------ outputs
    def _publish_plan(self, plan, stamp):
        self.pub_schedule.publish(cv.plan_to_joint_trajectory(plan, self.frame_id, stamp))
        self.pub_path.publish(cv.plan_to_path(plan, self.frame_id))

    def _diag(self, level, message, values, stamp, log_every_s=None):
        """Publish one DiagnosticStatus; non-OK ones are also logged (at most once per
        log_every_s seconds when given, so a flood of bad inputs does not flood the log)."""
        if stamp is None:   # no message time to refer to: the node's clock
            stamp = self.get_clock().now().nanoseconds * 1e-9
        self.pub_diag.publish(cv.diagnostics(level, message, values, stamp))
        # rclpy fixes a call site's filters at its first call: one call site per filter
        if level != "OK" and log_every_s:
            self.get_logger().warning(f"{level}: {message}", throttle_duration_sec=log_every_s)
        elif level != "OK":
            self.get_logger().warning(f"{level}: {message}")

    def stop(self):
        with self._lock:
            self._stop = True
            self._wake.notify_all()
        self._worker.join(timeout=5.0)


def run(node_factory, args=None) -> int:
    """Spin a node with our own SIGINT/SIGTERM handling and a clean shutdown sequence.

    The node's callbacks run on a single-threaded executor (rclpy's multi-threaded executor
    busy-polls: measured ~95 % of a core at 50 Hz estimates vs ~13 % here, CPU the solver
    worker needs); a blocking service hosted on ``node.service_node`` gets its own executor
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
            node._diag("ERROR", f"internal error in a callback: {exc!r}", {}, None)

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


def _guidance_with_service_node() -> GuidanceNode:
    helper = Node("daddy_guidance_service", use_global_arguments=False,
                  start_parameter_services=False, enable_rosout=False)
    try:
        return GuidanceNode(service_node=helper)
    except Exception:
        helper.destroy_node()
        raise


def main(args=None) -> int:
    return run(_guidance_with_service_node, args)


if __name__ == "__main__":
    raise SystemExit(main())
