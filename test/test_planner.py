"""ROS-free guidance logic: the warm-start shift, estimate checks, plan persistence, and the
message conversions (message classes only, no graph)."""
import json
import time

import numpy as np
import pytest

from daddy_core.errors import DaddyError
from daddy_ros.checks import InputRejected
from daddy_ros.config import PLANS_DIR, TriggerConfig
from daddy_sim.closed_loop import flight_steps
from daddy_ros.plan import Code
from daddy_ros.planner import GuidancePlanner
from daddy_ros.self_trigger import Reason, ReplanTrigger, propagate
from daddy_ros.shift import ARRIVAL_SPEED_SCALE_M_S, MIN_STAGE_FRACTION, MIN_STAGES_LEFT
from daddy_sim.sim import T0_S, Errors, TruthSim


@pytest.fixture(scope="module")
def planner():
    pl = GuidancePlanner("earth_mars")
    pl.load_plan(PLANS_DIR / "earth_mars_fuel.json", T0_S)
    return pl


def test_shift_drops_executed_stages_and_keeps_time_to_go(planner):
    plan = planner.plan
    dt = plan.stage_dt_s
    x0 = planner.plan.solution.X[0]
    tu = planner.units.tu_s
    # 2.5 stages flown: two stages dropped, the current (third) one shortened
    t = plan.epoch_s + dt[0] + dt[1] + 0.5 * dt[2]
    s = planner.shift(plan, t, x0)
    prob, U, duals, maps = s.problem, s.start.U, s.start.duals, s.start.maps
    assert prob.N == len(dt) - 2 and not s.arrival
    assert s.start.rho == plan.solution.rho
    assert prob.stage_dt[0] * tu == pytest.approx(0.5 * dt[2])
    assert np.sum(prob.stage_dt) * tu == pytest.approx(plan.end_s - t)
    np.testing.assert_array_equal(U, plan.solution.U[2:])
    assert duals["lam"].shape[1] == prob.N
    # the plan's stage maps (expanded when it was loaded) come along; the shortened first
    # stage's map is not used
    assert maps.N == prob.N and maps.radius[0] == 0
    np.testing.assert_array_equal(maps.radius[1:], plan.solution.stage_maps.radius[3:])
    at_boundary = planner.shift(plan, plan.epoch_s + dt[0] + dt[1], x0).start.maps
    assert at_boundary.N == len(dt) - 2 and at_boundary.radius[0] > 0
    # a first stage shorter than MIN_STAGE_FRACTION is merged into the next one
    t = plan.epoch_s + dt[0] - 0.5 * MIN_STAGE_FRACTION * dt[1]
    s = planner.shift(plan, t, x0)
    prob, U, maps = s.problem, s.start.U, s.start.maps
    assert prob.N == len(dt) - 1
    assert prob.stage_dt[0] * tu == pytest.approx(dt[1] + 0.5 * MIN_STAGE_FRACTION * dt[1])
    np.testing.assert_array_equal(U, plan.solution.U[1:])   # the merged stage flies stage 1's
    assert maps.N == prob.N and maps.radius[0] == 0
    with pytest.raises(InputRejected, match="ended"):
        planner.shift(plan, plan.end_s + 1.0, x0)
    cold = planner.shift(None, t, x0)   # no plan: the whole transfer from x0, no warm start
    assert cold.start is None and cold.problem.N == len(dt)
    np.testing.assert_array_equal(cold.problem.x0, x0)


def test_shift_splits_the_last_stages(planner):
    plan = planner.plan
    dt = plan.stage_dt_s
    x0 = planner.plan.solution.X[0]
    tu = planner.units.tu_s
    # half of the last stage left: halved into MIN_STAGES_LEFT equal stages flying its thrust
    t = plan.end_s - 0.5 * dt[-1]
    s = planner.shift(plan, t, x0)
    prob, U, duals, maps = s.problem, s.start.U, s.start.duals, s.start.maps
    assert prob.N == MIN_STAGES_LEFT and s.arrival
    np.testing.assert_allclose(prob.stage_dt * tu, np.full(MIN_STAGES_LEFT, 0.5 * dt[-1] / MIN_STAGES_LEFT))
    np.testing.assert_array_equal(U, np.tile(plan.solution.U[-1], (MIN_STAGES_LEFT, 1)))
    assert maps is None   # a new grid: no maps
    assert duals["lam"].shape[1] == MIN_STAGES_LEFT
    # two stages left: each halved, each half flying its stage's thrust
    t = plan.end_s - dt[-2] - dt[-1]
    s = planner.shift(plan, t, x0)
    prob, U = s.problem, s.start.U
    assert np.sum(prob.stage_dt) * tu == pytest.approx(dt[-2] + dt[-1])
    np.testing.assert_array_equal(U, plan.solution.U[[-2, -2, -1, -1]])


