"""The guidance node over real rclpy / Fast DDS on loopback: requests, schedules, diagnostics,
malformed inputs, the Trigger service."""
import math
import os
import threading
import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")

from diagnostic_msgs.msg import DiagnosticStatus  # noqa: E402
from rclpy.executors import MultiThreadedExecutor  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from daddy_ros import conversions as cv  # noqa: E402
from daddy_ros.client import GuidanceClient  # noqa: E402
from daddy_ros.guidance_node import GuidanceNode  # noqa: E402
from daddy_sim.sim import TruthSim  # noqa: E402

assert os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
FRAME = "sun_ecliptic"
T0 = 1000.0


@pytest.fixture(scope="module")
def graph():
    rclpy.init()
    # request-driven: the tests below send perturbed estimates and expect the plan to change
    # only on their requests (the node's own policy has its test)
    node = GuidanceNode(scenario="earth_mars", frame_id=FRAME, time_budget_s=60.0,
                        self_replan=False)
    client = GuidanceClient(FRAME, name="daddy_test_client")
    ex = MultiThreadedExecutor(num_threads=4)   # the node hosts its Trigger service itself
    ex.add_node(node)
    th = threading.Thread(target=ex.spin, daemon=True)
    th.start()
    # discovery of a late joiner can take a while: poll, never sleep a fixed time
    end = time.monotonic() + 15
    while time.monotonic() < end and not (client.pub_state.get_subscription_count()
                                          and client.pub_req.get_subscription_count()):
        time.sleep(0.05)
    assert client.pub_state.get_subscription_count(), "no discovery on loopback"
    yield node, client
    node.stop()
    ex.shutdown(timeout_sec=2.0)
    node.destroy_node()
    client.close()
    rclpy.try_shutdown()


def truth_at_start():
    sim = TruthSim("earth_mars", t0_s=T0)
    return sim.truth_si()


def test_nominal_then_replan_publishes_valid_schedule(graph):
    node, c = graph
    pos, vel, mass = truth_at_start()
    c.publish_estimate(pos, vel, mass, T0)
    assert c.wait_for(lambda: c.schedules, 15), "no schedule after the first estimate"
    # a perturbed state 5 % into the flight (1000 km, 1 m/s), a warm-started re-optimisation
    sim = TruthSim("earth_mars", t0_s=T0)
    plan = node.planner.plan
    k = 2
    for j in range(k):
        sim.apply(plan.thrust_n[j], plan.stage_dt_s[j])
    p, v, m = sim.truth_si()
    t = sim.t_s
    c.publish_estimate(p + [1e6, 0, 0], v + [1.0, 0, 0], m, t)
    c.wait_for(lambda: c.thrust, 10)
    c.request("req-1", t)
    st = c.wait_for(lambda: c.status_for("req-1"), 120)
    assert st, "no diagnostics for req-1"
    vals = {kv.key: kv.value for kv in st.values}
    assert st.level == DiagnosticStatus.OK, st.message
    assert st.name == "/daddy_guidance: replan" and st.hardware_id == "/daddy_guidance"
    for key in ("request_id", "solve_time_s", "max_violation", "final_mass_kg", "method",
                "warm_start", "thrust_bound_n"):
        assert key in vals
    assert vals["warm_start"] == "yes" and vals["code"] == "OK"
    bound = float(vals["thrust_bound_n"])          # a rung of the margin ladder: 95-100 % of 0.5 N
    assert 0.95 * 0.5 * (1 - 1e-9) <= bound <= 0.5 * (1 + 1e-9)
    sched = c.wait_for(lambda: [s for _, s in c.schedules
                                if cv.stamp_to_s(s.header.stamp) >= t - 1e-3], 10)
    assert sched
    starts, u = cv.joint_trajectory_to_schedule(sched[-1])
    assert sched[-1].joint_names == ["thrust_x", "thrust_y", "thrust_z"]
    assert sched[-1].header.frame_id == FRAME
    assert len(u) == 40 - k and np.all(np.isfinite(u))
    assert np.all(np.linalg.norm(u, axis=1) <= bound * (1 + 1e-6))
    assert np.all(np.diff(starts) > 0) and starts[0] == pytest.approx(0.0)


