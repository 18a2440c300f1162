"""A Python client of the guidance node over ROS 2: the other side of its interface
(msg_docs/). Estimates, re-plan requests, Trigger and parameter calls out; schedules, thrust
commands and diagnostics in, each recorded with its arrival time. The closed-loop demo's ROS
link, the ROS tests and the fault-injection campaign all drive the node through it.

Needs an initialised rclpy context; the client spins its own node on its own executor thread.
"""
from __future__ import annotations

import threading
import time

from lifecycle_msgs.srv import ChangeState, GetState
from rcl_interfaces.srv import GetParameters, SetParameters
from rclpy.node import Node
from std_msgs.msg import Header
from std_srvs.srv import Trigger

from . import conversions as cv
from . import interface as io
from .interface import NODE_NAME, RELIABLE
from .spin import SpinThread


def status_of(st) -> tuple[int, str, dict]:
    """(level as an int, message, values) of one DiagnosticStatus (rclpy gives the level as a
    byte)."""
    level = st.level[0] if isinstance(st.level, (bytes, bytearray)) else int(st.level)
    return level, st.message, {kv.key: kv.value for kv in st.values}


class GuidanceClient:
    """Publishers, service clients and recorders for one guidance node (default topic names,
    node ``/daddy_guidance``).

    Attributes:
        schedules, diags, thrust: lists of (arrival unix s, message), in arrival order.
        cond: the condition guarding them (``wait_for`` waits on it).
    """

    def __init__(self, frame_id: str, name: str = "daddy_client", node: str = NODE_NAME,
                 namespace: str = ""):
        """``namespace``: the guidance node's (this client joins it, so the relative topic
        names meet)."""
        self.frame_id = frame_id
        self.node = Node(name, namespace=namespace or None)
        n = self.node
        node = f"{namespace.rstrip('/')}/{node}" if namespace else node
        # (reliable publishers: the node's sensor-data subscriptions accept them)
        self.pub_state, self.pub_mass, self.pub_req = (
            n.create_publisher(t.msg_type, t.default, RELIABLE)
            for t in (io.STATE, io.MASS, io.REQUEST))
        node = node if node.startswith("/") else f"/{node}"
        self.trigger = n.create_client(Trigger, f"{node}/{io.REPLAN_SERVICE.removeprefix('~/')}")
        self.set_params = n.create_client(SetParameters, f"{node}/set_parameters")
        self.get_params = n.create_client(GetParameters, f"{node}/get_parameters")
        self.change_state = n.create_client(ChangeState, f"{node}/change_state")
        self.get_state = n.create_client(GetState, f"{node}/get_state")
        self.cond = threading.Condition()
        self.schedules, self.diags, self.thrust = [], [], []
        self._parsed = (None, None)   # (the newest schedule message, its conversion)
        for topic, bucket in ((io.SCHEDULE, self.schedules), (io.DIAGNOSTICS, self.diags),
                              (io.THRUST, self.thrust)):
            n.create_subscription(topic.msg_type, topic.default,
                                  lambda m, b=bucket: self._add(b, m), topic.qos)
        self.spinner = SpinThread(n)

    def _add(self, bucket: list, msg) -> None:
        with self.cond:
            bucket.append((time.time(), msg))
            self.cond.notify_all()

    def wait_for(self, pred, timeout_s: float):
        """Poll ``pred()`` (called with ``cond`` held) until it is truthy or the time is up;
        returns its last value."""
        end = time.monotonic() + timeout_s
        with self.cond:
            while True:
                r = pred()
                if r or time.monotonic() >= end:
                    return r
                self.cond.wait(0.02)

    def connected(self, timeout_s: float = 20.0) -> bool:
        """The node subscribes to our estimate and request topics (discovery on loopback)."""
        return bool(self.wait_for(lambda: self.pub_state.get_subscription_count() > 0
                                  and self.pub_mass.get_subscription_count() > 0
                                  and self.pub_req.get_subscription_count() > 0, timeout_s))

    # ------------------------------------------------------------------ out
    def send_state(self, pos_m, vel_m_s, stamp_s: float, frame: str | None = None) -> None:
        frame = self.frame_id if frame is None else frame
        self.pub_state.publish(cv.state_to_odometry(pos_m, vel_m_s, stamp_s, frame))

    def send_mass(self, mass_kg: float, stamp_s: float, frame: str | None = None) -> None:
        frame = self.frame_id if frame is None else frame
        self.pub_mass.publish(cv.mass_estimate(mass_kg, stamp_s, frame))

    def publish_estimate(self, pos_m, vel_m_s, mass_kg: float, stamp_s: float,
                         frame: str | None = None) -> None:
        """Mass, then state of one epoch (the node serves a request from the newest state and
        the mass of its time)."""
        self.send_mass(mass_kg, stamp_s, frame)
        self.send_state(pos_m, vel_m_s, stamp_s, frame)

    def send_estimate(self, pos_m, vel_m_s, mass_kg: float, stamp_s: float,
                      timeout_s: float = 5.0) -> bool:
        """``publish_estimate``, then wait until the node has acted on the state (its thrust
        command for that stamp arrives). True if it did within timeout_s."""
        self.publish_estimate(pos_m, vel_m_s, mass_kg, stamp_s)
        return bool(self.wait_for(lambda: any(cv.stamp_to_s(m.header.stamp) >= stamp_s - 1e-3
                                              for _, m in self.thrust), timeout_s))

    def request(self, request_id: str, stamp_s: float) -> None:
        self.pub_req.publish(Header(stamp=cv.s_to_stamp(stamp_s), frame_id=request_id))

    def call(self, client, request, timeout_s: float):
        """(response or None, latency s) of a service call (e.g. ``self.trigger``)."""
        t0 = time.monotonic()
        if not client.wait_for_service(timeout_sec=timeout_s):
            return None, time.monotonic() - t0
        fut = client.call_async(request)
        end = t0 + timeout_s
        while not fut.done() and time.monotonic() < end:
            time.sleep(0.005)
        return (fut.result() if fut.done() else None), time.monotonic() - t0

    # ------------------------------------------------------------------ in
    def status_for(self, request_id: str, after: int = 0):
        """The first DiagnosticStatus naming ``request_id`` among the diagnostics received from
        index ``after`` on, or None."""
        with self.cond:
            for _, m in self.diags[after:]:
                for st in m.status:
                    if any(kv.key == "request_id" and kv.value == request_id for kv in st.values):
                        return st
        return None

    def diag_for(self, request_id: str, after: int = 0):
        """(level, message, values) of ``status_for(request_id, after)``, or None."""
        st = self.status_for(request_id, after)
        return None if st is None else status_of(st)

    def latest_schedule(self):
        """(stamp s, stage starts (K,) s relative to it, thrust (K, 3) N) of the newest schedule
        received, or None."""
        with self.cond:
            if not self.schedules:
                return None
            msg = self.schedules[-1][1]
            if self._parsed[0] is not msg:   # converted once per message, not per call
                starts, u = cv.joint_trajectory_to_schedule(msg)
                self._parsed = (msg, (cv.stamp_to_s(msg.header.stamp), starts, u))
            return self._parsed[1]

    def close(self) -> None:
        self.spinner.shutdown(timeout_sec=2.0)
        self.node.destroy_node()