def test_the_arrival_split_flies_the_plan_in_force_exactly(planner):
    """Three whole stages left: split into MIN_STAGES_LEFT by halving the longest (the first
    of equal ones), each new stage flying its old stage's thrust, so the warm start from the
    plan's node arrives where the plan does."""
    plan = planner.plan
    dt, X = plan.stage_dt_s, plan.solution.X
    t = plan.end_s - dt[-3] - dt[-2] - dt[-1]
    s = planner.shift(plan, t, planner.units.cartesian_normalised(plan.states_si[-4]))
    assert s.arrival and s.problem.N == MIN_STAGES_LEFT
    np.testing.assert_allclose(s.problem.stage_dt * planner.units.tu_s,
                               [dt[-3] / 2, dt[-3] / 2, dt[-2], dt[-1]], rtol=1e-12)
    np.testing.assert_array_equal(s.start.U, plan.solution.U[[-3, -3, -2, -1]])
    flown = s.problem.rollout(s.start.U)[-1]
    assert np.max(np.abs(flown[:6] - X[-1][:6])) < 1e-8 * np.max(np.abs(X[-1][:6]))


def test_a_plan_of_the_arrival_phase_re_plans_in_the_arrival_phase():
    """An arrival plan keeps its position tolerance in every re-plan of it, even where the
    shift leaves MIN_STAGES_LEFT stages or more (no flip to the exact target and back), and
    its schedule (a short first stage is not merged); a plan that is not one targets the
    position exactly there; a re-plan of the arrival phase stores an arrival plan."""
    from dataclasses import replace
    pl = GuidancePlanner("earth_mars", arrival_tolerance_m=300e3)
    plan = pl.load_plan(PLANS_DIR / "earth_mars_fuel.json", T0_S)
    dt = plan.stage_dt_s
    t = plan.end_s - np.sum(dt[-5:])                  # five stages left
    x = pl.units.cartesian_normalised(plan.states_si[-6])
    exact = pl.shift(plan, t, x)
    off = exact.problem.x_target.copy()
    R = pl.units.length(300e3)
    off[0] += R / 3                                   # a third of the tolerance off the target
    assert not exact.arrival
    assert exact.problem.terminal_violation(off) == pytest.approx(R / 3)   # raw: exact target
    arriving = replace(plan, arrival=True)
    sticky = pl.shift(arriving, t, x)
    assert sticky.arrival and sticky.problem.N == 5
    # the arrival rows: the plan flown from x arrives on the target, one tolerance weighs 1 cm/s
    assert sticky.problem.terminal_violation(off) == pytest.approx(
        pl.units.speed(ARRIVAL_SPEED_SCALE_M_S) / 3, rel=1e-2)
    # a short first stage: merged into the next (flying its thrust), except in an arrival plan
    t += 0.9 * dt[-5]
    assert pl.shift(plan, t, x).problem.N == 4
    short = pl.shift(arriving, t, x)
    assert short.problem.N == 5
    assert short.problem.stage_dt[0] * pl.units.tu_s == pytest.approx(0.1 * dt[-5], rel=1e-6)
    np.testing.assert_array_equal(short.start.U, plan.solution.U[-5:])
    t = plan.end_s - 0.5 * dt[-1]
    s = plan.states_si[-1]
    out = pl.replan(s[:3], s[3:6], s[6], t, "arrival", now_s=t)
    assert out.ok and out.plan.arrival, out.reason
    assert not plan.arrival


def test_arrival_phase_aims_where_the_plan_arrives_within_the_tolerance():
    """An arrival re-plan targets the velocity exactly and the position at the aim point:
    where the plan in force, flown from the estimate, arrives (a position error inside the
    tolerance left alone, no drift inside it for a fraction of a gram), radially projected
    onto the tolerance's sphere when outside it."""
    pl = GuidancePlanner("earth_mars", arrival_tolerance_m=300e3)
    plan = pl.load_plan(PLANS_DIR / "earth_mars_fuel.json", T0_S)
    mid = pl.shift(plan, plan.epoch_s + plan.stage_dt_s[0], plan.solution.X[0]).problem
    assert mid.terminal_constraints(mid.x_target)[0].shape == (6,)   # not yet: exact target
    R = pl.units.length(300e3)
    s = pl.units.speed(ARRIVAL_SPEED_SCALE_M_S)      # 1 cm/s: the weight of one tolerance
    t = plan.end_s - plan.stage_dt_s[-1]              # the last stage's start
    for dv, inside in ((0.2, True), (2.0, False)):    # [m/s] over 8.7 days: ~150 / ~1500 km
        x0 = plan.solution.X[-2].copy()
        x0[3:6] += pl.units.speed(dv) * np.array([0.6, -0.8, 0.0])
        shifted = pl.shift(plan, t, x0)
        prob, xt = shifted.problem, shifted.problem.x_target
        free = prob.rollout(shifted.start.U)[-1]      # the plan in force, flown
        miss = np.linalg.norm(free[:3] - xt[:3])
        assert (miss < 0.9 * R) if inside else (miss > 2 * R), miss / R
        aim = free[:3] if inside else xt[:3] + (free[:3] - xt[:3]) * (R / miss)
        x = xt.copy()
        x[:3] = aim
        g, n_ineq = prob.terminal_constraints(x)
        assert n_ineq == 0 and g.shape == (6,)
        np.testing.assert_allclose(g, 0.0, atol=1e-9 * s)
        x[0] += R                                     # one tolerance off the aim
        assert prob.terminal_violation(x) == pytest.approx(s, rel=1e-9)
        x[0] -= R
        x[4] += 1e-3                                  # the velocity stays exact
        assert prob.terminal_violation(x) == pytest.approx(1e-3)
    with pytest.raises(DaddyError, match="arrival_tolerance_m"):
        GuidancePlanner("earth_mars", arrival_tolerance_m=-1.0)