def _body_frame_odometry(pos, vel_inertial, stamp, yaw):
    """An Odometry as a standard estimator sends it: the twist in the body frame (child
    'spacecraft'), rotated by ``yaw`` about z from the header frame, with that orientation."""
    c, s = math.cos(yaw), math.sin(yaw)
    v_body = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]]) @ vel_inertial
    msg = cv.state_to_odometry(pos, v_body, stamp, FRAME)
    msg.pose.pose.orientation.w, msg.pose.pose.orientation.z = math.cos(yaw / 2), math.sin(yaw / 2)
    return msg


def test_body_frame_twist_is_rotated_into_the_header_frame(graph):
    node, c = graph
    t = node.planner.plan.epoch_s + 5.0
    x = node.session.fit.predicted(node.planner.plan, t)   # on the plan (no re-plan follows)
    pos, vel = x[:3], x[3:6]
    msg = _body_frame_odometry(pos, vel, t, yaw=2.1)
    msg.pose.covariance = np.diag([1e6, 1e6, 1e6, 0, 0, 0]).ravel().tolist()   # sigma 1 km
    c.pub_state.publish(msg)
    got = c.wait_for(lambda: (s := node.queue.state_for(None)) is not None
                     and abs(s.stamp_s - t) < 1e-6 and s, 10)
    assert got, "the body-frame estimate was not accepted"
    np.testing.assert_allclose(got.vel_m_s, vel, rtol=1e-12)
    assert got.pos_sigma_m == pytest.approx(1000.0) and got.vel_sigma_m_s is None


@pytest.mark.parametrize("case", ["nan", "frame", "negative_mass", "inside_sun", "unset_stamp",
                                  "orientation", "covariance"])
def test_malformed_estimates_rejected_at_arrival_and_plan_kept(graph, case):
    node, c = graph
    plan_before = node.planner.plan
    assert plan_before is not None
    t = plan_before.epoch_s + 10.0
    x = node.session.fit.predicted(plan_before, t)   # on the plan: only the fault is wrong
    pos, vel, mass = x[:3], x[3:6], x[6]
    n0 = len(c.diags)
    expect = {"nan": "position", "frame": "frame_id", "negative_mass": "inertia.m",
              "inside_sun": "heliocentric", "unset_stamp": "header.stamp",
              "orientation": "pose.pose.orientation", "covariance": "twist.covariance"}[case]
    if case == "nan":
        c.publish_estimate(pos * math.nan, vel, mass, t)
    elif case == "frame":
        c.publish_estimate(pos, vel, mass, t, frame="map")
    elif case == "negative_mass":
        c.publish_estimate(pos, vel, -5.0, t)
    elif case == "inside_sun":
        c.publish_estimate(pos * 1e-3, vel, mass, t)
    elif case == "unset_stamp":
        c.publish_estimate(pos, vel, mass, 0.0)
    elif case in ("orientation", "covariance"):
        msg = _body_frame_odometry(pos, vel, t, yaw=0.4)
        if case == "orientation":   # a body-frame twist without a usable orientation
            msg.pose.pose.orientation.w = msg.pose.pose.orientation.z = 0.0
        else:
            msg.twist.covariance = np.diag([1.0, math.inf, 1.0, 0, 0, 0]).ravel().tolist()
        c.send_mass(mass, t)
        c.pub_state.publish(msg)
    got = c.wait_for(lambda: [d.status[0] for _, d in c.diags[n0:]
                              if expect in d.status[0].message], 10)
    assert got, f"no diagnostic naming {expect!r}"
    assert got[0].level == DiagnosticStatus.ERROR and "rejected" in got[0].message
    assert {kv.key: kv.value for kv in got[0].values}["code"] == "INPUT_REJECTED"
    assert node.planner.plan is plan_before  # the last valid plan is kept
    _, u = cv.joint_trajectory_to_schedule(c.schedules[-1][1])
    assert np.all(np.isfinite(u))


@pytest.mark.parametrize("case", ["future", "stale"])
def test_requests_without_a_usable_estimate_are_rejected(graph, case):
    node, c = graph
    plan_before = node.planner.plan
    t = plan_before.epoch_s + 10.0
    x = node.session.fit.predicted(plan_before, t)     # an estimate on the plan
    pos, vel, mass = x[:3], x[3:6], x[6]
    c.publish_estimate(pos, vel, mass, t)
    assert c.wait_for(lambda: [m for _, m in c.thrust
                               if cv.stamp_to_s(m.header.stamp) >= t - 1e-3], 10)
    rid = f"bad-{case}"
    # future: the request predates every stored estimate; stale: it is far after the newest
    c.request(rid, 1.0 if case == "future" else t + 10 * node.planner.config.staleness_s)
    st = c.wait_for(lambda: c.status_for(rid), 30)
    assert st, f"no diagnostics for {rid}"
    assert st.level == DiagnosticStatus.ERROR and case in st.message, st.message
    assert {kv.key: kv.value for kv in st.values}["code"] == case.upper()   # FUTURE / STALE
    assert node.planner.plan is plan_before


