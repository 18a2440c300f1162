"""The ``guidance_node`` process as nav2's lifecycle manager sees it, with a stand-in for the
manager written from nav2's and bond_core's behaviour: one node per instance, brought up through
the standard lifecycle services, a bond formed on activation within the manager's
``bond_timeout`` (heartbeats on ``bond``), broken by deactivation, reported when the manager
stops beating, and the process gone after finalized."""
import os
import subprocess
import sys
import time
import uuid

import pytest

rclpy = pytest.importorskip("rclpy")

from lifecycle_msgs.msg import State, Transition  # noqa: E402
from lifecycle_msgs.srv import ChangeState, GetState  # noqa: E402

assert os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
BOND_TIMEOUT_S = 4.0   # nav2 lifecycle_manager's default bond_timeout


class Manager:
    """A lifecycle-manager stand-in for the node ``daddy_guidance`` in namespace ``ns``."""

    def __init__(self, ns):
        self.ns = ns
        self.node = rclpy.create_node("lifecycle_manager_standin", namespace=ns)
        self.change = self.node.create_client(ChangeState, f"{ns}/daddy_guidance/change_state")
        self.get = self.node.create_client(GetState, f"{ns}/daddy_guidance/get_state")
        self.statuses = []   # the node's bond heartbeats: (monotonic s, active)
        self.instance = str(uuid.uuid4())
        self.beating = False
        self.diags = []
        from diagnostic_msgs.msg import DiagnosticArray
        self.node.create_subscription(DiagnosticArray, "/diagnostics",
                                      lambda m: self.diags.extend(m.status), 50)

    def call(self, client, request, timeout=20.0, attempts=1):
        """The service's answer, each attempt waiting ``timeout``. A request sent just as the
        service is discovered can be lost before its reply path is matched (a fresh-clone run
        once waited 20 s for its first get_state): an idempotent query asks again."""
        assert client.wait_for_service(timeout_sec=timeout), client.srv_name
        for _ in range(attempts):
            fut = client.call_async(request)
            rclpy.spin_until_future_complete(self.node, fut, timeout_sec=timeout)
            if fut.done():
                return fut.result()
            client.remove_pending_request(fut)
        raise AssertionError(f"{client.srv_name}: no answer in {attempts} attempts")

    def transition(self, tid) -> bool:
        return self.call(self.change, ChangeState.Request(transition=Transition(id=tid))).success

    def state(self) -> int:
        return self.call(self.get, GetState.Request(), attempts=3).current_state.id

    def start_bond(self):
        from bond.msg import Status
        self.pub = self.node.create_publisher(Status, "bond", 5)
        self.node.create_subscription(Status, "bond", self._status, 100)
        self.beating = True
        self.node.create_timer(0.1, self._beat)

    def _status(self, msg):
        if msg.id == "daddy_guidance" and msg.instance_id != self.instance:
            self.statuses.append((time.monotonic(), msg.active))

    def _beat(self):
        if self.beating:
            from bond.msg import Status
            self.pub.publish(Status(id="daddy_guidance", instance_id=self.instance, active=True,
                                    heartbeat_timeout=BOND_TIMEOUT_S, heartbeat_period=0.1))

    def spin_until(self, cond, timeout):
        end = time.monotonic() + timeout
        while not cond() and time.monotonic() < end:
            rclpy.spin_once(self.node, timeout_sec=0.05)
        return cond()


@pytest.fixture
def process():
    ns = f"/proc_{os.getpid()}_{uuid.uuid4().hex[:6]}"
    proc = subprocess.Popen(
        [sys.executable, "-m", "daddy_ros.guidance_node", "--ros-args", "-p", "autostart:=false",
         "-p", "scenario:=earth_mars", "-p", "frame_id:=sun_ecliptic", "-r", f"__ns:={ns}"],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    rclpy.init()
    yield proc, Manager(ns)
    if proc.poll() is None:
        proc.kill()
        proc.wait()
    rclpy.try_shutdown()


def test_bringup_forms_the_bond_deactivation_breaks_it_and_the_process_exits_after_finalized(
        process):
    pytest.importorskip("bond.msg", reason="no bond message package (make interfaces)")
    proc, m = process
    assert m.state() == State.PRIMARY_STATE_UNCONFIGURED
    assert m.transition(Transition.TRANSITION_CONFIGURE)
    assert m.transition(Transition.TRANSITION_ACTIVATE)
    assert m.state() == State.PRIMARY_STATE_ACTIVE
    m.start_bond()
    t0 = time.monotonic()
    # formed: the node's active heartbeats arrive within the manager's bond_timeout
    assert m.spin_until(lambda: any(a for _, a in m.statuses), BOND_TIMEOUT_S), "no bond"
    assert time.monotonic() - t0 < BOND_TIMEOUT_S
    names = sorted(n for n, space in m.node.get_node_names_and_namespaces() if space == m.ns)
    assert names == ["daddy_guidance", "lifecycle_manager_standin"], names   # no helper node
    assert m.transition(Transition.TRANSITION_DEACTIVATE)
    assert m.spin_until(lambda: m.statuses and not m.statuses[-1][1], 5.0), \
        "deactivation did not break the bond"
    assert m.transition(Transition.TRANSITION_CLEANUP)
    assert m.transition(Transition.TRANSITION_UNCONFIGURED_SHUTDOWN)
    out, _ = proc.communicate(timeout=20)                 # the process exits by itself
    assert proc.returncode == 0, out
    assert "Traceback" not in out


def test_the_managers_silence_is_reported_and_guidance_goes_on(process):
    pytest.importorskip("bond.msg", reason="no bond message package (make interfaces)")
    proc, m = process
    assert m.transition(Transition.TRANSITION_CONFIGURE)
    assert m.transition(Transition.TRANSITION_ACTIVATE)
    m.start_bond()
    assert m.spin_until(lambda: any(a for _, a in m.statuses), BOND_TIMEOUT_S)
    assert m.spin_until(lambda: len(m.statuses) > 5, 5.0)
    m.beating = False                                     # the manager dies
    t_silent = time.monotonic()

    def broken():
        return [d for d in m.diags if any(kv.key == "code" and kv.value == "BOND_BROKEN"
                                          for kv in d.values)]

    assert m.spin_until(broken, BOND_TIMEOUT_S + 5.0), "no BOND_BROKEN diagnostic"
    assert time.monotonic() - t_silent >= BOND_TIMEOUT_S * 0.9
    assert "guidance goes on" in broken()[0].message
    assert m.state() == State.PRIMARY_STATE_ACTIVE        # still guiding