def _trigger(policy=None):
    """The node's re-plan policy on the bundled Earth-Mars nominal (40 stages of 8.7 days)."""
    pl = GuidancePlanner("earth_mars")
    pl.load_plan(PLANS_DIR / "earth_mars_fuel.json", T0_S)
    trig = ReplanTrigger.for_planner(pl, policy or TriggerConfig())
    return pl, trig, trig.stage_length


def test_self_trigger_predicts_the_flight_and_flags_drift():
    """Without errors the prediction follows the truth flown with the plan's thrust (no drift,
    no re-plan inside a stage); an estimate 6 km or 6 cm/s off re-plans (DRIFT), and the
    prediction restarts from the estimate a re-plan starts from."""
    pl, trig, stage_s = _trigger()
    sim = TruthSim("earth_mars", Errors(0, 0, 0, 0), t0_s=T0_S)
    plan = pl.plan
    assert trig.observe(sim.t_s, *sim.truth_si(), plan) is None    # starts the prediction
    for _ in range(3):                         # a third of the first stage, the truth flown
        dt = stage_s / 4
        sim.apply(plan.thrust_at(sim.t_s), dt)
        pos, vel, mass = sim.truth_si()
        assert trig.observe(sim.t_s, pos, vel, mass, plan) is None
    assert trig.observe(sim.t_s, pos + [6e3, 0, 0], vel, mass, plan) is Reason.DRIFT
    assert trig.observe(sim.t_s, pos, vel + [0, 0.06, 0], mass, plan) is Reason.DRIFT
    trig.replanned(sim.t_s, pos + [6e3, 0, 0], vel, mass)
    assert trig.observe(sim.t_s, pos + [6e3, 0, 0], vel, mass, plan) is None
    # an estimate older than the prediction (out of order) is not judged, nor moves it
    assert trig.observe(sim.t_s - 3600.0, pos + [9e4, 0, 0], vel, mass, plan) is None
    assert trig.observe(sim.t_s, pos + [6e3, 0, 0], vel, mass, plan) is None
    off = ReplanTrigger.for_planner(pl, TriggerConfig(
        trigger_position_m=0.0, trigger_velocity_m_s=0.0, replan_every_stages=0,
        arrival_stages=0))
    assert off.observe(T0_S, pos, vel, mass, plan) is None
    assert off.observe(T0_S + 1.0, pos + 1e9, vel + 1e3, mass, plan) is None   # all off


def test_self_trigger_stage_boundaries_and_arrival_phase_on_the_demo_grid():
    """On the closed loop's grid (flight_steps) the policy re-plans at every replan_every-th
    stage start before the arrival phase and at every arrival estimate but the last; with
    drift off nothing else."""
    pl, trig, stage_s = _trigger(TriggerConfig(replan_every_stages=5, trigger_position_m=0.0,
                                               trigger_velocity_m_s=0.0, arrival_stages=2,
                                               arrival_min_step=1 / 64))
    N, plan = pl.base_problem.N, pl.plan
    pos, vel, mass = TruthSim("earth_mars", t0_s=T0_S).truth_si()
    steps = list(flight_steps(T0_S, N, stage_s, 2, 2, 8, 1 / 64))
    starts, ends = (np.array(v) for v in zip(*steps))
    np.testing.assert_allclose(starts[1:], ends[:-1])                   # contiguous
    assert ends[-1] == pytest.approx(T0_S + N * stage_s)
    assert ends[-1] - starts[-1] == pytest.approx(stage_s / 64)
    reasons = [trig.observe(t, pos, vel, mass, plan) for t in starts]
    stage_at = [round((t - T0_S) / stage_s, 6) for t, r in zip(starts, reasons)
                if r is Reason.STAGE]
    assert stage_at == [5.0 * k for k in range(1, 8)]                  # 5, 10, ..., 35
    arrival = [r is Reason.ARRIVAL for t, r in zip(starts, reasons) if t >= T0_S + 38 * stage_s]
    assert all(arrival[:-1]) and not arrival[-1]     # the last open-loop step does not re-plan
    assert reasons.count(None) == len(reasons) - len(stage_at) - sum(arrival)