def test_trigger_service_answers(graph):
    node, c = graph
    plan = node.planner.plan
    sim = TruthSim("earth_mars", t0_s=T0)
    p, v, m = sim.truth_si()
    # a valid estimate on the current plan's epoch
    c.publish_estimate(plan.states_si[0, :3], plan.states_si[0, 3:6], plan.states_si[0, 6], plan.epoch_s)
    time.sleep(0.1)
    assert c.trigger.wait_for_service(timeout_sec=10)
    fut = c.trigger.call_async(Trigger.Request())
    end = time.monotonic() + 120
    while not fut.done() and time.monotonic() < end:
        time.sleep(0.05)
    assert fut.done()
    assert fut.result().success, fut.result().message


def test_triggers_during_a_solve_are_coalesced(graph):
    node, c = graph
    plan = node.planner.plan
    c.publish_estimate(plan.states_si[0, :3], plan.states_si[0, 3:6], plan.states_si[0, 6], plan.epoch_s)
    time.sleep(0.1)
    before_replans, before_coalesced = node.replans, node.coalesced
    for i in range(20):
        c.request(f"burst-{i}", plan.epoch_s)
    last = c.wait_for(lambda: c.diag_for("burst-19"), 180)
    assert last, "the newest request was not answered"
    solved = node.replans - before_replans
    merged = node.coalesced - before_coalesced
    # every request that reached the node was solved or merged into a solve (a reliable
    # depth-10 history may also drop the oldest of a fast burst, which is coalescing too)
    assert solved + merged <= 20
    assert merged >= 1 and 1 <= solved < 20


def test_lifecycle_transitions_gate_thrust_and_requests(graph):
    """A managed node (autostart false) driven through the standard lifecycle services by a
    client: no thrust command while unconfigured or inactive, a request while inactive is
    refused with an ERROR naming the state, a bad parameter fails configure (the node stays
    unconfigured, the parameter can then be fixed), and deactivate / activate stops and resumes
    thrust with the plan still latched."""
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState, GetState
    from rcl_interfaces.srv import SetParameters
    from rclpy.parameter import Parameter

    from daddy_ros.spin import SpinThread
    ns = "/lc"
    node = GuidanceNode(namespace=ns, scenario="no_such_case", frame_id=FRAME,
                        time_budget_s=60.0, autostart=False)
    spin = SpinThread(node)
    c = GuidanceClient(FRAME, name="daddy_lifecycle_client", namespace=ns)
    pos, vel, mass = truth_at_start()

    def state():
        resp, _ = c.call(c.get_state, GetState.Request(), 15.0)
        return resp.current_state.label if resp else "no answer"

    def change(tid):
        resp, _ = c.call(c.change_state, ChangeState.Request(transition=Transition(id=tid)), 30)
        return resp is not None and resp.success

    def thrust_after(t):
        return [m for _, m in c.thrust if cv.stamp_to_s(m.header.stamp) >= t - 1e-6]

    def fly_until_thrust(t):
        """Estimates every 0.2 s from stamp t on (best-effort topic, late discovery) until a
        thrust command answers one; the last stamp sent."""
        end = time.monotonic() + 15
        while time.monotonic() < end and not thrust_after(t):
            c.publish_estimate(pos, vel, mass, t)
            c.wait_for(lambda: thrust_after(t), 0.2)
        return bool(thrust_after(t))

    try:
        assert state() == "unconfigured"
        assert not change(Transition.TRANSITION_CONFIGURE), "an unknown scenario must fail"
        assert state() == "unconfigured"
        assert c.wait_for(lambda: [d for _, d in c.diags
                                   if "configure failed" in d.status[0].message
                                   and "no_such_case" in d.status[0].message
                                   and "CONFIGURE_FAILED" in str(d.status[0].values)], 10)
        resp, _ = c.call(c.set_params, SetParameters.Request(parameters=[
            Parameter("scenario", value="earth_mars").to_parameter_msg()]), 10.0)
        assert resp.results[0].successful, "parameters are editable while unconfigured"
        assert change(Transition.TRANSITION_CONFIGURE) and state() == "inactive"
        end = time.monotonic() + 15
        while time.monotonic() < end and not c.pub_state.get_subscription_count():
            time.sleep(0.05)
        for k in range(5):   # inactive: estimates dropped, no thrust
            c.publish_estimate(pos, vel, mass, T0 + 0.1 * k)
            time.sleep(0.05)
        c.request("while-inactive", T0)
        assert c.wait_for(lambda: [d for _, d in c.diags if "while-inactive" in str(
            d.status[0].values) and "not active" in d.status[0].message
            and "NOT_ACTIVE" in str(d.status[0].values)], 10)
        assert change(Transition.TRANSITION_ACTIVATE) and state() == "active"
        assert fly_until_thrust(T0 + 1.0), "no thrust command while active"
        assert c.wait_for(lambda: c.schedules, 15)
        assert change(Transition.TRANSITION_DEACTIVATE) and state() == "inactive"
        for k in range(5):
            c.publish_estimate(pos, vel, mass, T0 + 2.0 + k)
            time.sleep(0.05)
        late = GuidanceClient(FRAME, name="daddy_lifecycle_late", namespace=ns)
        try:   # the plan stays latched for a subscriber joining while inactive
            assert late.wait_for(lambda: late.schedules, 15)
        finally:
            late.close()
        assert change(Transition.TRANSITION_ACTIVATE)
        assert fly_until_thrust(T0 + 10.0)
        stamps = [cv.stamp_to_s(m.header.stamp) for _, m in c.thrust]
        assert not [s for s in stamps if s < T0 + 1.0 - 1e-6 or T0 + 2.0 - 1e-6 <= s
                    <= T0 + 6.0 + 1e-6], "thrust published while unconfigured or inactive"
    finally:
        c.close()
        spin.shutdown()
        if node.lifecycle_state != "finalized":
            node.trigger_shutdown()
        node.destroy_node()


