"""The node's Replan action over real rclpy / Fast DDS on loopback, driven by a client written
from msg_docs/replan_action.md alone (plain rclpy ActionClient, no daddy_ros client code):
goal, feedback, result, cancel, refusals. The node is spun as ``guidance_node`` spins it: one
single-threaded executor."""
import os
import threading
import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
action = pytest.importorskip("daddy_interfaces.action",
                             reason="daddy_interfaces is not built (make interfaces)")

from builtin_interfaces.msg import Time  # noqa: E402
from rclpy.action import ActionClient  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402

from daddy_ros import conversions as cv  # noqa: E402
from daddy_ros.guidance_node import GuidanceNode  # noqa: E402
from daddy_ros.spin import SpinThread  # noqa: E402
from daddy_sim.sim import TruthSim  # noqa: E402

Replan = action.Replan
assert os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
FRAME = "sun_ecliptic"
T0 = 1000.0
NS = "/act"


class Client:
    """A msg_docs-only client: estimates in, goals out, feedback and results recorded."""

    def __init__(self):
        from geometry_msgs.msg import InertiaStamped
        from nav_msgs.msg import Odometry
        self.node = Node("replan_action_client", namespace=NS)
        self.pub_state = self.node.create_publisher(Odometry, "state_estimate", 10)
        self.pub_mass = self.node.create_publisher(InertiaStamped, "mass_estimate", 10)
        self.action = ActionClient(self.node, Replan, f"{NS}/daddy_guidance/replan_action")
        self.ex = SingleThreadedExecutor()
        self.ex.add_node(self.node)
        self.stop = threading.Event()
        self.th = threading.Thread(target=self._spin, daemon=True)
        self.th.start()

    def _spin(self):
        while not self.stop.is_set() and rclpy.ok():
            self.ex.spin_once(timeout_sec=0.05)

    def estimate(self, pos, vel, mass, t):
        from geometry_msgs.msg import InertiaStamped
        self.pub_state.publish(cv.state_to_odometry(pos, vel, t, FRAME))
        m = InertiaStamped()
        m.header.stamp, m.header.frame_id, m.inertia.m = cv.s_to_stamp(t), FRAME, float(mass)
        self.pub_mass.publish(m)

    def send(self, goal, timeout=30.0):
        """(goal handle, feedback list) once accepted."""
        feedback = []
        fut = self.action.send_goal_async(goal, feedback_callback=lambda m: feedback.append(
            (time.monotonic(), m.feedback)))
        end = time.monotonic() + timeout
        while not fut.done() and time.monotonic() < end:
            time.sleep(0.01)
        assert fut.done() and fut.result().accepted, "goal not accepted"
        return fut.result(), feedback

    @staticmethod
    def result(handle, timeout=120.0):
        fut = handle.get_result_async()
        end = time.monotonic() + timeout
        while not fut.done() and time.monotonic() < end:
            time.sleep(0.01)
        assert fut.done(), "no result"
        return fut.result().status, fut.result().result

    def close(self):
        self.stop.set()
        self.th.join(2.0)
        self.ex.shutdown(timeout_sec=2.0)
        self.action.destroy()
        self.node.destroy_node()


@pytest.fixture(scope="module")
def graph():
    rclpy.init()
    node = GuidanceNode(namespace=NS, scenario="earth_mars", frame_id=FRAME,
                        time_budget_s=60.0, self_replan=False)
    spin = SpinThread(node)
    client = Client()
    assert client.action.wait_for_server(timeout_sec=15), "no action server on loopback"
    pos, vel, mass = TruthSim("earth_mars", t0_s=T0).truth_si()
    end = time.monotonic() + 15
    while node.planner.plan is None and time.monotonic() < end:   # the nominal adopted
        client.estimate(pos, vel, mass, T0)
        time.sleep(0.2)
    assert node.planner.plan is not None
    yield node, client, (pos, vel, mass)
    client.close()
    node.stop()
    spin.shutdown()
    node.destroy_node()
    rclpy.try_shutdown()


def test_a_goal_re_plans_with_feedback_and_returns_the_new_plan(graph):
    from action_msgs.msg import GoalStatus
    node, client, (pos, vel, mass) = graph
    client.estimate(pos + [2e5, 0, 0], vel, mass, T0 + 10.0)   # 200 km off: a real correction
    goal = Replan.Goal(request_id="goal-1", time_budget_s=30.0)
    goal.header.stamp = cv.s_to_stamp(T0 + 10.0)
    handle, feedback = client.send(goal)
    status, r = client.result(handle)
    assert status == GoalStatus.STATUS_SUCCEEDED, (r.code, r.message)
    assert r.request_id == "goal-1" and r.code in ("OK", "NOT_CONVERGED") and r.plan_stored
    assert r.solve_time_s > 0 and r.warm_start
    assert feedback and feedback[0][1].state in ("QUEUED", "SOLVING")
    # the result's plan is the one in force, as the latched schedule gives it
    plan = node.planner.plan
    assert plan.request_id == "goal-1"
    assert r.final_mass_kg == pytest.approx(plan.states_si[-1, 6], abs=1e-9)
    assert r.schedule.header.frame_id == FRAME and r.schedule.joint_names == [
        "thrust_x", "thrust_y", "thrust_z"]
    starts, u = cv.joint_trajectory_to_schedule(r.schedule)
    assert len(u) == len(plan.thrust_n) and np.allclose(u, plan.thrust_n)
    assert np.all(np.linalg.norm(u, axis=1) <= plan.thrust_bound_n * (1 + 1e-6))