def test_replan_gives_up_the_thrust_margin_only_as_far_as_needed():
    """The nominal Earth-Mars plan ends on a burn at the derated bound; 5 m/s less speed along
    it cannot be made up on the derated bound, but the next rung of the margin ladder suffices
    -- the plan must not jump to the full rating and leave nothing for later errors."""
    pl = GuidancePlanner("earth_mars")
    plan = pl.load_plan(PLANS_DIR / "earth_mars_fuel.json", T0_S)
    full = pl.case.spacecraft.max_thrust_n
    ratings = [float(pl.units.thrust_n(p.u_max)) for p in pl.rated_problems]   # [N]
    assert ratings[0] == pytest.approx(0.95 * full) and ratings[-1] == pytest.approx(full)
    assert np.all(np.diff(ratings) > 0)
    k = 34                                               # inside the last burn
    peak = np.linalg.norm(plan.thrust_n[k:], axis=1)
    assert np.allclose(peak, ratings[0], rtol=1e-6)      # riding the derated bound
    t = plan.epoch_s + np.sum(plan.stage_dt_s[:k])
    s = plan.states_si[k]
    along = plan.thrust_n[k] / np.linalg.norm(plan.thrust_n[k])
    out = pl.replan(s[:3], s[3:6] - 5.0 * along, s[6], t, "behind", now_s=t)
    assert out.ok and out.level == "OK", out.reason
    new_peak = np.max(np.linalg.norm(out.plan.thrust_n, axis=1))
    assert ratings[0] * 1.001 < new_peak <= ratings[1] * 1.001


def test_a_plan_solved_on_a_higher_rung_re_plans_from_that_rung(monkeypatch):
    """A plan solved on rung 1 re-plans from rung 1 even where its thrust fits rung 0
    (``GuidancePlanner._start_rung``: rung 0 had failed for a state next to it); a plan solved
    on rung 0 from rung 0."""
    import dataclasses

    import daddy_ros.planner as planner_mod
    pl = GuidancePlanner("earth_mars")
    plan = pl.load_plan(PLANS_DIR / "earth_mars_fuel.json", T0_S)   # fits rung 0
    bounds, real_solve = [], planner_mod.solve

    def recording_solve(problem, *args, **kw):
        bounds.append(problem.u_max)
        return real_solve(problem, *args, **kw)

    monkeypatch.setattr(planner_mod, "solve", recording_solve)
    k = 5
    t = plan.epoch_s + np.sum(plan.stage_dt_s[:k])
    s = plan.states_si[k]
    for rung in (0, 1):
        pl.set_plan(dataclasses.replace(plan, thrust_bound_n=float(
            pl.units.thrust_n(pl.rated_problems[rung].u_max))))
        bounds.clear()
        out = pl.replan(s[:3] + 1e3, s[3:6], s[6], t, f"r{rung}", now_s=t)
        assert out.ok, out.reason
        assert bounds[0] == pl.rated_problems[rung].u_max


def test_one_budget_for_the_whole_replan_ladder_included(monkeypatch):
    """The margin ladder's rungs solve in what is left of the re-plan's budget, and are not
    tried once it is spent: a re-plan answers within its budget (an outage campaign had
    re-plans of 112 s on a 60 s budget, one budget per rung)."""
    import daddy_ros.planner as planner_mod
    budgets, real_solve = [], planner_mod.solve

    def slow_solve(problem, guess, options, **kw):
        budgets.append(options.run.time_budget_s)
        sol = real_solve(problem, guess, options=options, **kw)
        time.sleep(max(0.0, options.run.time_budget_s))   # spends whatever it was given
        return sol

    monkeypatch.setattr(planner_mod, "solve", slow_solve)
    pl = GuidancePlanner("earth_mars", time_budget_s=1.0)
    plan = pl.load_plan(PLANS_DIR / "earth_mars_fuel.json", T0_S)
    k = 34                                       # on the derated bound (test above)
    t = plan.epoch_s + np.sum(plan.stage_dt_s[:k])
    s = plan.states_si[k]
    along = plan.thrust_n[k] / np.linalg.norm(plan.thrust_n[k])
    out = pl.replan(s[:3], s[3:6] - 5.0 * along, s[6], t, "behind", now_s=t)
    assert len(budgets) == 1 and budgets[0] <= 1.0          # no rung after the budget
    assert "rung 1: not tried, the 1 s budget was spent" in out.reason, out.reason
    assert out.code is Code.BUDGET_EXCEEDED or not out.ok


@pytest.mark.parametrize("pos_scale, vel_nan, mass, stamp, now, field", [
    (1.0, True, 900.0, T0_S, None, "twist.twist.linear"),
    (1e-3, False, 900.0, T0_S, None, "heliocentric"),
    (1.0, False, 400.0, T0_S, None, "inertia.m"),
    (1.0, False, 2000.0, T0_S, None, "inertia.m"),
    (1.0, False, 900.0, 0.0, None, "header.stamp"),
    (1.0, False, 900.0, T0_S + 10.0, T0_S, "future"),
    (1.0, False, 900.0, T0_S, T0_S + 1e6, "stale"),
])
def test_check_state_names_the_field(planner, pos_scale, vel_nan, mass, stamp, now, field):
    X = planner.plan.states_si
    vel = X[0, 3:6] * (np.nan if vel_nan else 1.0)
    with pytest.raises(InputRejected, match=field):
        planner.checks.check_state(X[0, :3] * pos_scale, vel, mass, stamp, now)