def test_two_namespaced_instances_publish_distinct_live_health(graph):
    """Two instances side by side (/sc1 active, /sc2 left unconfigured): each publishes its
    periodic health under its own fully qualified name and hardware_id, with its lifecycle
    state, and /sc1's turns OK with the plan's age and time to the next stage once it has a
    plan. (Period 0.25 s; at least 4 statuses each within 5 s: a 3x margin on a loaded
    machine.)"""
    from daddy_ros.spin import SpinThread
    nodes = [GuidanceNode(namespace="/sc1", scenario="earth_mars", frame_id=FRAME,
                          diagnostics_period_s=0.25),
             GuidanceNode(namespace="/sc2", scenario="earth_mars", frame_id=FRAME,
                          diagnostics_period_s=0.25, autostart=False)]
    spins = [SpinThread(n) for n in nodes]
    c = GuidanceClient(FRAME, name="daddy_health_client", namespace="/sc1")
    try:
        def health(fqn):
            out = []
            for _, m in c.diags:
                for st in m.status:
                    if st.name == f"{fqn}: health":
                        out.append(st)
            return out

        assert c.wait_for(lambda: len(health("/sc1/daddy_guidance")) >= 4
                          and len(health("/sc2/daddy_guidance")) >= 4, 5.0)
        h1, h2 = health("/sc1/daddy_guidance")[-1], health("/sc2/daddy_guidance")[-1]
        assert h1.hardware_id == "/sc1/daddy_guidance" and h2.hardware_id == "/sc2/daddy_guidance"
        v1 = {kv.key: kv.value for kv in h1.values}
        v2 = {kv.key: kv.value for kv in h2.values}
        assert v1["lifecycle_state"] == "active" and v2["lifecycle_state"] == "unconfigured"
        assert h2.level == DiagnosticStatus.WARN
        pos, vel, mass = truth_at_start()
        end = time.monotonic() + 15
        while time.monotonic() < end and not c.schedules:
            c.publish_estimate(pos, vel, mass, T0 + 3600.0)   # an hour into the plan
            c.wait_for(lambda: c.schedules, 0.3)
        n0 = len(health("/sc1/daddy_guidance"))
        assert c.wait_for(lambda: [s for s in health("/sc1/daddy_guidance")[n0:]
                                   if s.level == DiagnosticStatus.OK], 5.0)
        v1 = {kv.key: kv.value for kv in health("/sc1/daddy_guidance")[-1].values}
        plan = nodes[0].planner.plan
        assert float(v1["plan_age_s"]) == pytest.approx(T0 + 3600.0 - plan.epoch_s, abs=1e-3)
        next_end = plan.epoch_s + plan.stage_start_s[0] + plan.stage_dt_s[0]
        assert float(v1["time_to_next_stage_s"]) == pytest.approx(next_end - (T0 + 3600.0),
                                                                  abs=1e-3)
    finally:
        c.close()
        for s in spins:
            s.shutdown()
        for n in nodes:
            n.stop()
            n.destroy_node()