def test_a_cancel_stops_the_solve_and_keeps_the_plan_in_force(graph):
    from action_msgs.msg import GoalStatus
    node, client, (pos, vel, mass) = graph
    before = node.planner.plan
    # a cold solve from a state 2,000 km off: seconds of solver iterations to cancel
    client.estimate(pos + [2e6, 0, 0], vel, mass, T0 + 20.0)
    goal = Replan.Goal(request_id="goal-cancel", cold=True, time_budget_s=600.0)
    goal.header.stamp = cv.s_to_stamp(T0 + 20.0)
    handle, feedback = client.send(goal)
    def reported():   # SOLVING feedback with the solver's figures in it
        return [f for _, f in feedback if f.state == "SOLVING" and f.line and f.homotopy_steps]

    end = time.monotonic() + 60
    while not reported() and time.monotonic() < end:
        time.sleep(0.01)
    assert reported(), "no SOLVING feedback with the solver's figures"
    f = reported()[-1]
    assert 1 <= f.homotopy_step <= f.homotopy_steps and f.elapsed_s > 0
    t_cancel = time.monotonic()
    cancel = handle.cancel_goal_async()
    status, r = client.result(handle)
    waited = time.monotonic() - t_cancel
    assert status == GoalStatus.STATUS_CANCELED, (status, r.code, r.message)
    assert r.code == "CANCELLED" and not r.plan_stored and r.level == 1
    assert cancel.done() and cancel.result().return_code == 0   # ERROR_NONE: accepted
    assert node.planner.plan is before                        # the plan in force kept
    starts, u = cv.joint_trajectory_to_schedule(r.schedule)
    assert np.allclose(u, before.thrust_n)
    print(f"cancel answered in {waited:.3f} s (solve stopped after {r.solve_time_s:.3f} s)")


def test_goals_the_node_cannot_serve_are_answered_with_their_code(graph):
    from action_msgs.msg import GoalStatus
    node, client, _ = graph
    bad_frame = Replan.Goal(request_id="goal-frame")
    bad_frame.header.frame_id = "earth_moon_rotating"
    bad_budget = Replan.Goal(request_id="goal-budget", time_budget_s=-1.0)
    for goal, field in ((bad_frame, "goal.header.frame_id"),
                        (bad_budget, "goal.time_budget_s")):
        handle, _ = client.send(goal)
        status, r = client.result(handle, 30.0)
        assert status == GoalStatus.STATUS_ABORTED
        assert r.code == "INPUT_REJECTED" and field in r.message and r.level == 2
        assert r.solve_time_s < 0 and not r.plan_stored
    node.trigger_deactivate()
    try:
        handle, _ = client.send(Replan.Goal(request_id="goal-inactive"))
        status, r = client.result(handle, 30.0)
        assert status == GoalStatus.STATUS_ABORTED and r.code == "NOT_ACTIVE"
    finally:
        node.trigger_activate()
    assert Time(sec=0) == Replan.Goal().header.stamp   # zero stamp: the newest estimate


def test_the_msg_docs_example_runs_against_the_node(graph):
    """msg_docs/replan_action.md's Python block, run as written (the node's namespace added to
    the action's name): its goal is accepted, its feedback lines printed, its result a plan."""
    import re
    from pathlib import Path
    node, client, (pos, vel, mass) = graph
    page = Path(__file__).resolve().parents[1] / "msg_docs" / "replan_action.md"
    block = re.search(r"```python\n(.*?)```", page.read_text(), re.S).group(1)
    client.estimate(pos + [1e5, 0, 0], vel, mass, T0 + 40.0)
    lines = []
    scope = {"node": client.node, "estimate_stamp": cv.s_to_stamp(T0 + 40.0),
             "print": lines.append}
    exec(compile(block.replace('"/daddy_guidance/', f'"{NS}/daddy_guidance/'),
                 str(page), "exec"), scope)
    future, end = scope["future"], time.monotonic() + 30
    while not future.done() and time.monotonic() < end:
        time.sleep(0.01)
    assert future.done() and future.result().accepted
    status, r = client.result(future.result())
    assert r.request_id == "gnc-42" and r.code in ("OK", "NOT_CONVERGED") and r.plan_stored
    assert lines and all(isinstance(line, str) for line in lines)
    scope["client"].destroy()