def test_persistence_round_trip_and_bad_files(planner, tmp_path):
    path = tmp_path / "plan.json"
    planner.save_plan(path)
    other = GuidancePlanner("earth_mars")
    plan = other.restore_plan(path)
    assert plan.epoch_s == planner.plan.epoch_s
    np.testing.assert_array_equal(plan.thrust_n, planner.plan.thrust_n)
    np.testing.assert_array_equal(plan.solution.duals["lam"], planner.plan.solution.duals["lam"])
    assert not plan.arrival
    data = json.loads(path.read_text())
    with pytest.raises(DaddyError, match="scenario"):
        GuidancePlanner("halo_l2_l1").restore_plan(path)
    data["arrival"] = True                       # a plan of the arrival phase stays one
    path.write_text(json.dumps(data))
    assert other.restore_plan(path).arrival
    data["arrival"] = "yes"
    path.write_text(json.dumps(data))
    with pytest.raises(DaddyError, match="arrival"):
        other.restore_plan(path)
    data["arrival"] = False
    data["epoch_s"] = "soon"
    path.write_text(json.dumps(data))
    with pytest.raises(DaddyError, match="unreadable"):
        other.restore_plan(path)
    path.write_text("{ truncated")
    with pytest.raises(DaddyError, match="unreadable"):
        other.restore_plan(path)


def test_odometry_twist_is_read_in_child_frame_and_covariances_checked():
    """nav_msgs/Odometry: the twist is in child_frame_id. A body-frame twist is rotated into
    header.frame_id by the pose orientation; one in the header's own frame (or an empty child
    frame) is taken as it is; an orientation that is not a unit quaternion, or a covariance
    that is given but not finite and positive definite, is refused naming the field."""
    cv = pytest.importorskip("daddy_ros.conversions")
    from daddy_ros.checks import InputRejected
    v_inertial = np.array([1200.0, -350.0, 80.0])
    angle = 0.7   # body frame rotated by 0.7 rad about z, then 0.3 rad about the new x
    qz = np.array([np.cos(angle / 2), 0.0, 0.0, np.sin(angle / 2)])
    qx = np.array([np.cos(0.15), np.sin(0.15), 0.0, 0.0])
    w1, x1, y1, z1 = qz
    w2, x2, y2, z2 = qx
    q = np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                  w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])
    c, s = np.cos(angle), np.sin(angle)
    Rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    Rx = np.array([[1, 0, 0], [0, np.cos(0.3), -np.sin(0.3)], [0, np.sin(0.3), np.cos(0.3)]])
    v_body = (Rz @ Rx).T @ v_inertial
    msg = cv.state_to_odometry([1e11, 2e10, 0.0], v_body, 50.0, "sun_ecliptic")
    msg.child_frame_id = "body"
    (msg.pose.pose.orientation.w, msg.pose.pose.orientation.x, msg.pose.pose.orientation.y,
     msg.pose.pose.orientation.z) = map(float, q)
    np.testing.assert_allclose(cv.odometry_to_state(msg).vel_m_s, v_inertial, rtol=1e-12)
    for child in ("", "sun_ecliptic"):   # the twist is in the header frame already
        msg.child_frame_id = child
        np.testing.assert_allclose(cv.odometry_to_state(msg).vel_m_s, v_body, rtol=0)
    msg.child_frame_id = "body"
    msg.pose.pose.orientation.w = msg.pose.pose.orientation.x = 0.0
    msg.pose.pose.orientation.y = msg.pose.pose.orientation.z = 0.0
    with pytest.raises(InputRejected, match="pose.pose.orientation is not a unit quaternion"):
        cv.odometry_to_state(msg)
    msg.pose.pose.orientation.w = 1.0
    cov = np.zeros((6, 6))
    cov[:3, :3] = np.diag([4.0, 9.0, 16.0])   # sigma 2, 3, 4 m
    msg.pose.covariance = cov.ravel().tolist()
    est = cv.odometry_to_state(msg)
    assert est.pos_sigma_m == pytest.approx(np.sqrt(29.0 / 3.0)) and est.vel_sigma_m_s is None
    for bad, what in ((np.nan, "non-finite"), (-1.0, "not positive definite")):
        cov[1, 1] = bad
        msg.pose.covariance = cov.ravel().tolist()
        with pytest.raises(InputRejected, match=f"state_estimate.pose.covariance.*{what}|"
                                                f"state_estimate.pose.covariance is {what}"):
            cv.odometry_to_state(msg)


def test_message_conversions_round_trip(planner):
    cv = pytest.importorskip("daddy_ros.conversions")
    plan = planner.plan
    msg = cv.state_to_odometry(plan.states_si[0, :3], plan.states_si[0, 3:6], 1234.5, "f")
    est = cv.odometry_to_state(msg)
    np.testing.assert_allclose(est.pos_m, plan.states_si[0, :3])
    np.testing.assert_allclose(est.vel_m_s, plan.states_si[0, 3:6])
    assert est.stamp_s == pytest.approx(1234.5) and est.frame_id == "f"
    assert est.pos_sigma_m is None and est.vel_sigma_m_s is None   # no covariance given
    # a schedule published mid-plan starts at the stage containing from_s
    from_s = plan.epoch_s + plan.stage_dt_s[0] * 1.5
    traj = cv.plan_to_joint_trajectory(plan, "f", from_s)
    starts, u = cv.joint_trajectory_to_schedule(traj)
    assert len(u) == len(plan.thrust_n) - 1
    np.testing.assert_array_equal(u, plan.thrust_n[1:])
    assert starts[0] == 0.0
    assert starts[1] == pytest.approx(plan.stage_dt_s[:2].sum() - 1.5 * plan.stage_dt_s[0],
                                      abs=1e-6)