def test_parameter_descriptors_carry_read_only_flags_and_ranges(graph):
    """Descriptors as tools show them: the parameters read at construction are read_only,
    bounded ones carry their range (rclpy refuses a value outside it, and a constructor given
    one raises DaddyError naming the parameter), and each says when it may change."""
    from rclpy.parameter import Parameter

    from daddy_core.errors import DaddyError
    node, _ = graph
    d = node.describe_parameter("autostart")
    assert d.read_only and "construction" in d.additional_constraints
    d = node.describe_parameter("thrust_margin")
    assert not d.read_only and d.floating_point_range[0].to_value == pytest.approx(0.99)
    assert node.describe_parameter("stages").integer_range[0].to_value == 100_000
    assert "every state" in node.describe_parameter("time_budget_s").additional_constraints
    results = node.set_parameters([Parameter("time_budget_s", value=1e6),
                                   Parameter("thrust_topic", value="elsewhere")])
    assert not results[0].successful and not results[1].successful
    assert node.get_parameter("time_budget_s").value == pytest.approx(60.0)
    with pytest.raises(DaddyError, match="thrust_margin"):
        GuidanceNode(namespace="/bad", scenario="earth_mars", frame_id=FRAME, thrust_margin=2.0)


def test_settings_change_in_flight_at_the_next_estimate_or_re_plan_and_the_rest_are_refused(
        graph):
    """Issue 49 item 5: every setting that can safely change while active can (the re-plan
    policy, the estimate tests, the solver's settings, the thrust margin, the budget): the
    estimate-side ones apply at once, the solver's at the next re-plan (not the one running);
    the settings that shape the problem or the interface are refused with the reason."""
    from rclpy.parameter import Parameter

    from daddy_ros.config import bundled_plan
    node = GuidanceNode(namespace="/inflight", scenario="earth_mars", frame_id=FRAME,
                        time_budget_s=60.0)
    try:
        assert node.lifecycle_state == "active"
        new = {"trigger_position_m": 1234.0, "replan_every_stages": 3, "arrival_stages": 4,
               "feedback_position_m": 5000.0, "fit_position_m": 2e6, "max_stamp_jump_stages": 4.0,
               "stamp_jump_confirmations": 5, "staleness_s": 100.0, "thrust_margin": 0.1,
               "time_budget_s": 30.0, "tol_aul": 1e-7, "method": "hess", "polish": False}
        results = node.set_parameters([Parameter(k, value=v) for k, v in new.items()])
        assert all(r.successful for r in results), [r.reason for r in results]
        s = node.session
        # the estimates' tests and the re-plan policy: at once (the policy's prediction kept)
        assert s.trigger.settings.trigger_position_m == 1234.0
        assert s.trigger.settings.replan_every_stages == 3 and s.trigger.settings.arrival_stages == 4
        assert s.laws.position_m == 5000.0 and s.fit.position_m == 2e6
        assert (s.stamps.stages, s.stamps.confirmations) == (4.0, 5)
        assert node.planner.checks.staleness_s == 100.0
        # the solver's settings: from the next re-plan on
        assert node.planner.config.thrust_margin == 0.05 and node.planner.method == "dyn"
        pos, vel, mass = truth_at_start()
        node.planner.load_plan(bundled_plan("earth_mars"), T0)
        out = node.planner.replan(pos, vel, mass, T0, "after-the-change")
        assert out.ok, out.reason
        cfg = node.planner.config
        assert (cfg.thrust_margin, cfg.time_budget_s, cfg.tol_aul, cfg.method, cfg.polish) == (
            0.1, 30.0, 1e-7, "hess", False)
        rating = node.planner.case.spacecraft.max_thrust_n
        assert float(node.planner.base_problem.u_max) == pytest.approx(
            float(node.planner.units.thrust(0.9 * rating)))
        assert node.planner.policy.warm.aul.tol == 1e-7
        # what shapes the problem or the interface: refused while configured, with the reason
        for name, value in (("stages", 10), ("scenario", "halo_l2_l1"), ("fuel_optimal", False),
                            ("frame_id", "map"), ("state_topic", "elsewhere")):
            r = node.set_parameters([Parameter(name, value=value)])[0]
            assert not r.successful and "read-only once configured" in r.reason, (name, r)
        r = node.set_parameters([Parameter("method", value="newton")])[0]
        assert not r.successful and "method 'newton' is unknown" in r.reason
    finally:
        node.trigger_shutdown()
        node.destroy_node()