def test_warm_replans_loosen_the_aul_tolerance_except_in_the_arrival_phase(monkeypatch):
    """Polished warm re-plans stop the AUL at WARM_TOL_AUL (Newton finishes the constraints),
    polish from the DDP's maps and hold inequalities within WARM_ACTIVE_TOL on their bound (and
    do not stop DDP on its prediction alone); the arrival phase keeps the case's settings and
    fresh expansions, an explicit tol_aul applies throughout, and without polishing nothing
    changes."""
    import daddy_ros.planner as planner_mod
    from daddy_ros.replan_policy import WARM_ACTIVE_TOL, WARM_TOL_AUL
    pl = GuidancePlanner("earth_mars")
    case_tol, case_active = pl.policy.cold.aul.tol, pl.policy.cold.newton.active_tol
    assert case_tol < WARM_TOL_AUL and pl.policy.warm.aul.tol == WARM_TOL_AUL
    assert case_active < WARM_ACTIVE_TOL == pl.policy.warm.newton.active_tol
    assert GuidancePlanner("earth_mars", tol_aul=2e-6).policy.warm.aul.tol == 2e-6
    assert GuidancePlanner("earth_mars", polish=False).policy.warm.aul.tol == case_tol
    seen = []
    real_solve = planner_mod.solve

    def recording_solve(problem, *args, **kw):
        o = kw["options"]
        seen.append((problem.N, o.aul.tol, o.newton.polish_from_ddp_maps, o.newton.active_tol))
        return real_solve(problem, *args, **kw)

    monkeypatch.setattr(planner_mod, "solve", recording_solve)
    plan = pl.load_plan(PLANS_DIR / "earth_mars_fuel.json", T0_S)
    for k in (10, len(plan.stage_dt_s) - 2):            # mid-course, then the arrival phase
        t = plan.epoch_s + np.sum(plan.stage_dt_s[:k])
        s = plan.states_si[k]
        seen.clear()
        out = pl.replan(s[:3] + 1e5, s[3:6], s[6], t, f"k{k}", now_s=t)
        assert out.ok, out.reason
        assert seen[0] == ((len(plan.stage_dt_s) - k, WARM_TOL_AUL, True, WARM_ACTIVE_TOL)
                           if k == 10 else (MIN_STAGES_LEFT, case_tol, False, case_active))
        assert out.plan.solution.max_violation <= 1e-9


def test_a_plan_that_fails_its_repropagation_is_never_adopted(monkeypatch):
    """A solve whose DOP853 check failed (infinite miss) is not safe to fly: ERROR, and the
    last valid plan stays (on every rung of the margin ladder)."""
    from daddy_core.solver import assemble
    pl = GuidancePlanner("earth_mars")
    plan = pl.load_plan(PLANS_DIR / "earth_mars_fuel.json", T0_S)
    monkeypatch.setattr(assemble, "repropagation_miss", lambda problem, U, *rest: np.inf)
    k = 5
    t = plan.epoch_s + np.sum(plan.stage_dt_s[:k])
    s = plan.states_si[k]
    out = pl.replan(s[:3], s[3:6], s[6], t, "r1", now_s=t)
    assert not out.ok and out.level == "ERROR" and "re-propagated" in out.reason
    assert pl.plan is plan


def test_demo_plot_is_a_png_of_flown_and_planned(planner, tmp_path):
    """The demo's figure (matplotlib: the plots extra, installed by make demo / make test)."""
    pytest.importorskip("matplotlib")
    from daddy_sim.demo import plan_deviation, plot_closed_loop
    plan = planner.plan
    nodes = plan.epoch_s + np.append(plan.stage_start_s, plan.end_s - plan.epoch_s)
    # a flight grid of two steps per stage, flown 0.1 % off the plan at every node
    times = np.sort(np.concatenate([nodes, (nodes[:-1] + nodes[1:]) / 2]))
    flown = np.array([np.interp(times, nodes, plan.states_si[:, j]) for j in range(6)]).T
    r = {"flown_m": flown[:, :3] * 1.001, "flown_v_m_s": flown[:, 3:6] * 1.001,
         "times_s": times, "nav_error_si": np.full((len(times) - 1, 2), [100.0, 1e-3]),
         "thrust_log": np.column_stack([plan.epoch_s + plan.stage_start_s,
                                        np.linalg.norm(plan.thrust_n, axis=1)])}
    days, dr, dv = plan_deviation(r, plan)
    assert len(days) == len(nodes) and days[0] == 0.0
    np.testing.assert_allclose(dr, 1e-3 * np.linalg.norm(plan.states_si[:, :3], axis=1) / 1e3,
                               rtol=1e-12)
    np.testing.assert_allclose(dv, 1e-1 * np.linalg.norm(plan.states_si[:, 3:6], axis=1),
                               rtol=1e-12)
    path = tmp_path / "out" / "demo.png"
    plot_closed_loop(r, plan, path)
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000


def test_config_yaml_lists_every_node_parameter_with_its_default():
    """config/guidance.yaml, the node's declarations and the planner's defaults all come from
    daddy_ros.config: the file lists exactly the declared parameters, each at its default."""
    yaml = pytest.importorskip("yaml")
    from pathlib import Path

    from daddy_ros.config import PlannerConfig, parameters
    path = Path(__file__).parents[1] / "config" / "guidance.yaml"
    # "/**/daddy_guidance": the file applies to the node in any namespace (a plain
    # "daddy_guidance" key only to the root namespace's)
    listed = yaml.safe_load(path.read_text())["/**/daddy_guidance"]["ros__parameters"]
    declared = {p.name: p.default for p in parameters()}
    assert listed == declared
    assert all(type(listed[k]) is type(v) for k, v in declared.items())   # 0.0 stays a float
    # in flight: everything but what shapes the problem, the interface or the start-up
    fixed = {p.name for p in parameters() if not p.runtime}
    assert {"scenario", "stages", "fuel_optimal", "r_min_km", "frame_id", "plan_file",
            "persist_file", "autostart"} <= fixed
    assert {"time_budget_s", "staleness_s", "thrust_margin", "trigger_position_m"}.isdisjoint(fixed)
    pl = GuidancePlanner()
    assert pl.config == PlannerConfig() and pl.case.name == declared["scenario"]
    assert pl.time_budget_s == declared["time_budget_s"]


def test_warm_replans_optimise_the_cost_their_loaded_plan_was_solved_for(tmp_path):
    """A loaded plan whose last homotopy step was a pseudo-Huber one sets the warm (and
    arrival) re-plans' step to it; a plan whose exact end game ran from the energy step (the
    bundled halo nominal) leaves the case's last step; the cold solve keeps the case's whole
    homotopy."""
    pl = GuidancePlanner("halo_l2_l1")
    case_last = pl.policy.cold.homotopy[-1]
    plan_file = PLANS_DIR / "halo_l2_l1_fuel.json"
    data = json.loads(plan_file.read_text())
    assert data["history"][-1]["h"] == 0.0        # exact from the energy step
    pl.load_plan(plan_file, T0_S)
    assert pl.policy.warm.homotopy == pl.policy.arrival.homotopy == (case_last,)
    data["history"].append(dict(data["history"][-1], h=0.5, delta=0.1))
    smooth = tmp_path / "pseudo_huber.json"
    smooth.write_text(json.dumps(data))
    pl.load_plan(smooth, T0_S)
    assert pl.policy.warm.homotopy == pl.policy.arrival.homotopy == ((0.5, 0.1),)
    assert pl.policy.cold.homotopy[-1] == case_last


@pytest.fixture(scope="module")
def earth_planner(tmp_path_factory):
    """An Earth-centred scenario no issue names, as a user case file: the catalogue's LEO
    spacecraft raising its orbit by 10 km in a day (155 stages of 36 deg), energy-optimal,
    with its cold plan from the departure state at T0_S."""
    from daddy_core.catalogue.cases import CASES_DIR
    d = json.loads((CASES_DIR / "leo_leo.json").read_text())
    d.update(name="leo_raise", tof_days=1.0, x_target=[6788.0, 0, 51.0, 145.0, 0, 0])
    path = tmp_path_factory.mktemp("earth") / "leo_raise.json"
    path.write_text(json.dumps(d))
    pl = GuidancePlanner(str(path), thrust_margin=0.0, fuel_optimal=False)
    x = pl.units.cartesian_si(pl.case.cartesian_x0())
    out = pl.replan(x[:3], x[3:6], x[6], T0_S)
    assert out.ok and out.level == "OK", out.reason
    return pl


def test_an_earth_centred_scenario_plans_from_cartesian_estimates(earth_planner):
    """Estimates are Cartesian (ECI, SI) for every scenario: an Earth-centred plan starts at the
    estimate, its stages of true longitude become durations (summing to the time of flight),
    its states are Cartesian, and its thrust -- in the osculating orbit's RTN axes -- is
    commanded in the inertial frame, turned with the estimate's orbit."""
    from daddy_core.dynamics import models
    pl = earth_planner
    plan = pl.plan
    x = pl.units.cartesian_si(pl.case.cartesian_x0())
    assert plan.thrust_rtn and len(plan.stage_dt_s) == 155
    assert plan.stage_dt_s.sum() == pytest.approx(86400.0, abs=1e-3)
    np.testing.assert_allclose(plan.states_si[0, :3], x[:3], atol=1e-6)
    t = plan.epoch_s + 0.3 * plan.stage_dt_s[0]
    command = plan.command_at(t, x[:3], x[3:6])
    np.testing.assert_allclose(command, models.rtn_basis(x[:3], x[3:6]) @ plan.thrust_n[0])
    assert np.linalg.norm(command) == pytest.approx(np.linalg.norm(plan.thrust_n[0]))
    assert abs(x[:3] @ x[3:6]) < 1e-6 * np.linalg.norm(x[:3]) * np.linalg.norm(x[3:6])