def test_recording_writes_every_topic_and_a_schedule_round_trips(graph, tmp_path):
    """McapRecorder (gnc_demo --record) on the node's interface topics and the simulator's
    truth: every topic of a short session is in the file with its ros2msg schema and its QoS
    as rosbag2's offered_qos_profiles (the latched plan topics transient local, so ``ros2 bag
    play`` re-latches them), the file decodes with the standard MCAP ROS 2 decoder, the
    recorded schedule is the one the client received and the truth the one published."""
    pytest.importorskip("mcap_ros2", reason="the record extra (make test installs it)")
    yaml = pytest.importorskip("yaml")
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    from daddy_sim.demo import RosLink, truth_topics
    from daddy_sim.recording import McapRecorder
    node, c = graph
    path = tmp_path / "run.mcap"
    rec = McapRecorder(path, {**node.interface_topics(), **truth_topics()},
                       node_name="daddy_test_recorder")
    sim_link = RosLink(FRAME, timeout_s=10.0)
    end = time.monotonic() + 15
    while time.monotonic() < end and rec.node.count_publishers("/state_estimate") == 0:
        time.sleep(0.05)
    pos, vel, mass = truth_at_start()
    t = T0 + 20.0   # (the first estimates adopt the nominal plan when no test did before)
    n_sched = len(c.schedules)
    end = time.monotonic() + 20
    while time.monotonic() < end and not (rec.counts["/state_estimate"]
                                          and rec.counts["/thrust_command"]):
        c.publish_estimate(pos, vel, mass, t)
        time.sleep(0.2)
    c.request("recorded", t)
    assert c.wait_for(lambda: c.status_for("recorded"), 60)
    assert c.wait_for(lambda: len(c.schedules) > n_sched, 15)
    end = time.monotonic() + 15
    while time.monotonic() < end and not rec.counts["/truth/state"]:
        sim_link.truth(pos, vel, mass, t)
        time.sleep(0.2)
    time.sleep(0.5)   # the last messages reach the recorder too
    counts = rec.close()
    sim_link.close()
    for topic in ("/state_estimate", "/mass_estimate", "/replan_request", "/control_schedule",
                  "/planned_path", "/thrust_command", "/diagnostics", "/truth/state",
                  "/truth/mass"):
        assert counts[topic] > 0, f"nothing recorded on {topic}: {counts}"
    seen, last_schedule, truth = {}, None, None
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        qos = {ch.topic: yaml.safe_load(ch.metadata["offered_qos_profiles"])[0]
               for ch in summary.channels.values()}
        distro = [m for m in reader.iter_metadata() if m.name == "rosbag2"]
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            seen[channel.topic] = seen.get(channel.topic, 0) + 1
            assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
            if channel.topic == "/control_schedule":
                last_schedule = decoded
            if channel.topic == "/truth/state":
                truth = decoded
    assert seen == counts
    # rmw's numbers: reliability 1 reliable / 2 best effort; durability 1 transient local
    for topic in ("/control_schedule", "/planned_path"):
        assert (qos[topic]["reliability"], qos[topic]["durability"], qos[topic]["depth"]) == (
            1, 1, 1), (topic, qos[topic])
    assert qos["/state_estimate"]["reliability"] == 2 and qos["/thrust_command"]["durability"] == 2
    assert distro and "ROS_DISTRO" in distro[0].metadata
    p = truth.pose.pose.position
    np.testing.assert_allclose([p.x, p.y, p.z], pos, rtol=1e-12)
    starts, u = cv.joint_trajectory_to_schedule(c.schedules[-1][1])
    assert list(last_schedule.joint_names) == ["thrust_x", "thrust_y", "thrust_z"]
    rec_u = np.array([list(p.effort) for p in last_schedule.points])
    np.testing.assert_array_equal(rec_u, u)


def test_node_replans_by_itself_on_drift_and_answers_the_estimate_after_it(graph):
    """The node's own policy over rclpy (/self namespace, defaults): an estimate 20 km off its
    prediction of the schedule in force triggers a re-plan (request_id self-drift-...) that
    starts from that estimate, and the estimate's thrust command comes after that re-plan's
    diagnostic, from the new plan; an estimate on the prediction triggers nothing."""
    from daddy_ros.spin import SpinThread
    node = GuidanceNode(namespace="/self", scenario="earth_mars", frame_id=FRAME,
                        time_budget_s=60.0)
    spin = SpinThread(node)
    c = GuidanceClient(FRAME, name="daddy_self_client", namespace="/self")
    try:
        pos, vel, mass = truth_at_start()
        end = time.monotonic() + 15
        while time.monotonic() < end and not c.schedules:   # the nominal, at the first estimate
            c.publish_estimate(pos, vel, mass, T0)
            c.wait_for(lambda: c.schedules, 0.3)
        assert c.schedules
        t1 = T0 + 600.0   # ten minutes on, on the prediction (the plan's thrust, no errors)
        sim = TruthSim("earth_mars", t0_s=T0)
        sim.apply(node.planner.plan.thrust_at(T0), 600.0)
        p1, v1, m1 = sim.truth_si()
        c.publish_estimate(p1, v1, m1, t1)
        assert c.wait_for(lambda: [m for _, m in c.thrust
                                   if abs(cv.stamp_to_s(m.header.stamp) - t1) < 1e-6], 15)
        t2 = t1 + 600.0
        sim.apply(node.planner.plan.thrust_at(t1), 600.0)
        p2, v2, m2 = sim.truth_si()
        n0 = len(c.diags)
        c.publish_estimate(p2 + [2e4, 0, 0], v2, m2, t2)
        got = c.wait_for(lambda: [m for _, m in c.thrust
                                  if abs(cv.stamp_to_s(m.header.stamp) - t2) < 1e-6], 60)
        assert got, "no thrust command for the drifted estimate"
        thrust_arrival = next(tt for tt, m in c.thrust
                              if abs(cv.stamp_to_s(m.header.stamp) - t2) < 1e-6)
        selfs = [(tt, st) for tt, m in c.diags[n0:] for st in m.status
                 if any(kv.key == "request_id" and kv.value.startswith("self-drift-")
                        for kv in st.values)]
        assert len(selfs) == 1, [st.message for _, st in selfs]
        tt, st = selfs[0]
        vals = {kv.key: kv.value for kv in st.values}
        assert float(vals["state_stamp_s"]) == pytest.approx(t2, abs=1e-6)
        assert tt <= thrust_arrival   # the command was withheld until the re-plan had finished
        assert node.planner.plan.epoch_s == pytest.approx(t2)
        assert not [st for _, m in c.diags[:n0] for st in m.status
                    if "self-" in str(st.values)]   # nothing on the undisturbed estimate
    finally:
        c.close()
        spin.shutdown()
        node.stop()
        node.destroy_node()