def test_self_trigger_counts_an_earth_plans_stages_in_true_longitude(earth_planner):
    """Earth-centred stages are equal in true longitude, not in time (a rising orbit's stages
    last longer): the policy re-plans at the estimates on every replan_every-th stage start of
    that grid and in the arrival phase's stages, and at no estimate between two starts."""
    pl = earth_planner
    plan, N = pl.plan, pl.base_problem.N
    trig = ReplanTrigger.for_planner(pl, TriggerConfig(
        replan_every_stages=10, trigger_position_m=0.0, trigger_velocity_m_s=0.0,
        arrival_stages=2, arrival_min_step=1 / 64))
    np.testing.assert_allclose(pl.base_problem.stage_dt, trig.stage_length)   # ~36 deg
    K = len(plan.stage_dt_s)
    starts = plan.epoch_s + np.concatenate([[0.0], np.cumsum(plan.stage_dt_s)])
    reasons = {}
    for j in range(K + 1):                     # the plan's nodes and the midpoints of its stages
        pos, vel, mass = plan.states_si[j, :3], plan.states_si[j, 3:6], plan.states_si[j, 6]
        reasons[N - K + j] = trig.observe(starts[j], pos, vel, mass, plan)
        if j < K:
            x = pl.units.cartesian_si(propagate(pl.case, pl.units.cartesian_normalised(
                plan.states_si[j]), plan.thrust_n[j], 0.5 * plan.stage_dt_s[j]))
            reasons[N - K + j + 0.5] = trig.observe(starts[j] + 0.5 * plan.stage_dt_s[j],
                                                    x[:3], x[3:6], x[6], plan)
    stage = [k for k, r in reasons.items() if r is Reason.STAGE]
    arrival = [k for k, r in reasons.items() if r is Reason.ARRIVAL]
    first = N - K + 1                          # the first node observed after the prediction starts
    assert stage == [k for k in range(10, N - 2, 10) if k >= first]
    assert arrival == [N - 2, N - 1.5, N - 1, N - 0.5]
    assert all(r is None for k, r in reasons.items() if k not in stage + arrival)


def test_an_earth_centred_plan_is_re_planned_warm_from_a_perturbed_estimate(earth_planner):
    """After 5 % of the flight, flown in Cartesian coordinates in time with the plan's thrust
    (``self_trigger.propagate``, the node's own prediction: it meets the plan's next node to
    a few cm), an estimate 1 km and 1 m/s off: the warm re-plan starts at the estimate's true
    longitude mid-stage, keeps the arrival time and reaches the target orbit."""
    pl = earth_planner
    plan, case, u = pl.plan, pl.case, pl.units
    k = int(0.05 * len(plan.stage_dt_s))
    x, t = case.cartesian_x0(), plan.epoch_s
    for j in range(k):
        x = propagate(case, x, plan.thrust_n[j], plan.stage_dt_s[j])
        t += plan.stage_dt_s[j]
    node = u.cartesian_si(propagate(case, x, plan.thrust_n[k], plan.stage_dt_s[k]))
    assert np.linalg.norm(node[:3] - plan.states_si[k + 1, :3]) < 0.1
    x = u.cartesian_si(propagate(case, x, plan.thrust_n[k], 0.4 * plan.stage_dt_s[k]))
    t += 0.4 * plan.stage_dt_s[k]
    rng = np.random.default_rng(3)
    dr, dv = (d / np.linalg.norm(d) for d in rng.normal(size=(2, 3)))
    out = pl.replan(x[:3] + 1000.0 * dr, x[3:6] + 1.0 * dv, x[6], t)
    assert out.ok and out.warm_start and out.level == "OK", out.reason
    new = pl.plan
    assert len(new.stage_dt_s) == len(plan.stage_dt_s) - k
    assert new.end_s == pytest.approx(plan.end_s, abs=1e-3)
    np.testing.assert_allclose(new.states_si[0, :3], x[:3] + 1000.0 * dr, atol=1e-6)
    sol = new.solution
    assert sol.converged and sol.max_violation <= 1e-10
    assert sol.elements[-1, 0] == pytest.approx(6788.0, abs=1e-6)
    assert sol.elements[-1, 2] == pytest.approx(51.0, abs=1e-8)


def test_an_estimate_off_any_closed_orbit_is_refused_for_an_earth_scenario(earth_planner):
    checks = earth_planner.checks
    with pytest.raises(InputRejected, match="inside the Earth"):
        checks.check_estimate([6000e3, 0, 0], [0, 7000.0, 0], T0_S)
    with pytest.raises(InputRejected, match="not a closed orbit"):
        checks.check_estimate([7000e3, 0, 0], [0, 11_000.0, 0], T0_S)