def test_an_earth_centred_scenario_is_flown_from_eci_odometry(graph, tmp_path):
    """An Earth-centred scenario (a user case file: the LEO spacecraft raising its orbit by
    10 km in a day, energy-optimal) over the graph: an ECI Odometry at departure gets a
    schedule whose efforts are in the osculating orbit's RTN axes (frame ``eci_rtn``), and a
    thrust command in ECI, the schedule's first effort turned by the estimate's RTN axes."""
    import json

    from daddy_core.catalogue.cases import CASES_DIR
    from daddy_core.dynamics import models
    from daddy_ros.spin import SpinThread
    d = json.loads((CASES_DIR / "leo_leo.json").read_text())
    d.update(name="leo_raise", tof_days=1.0, x_target=[6788.0, 0, 51.0, 145.0, 0, 0])
    path = tmp_path / "leo_raise.json"
    path.write_text(json.dumps(d))
    node = GuidanceNode(namespace="/leo", scenario=str(path), frame_id="eci",
                        fuel_optimal=False, self_replan=False, thrust_margin=0.0)
    spin = SpinThread(node)
    c = GuidanceClient("eci", name="daddy_earth_client", namespace="/leo")
    try:
        x = node.planner.units.cartesian_si(node.planner.case.cartesian_x0())
        end = time.monotonic() + 60
        while time.monotonic() < end and not c.schedules:
            c.publish_estimate(x[:3], x[3:6], x[6], T0)
            c.request("leo-1", T0)
            c.wait_for(lambda: c.schedules, 2.0)
        assert c.schedules, "no schedule for the Earth-centred scenario"
        msg = c.schedules[-1][1]
        assert msg.header.frame_id == "eci_rtn" and len(msg.points) == 155
        y = node.session.fit.predicted(node.planner.plan, T0 + 10.0)   # on the plan
        c.publish_estimate(y[:3], y[3:6], y[6], T0 + 10.0)
        assert c.wait_for(lambda: [m for _, m in c.thrust
                                   if cv.stamp_to_s(m.header.stamp) == T0 + 10.0], 10.0)
        cmd = [m for _, m in c.thrust if cv.stamp_to_s(m.header.stamp) == T0 + 10.0][-1]
        assert cmd.header.frame_id == "eci"
        expected = models.rtn_basis(y[:3], y[3:6]) @ np.array(msg.points[0].effort)
        np.testing.assert_allclose([cmd.vector.x, cmd.vector.y, cmd.vector.z], expected,
                                   rtol=1e-9, atol=1e-12)
    finally:
        c.close()
        spin.shutdown()
        node.stop()
        node.destroy_node()


def test_a_keep_out_scenario_adopts_and_reports_plans_held_between_the_nodes(graph, tmp_path):
    """A halo scenario with a 25,000 km keep-out around the Moon (``r_min_km``) over the
    graph: its nominal (a keep-out solution) is adopted, a warm re-plan from a perturbed
    estimate keeps out along its dense re-propagation and reports the margin in km; the
    bundled plan, solved without the keep-out, is not used (plans that dip in are refused:
    ``test_path_constraints``)."""
    from daddy_core.catalogue import load_case, problem_from_case
    from daddy_core.solver import case_options, solve
    from daddy_ros.spin import SpinThread
    case = load_case("halo_l2_l1")
    problem = problem_from_case(case, r_min_km=25_000.0)
    nominal = solve(problem, options=case_options(case, True))
    assert nominal.converged and nominal.min_path_margin >= -1e-10
    path = tmp_path / "halo_keep_out.json"
    nominal.to_json(path)
    node = GuidanceNode(namespace="/ko", scenario="halo_l2_l1", frame_id="em_rotating",
                        r_min_km=25_000.0, plan_file=str(path), thrust_margin=0.0,
                        self_replan=False)
    spin = SpinThread(node)
    c = GuidanceClient("em_rotating", name="daddy_keep_out_client", namespace="/ko")
    try:
        sim = TruthSim("halo_l2_l1", t0_s=T0)
        pos, vel, mass = sim.truth_si()
        end = time.monotonic() + 30
        while time.monotonic() < end and not c.schedules:
            c.publish_estimate(pos, vel, mass, T0)
            c.wait_for(lambda: c.schedules, 2.0)
        assert c.schedules, "the keep-out nominal was not adopted"
        plan = node.planner.plan
        for j in range(2):
            sim.apply(plan.thrust_n[j], plan.stage_dt_s[j])
        p, v, m = sim.truth_si()
        c.publish_estimate(p + [2e4, 0, 0], v + [0.5, 0, 0], m, sim.t_s)
        c.wait_for(lambda: c.thrust, 10)
        c.request("ko-1", sim.t_s)
        st = c.wait_for(lambda: c.status_for("ko-1"), 120)
        assert st, "no diagnostics for ko-1"
        vals = {kv.key: kv.value for kv in st.values}
        assert vals["code"] == "OK" and vals["plan_kept"] == "no", st.message
        assert float(vals["keep_out_margin_km"]) >= -1e-6
        assert node.planner.plan.solution.min_path_margin >= -1e-6 / problem.units.lu_km
    finally:
        c.close()
        spin.shutdown()
        node.stop()
        node.destroy_node()
