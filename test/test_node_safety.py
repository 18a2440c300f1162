"""The guidance session's safety against bad stamps (issue 49, item 1), ROS-free: a glitch
stamped far from the flight is rejected without touching the flight's clock, and a new clock
is taken only from consistent estimates in a row (the node's graph: test_ros_node)."""
import threading
import time

import numpy as np
import pytest

from daddy_ros.checks import InputRejected, StampGuard
from daddy_ros.config import TriggerConfig
from daddy_ros.conversions import OdometryState
from daddy_ros.plan import Code, Level, ReplanOutcome
from daddy_ros.self_trigger import ReplanTrigger
from daddy_ros.session import GuidanceSession

from test_feedback_laws import _Outputs, _planner

DAY_S = 86400.0
# stage boundaries re-plan, nothing else: the glitch must not silence them
STAGES_ONLY = TriggerConfig(feedback_order=0, trigger_position_m=0.0,
                            trigger_velocity_m_s=0.0, arrival_stages=0)


def _estimate(plan, k: int, dt: float):
    """The plan's state at stage k's start (stamped dt after it) as an estimate."""
    x = plan.states_si[k]
    t = float(plan.start_times_s[k]) + dt
    return OdometryState(x[:3], x[3:6], t, "", None, None), t, float(x[6])


def _send_off_plan(session, plan, offset_m: float):
    """Mass, then state, of an estimate ``offset_m`` (along x) from the plan's stage-3 start:
    (the estimate, its stamp)."""
    est, t, m = _estimate(plan, 3, 0.0)
    est = OdometryState(est.pos_m + np.array([offset_m, 0.0, 0.0]), est.vel_m_s, t, "", None,
                        None)
    session.on_mass(m, t)
    session.on_state(est, t)
    return est, t


def _session(config=STAGES_ONLY, **planner_config):
    from dataclasses import replace
    planner = _planner()
    planner.config = replace(planner.config, **planner_config)
    out = _Outputs()
    session = GuidanceSession(planner, ReplanTrigger.for_planner(planner, config), "", "", out,
                              lambda: True, None)
    return planner, session, out


def _wait(predicate, timeout_s=180.0):
    """Poll ``predicate`` until true or ``timeout_s`` (default: beyond a cold re-plan and its
    warm fallback, each up to the planner's 60 s budget on a loaded machine)."""
    end = time.monotonic() + timeout_s
    while not predicate() and time.monotonic() < end:
        time.sleep(0.02)
    return predicate()


def test_a_glitch_stamped_100_days_ahead_is_rejected_and_stage_re_plans_go_on():
    """One estimate stamped +100 days between normal ones: rejected with STAMP_JUMP naming
    state_estimate.header.stamp, no thrust command for it; the next stage boundary still
    re-plans and its thrust command is published after the re-plan."""
    planner, session, out = _session()
    plan = planner.plan
    try:
        est, t, m = _estimate(plan, 3, -60.0)
        session.on_mass(m, t)
        session.on_state(est, t)                      # the prediction starts
        glitch = OdometryState(est.pos_m, est.vel_m_s, t + 100 * DAY_S, "", None, None)
        with pytest.raises(InputRejected, match=r"state_estimate\.header\.stamp") as exc:
            session.on_state(glitch, t + 100 * DAY_S)
        assert exc.value.code is Code.STAMP_JUMP
        assert all(s != pytest.approx(t + 100 * DAY_S) for s, _ in out.thrust)
        est, t, m = _estimate(plan, 4, 0.0)           # the next boundary
        session.on_mass(m, t)
        session.on_state(est, t)
        assert _wait(lambda: session.replans == 1 and any(
            s == pytest.approx(t) for s, _ in out.thrust))
    finally:
        session.stop()


def test_consistent_estimates_in_a_row_set_a_new_clock_and_the_node_re_plans():
    """A clock that really moved (1 day ahead, 3 estimates a minute apart, the default
    confirmations; the bound 2 stages, ~6 h, so that the jump stays inside the plan): the
    first two are rejected, the third sets the new clock with a WARN CLOCK_CHANGED and a
    re-plan from it, after which its thrust command is published."""
    planner, session, out = _session(max_stamp_jump_stages=2.0)
    plan = planner.plan
    try:
        est, t, m = _estimate(plan, 3, -60.0)
        session.on_mass(m, t)
        session.on_state(est, t)
        shifted = [t + DAY_S + 60.0 * i for i in range(3)]
        for s in shifted[:2]:
            with pytest.raises(InputRejected):
                session.on_state(OdometryState(est.pos_m, est.vel_m_s, s, "", None, None), s)
        session.on_mass(m, shifted[2])
        session.on_state(OdometryState(est.pos_m, est.vel_m_s, shifted[2], "", None, None),
                         shifted[2])
        assert [e for e in out.events if e[1] is Code.CLOCK_CHANGED][0][0] is Level.WARN
        assert _wait(lambda: session.replans == 1 and any(
            s == pytest.approx(shifted[2]) for s, _ in out.thrust))
        assert session.stamps.newest == shifted[2]
    finally:
        session.stop()


def test_the_stamp_guard_without_a_plan_or_with_the_test_off_accepts_anything():
    class _Plan:
        stage_dt_s = np.array([100.0, 150.0])
    guard = StampGuard(2.0, 2)
    assert guard.bound_s(_Plan()) == 300.0 and guard.bound_s(None) == np.inf
    assert StampGuard(0.0, 2).bound_s(_Plan()) == np.inf
    assert not guard.accept(1000.0, "state_estimate", _Plan())
    assert not guard.accept(900.0, "state_estimate", _Plan())   # older, within the bound
    with pytest.raises(InputRejected):
        guard.accept(5000.0, "state_estimate", _Plan())
    with pytest.raises(InputRejected):                       # not consistent with 5000: restart
        guard.accept(9000.0, "state_estimate", _Plan())
    assert guard.accept(9100.0, "state_estimate", _Plan())   # two in a row agree
    assert guard.newest == 9100.0
    with pytest.raises(InputRejected, match="-9000"):          # as far behind
        guard.accept(100.0, "state_estimate", _Plan())
    assert guard.newest == 9100.0


def test_an_estimate_the_plan_does_not_fit_gets_no_thrust_from_it_and_a_re_plan():
    """An estimate 20,000 km from the plan (beyond fit_position_m = 10,000 km; the restarted node
    adopting its departure nominal days into the flight is the same fault, farther): ERROR
    PLAN_DOES_NOT_FIT naming the deviation, no thrust command from that plan; the re-plan
    from the estimate then answers it from a plan that fits it."""
    planner, session, out = _session()
    plan = planner.plan
    try:
        est, t = _send_off_plan(session, plan, 20000e3)
        (level, _, values), = [e for e in out.events if e[1] is Code.PLAN_DOES_NOT_FIT]
        assert level is Level.ERROR
        assert float(values["deviation_position_m"]) == pytest.approx(20000e3, rel=1e-6)
        assert not [s for s, _ in out.thrust if s == pytest.approx(t)]   # nothing yet
        assert _wait(lambda: any(s == pytest.approx(t) for s, _ in out.thrust))
        (_, thrust), = [(s, u) for s, u in out.thrust if s == pytest.approx(t)]
        new = planner.plan
        assert new is not plan and session.fit.check(new, t, est.pos_m, est.vel_m_s).fits
        np.testing.assert_allclose(thrust, new.command_at(t, est.pos_m, est.vel_m_s))
    finally:
        session.stop()


def test_a_failed_re_plan_leaves_zero_thrust_not_the_plan_that_does_not_fit():
    """The plan does not fit and the re-plan from the estimate stores nothing (its solve
    raises): the withheld command is zero thrust, with an ERROR saying so."""
    planner, session, out = _session()
    plan = planner.plan

    def broken(*args, **kwargs):
        raise RuntimeError("injected solver fault")
    planner.replan = broken
    try:
        est, t, m = _estimate(plan, 3, 0.0)
        est = OdometryState(est.pos_m, est.vel_m_s + np.array([0.0, 200.0, 0.0]), t, "", None,
                            None)
        session.on_mass(m, t)
        session.on_state(est, t)
        assert _wait(lambda: any(s == pytest.approx(t) for s, _ in out.thrust))
        (_, thrust), = [(s, u) for s, u in out.thrust if s == pytest.approx(t)]
        assert np.all(thrust == 0.0) and planner.plan is plan
        # one at the estimate (thrust withheld), one at the release (zero thrust commanded)
        assert [e[0] for e in out.events if e[1] is Code.PLAN_DOES_NOT_FIT] == [Level.ERROR] * 2
    finally:
        session.stop()


@pytest.mark.parametrize("state_first", [True, False])
def test_the_first_estimate_gets_its_command_whichever_of_state_and_mass_comes_first(
        state_first):
    """A node starting from its nominal plan file: the first state estimate gets its thrust
    command whether its mass came before or after it (the nominal is adopted at the first
    complete estimate)."""
    from daddy_ros.config import bundled_plan
    from daddy_ros.planner import GuidancePlanner

    from test_feedback_laws import CASE
    planner = GuidancePlanner(CASE, time_budget_s=60.0)
    out = _Outputs()
    session = GuidanceSession(planner, ReplanTrigger.for_planner(planner, STAGES_ONLY),
                              str(bundled_plan(CASE)), "", out, lambda: True, None)
    from daddy_sim.sim import T0_S, Errors, TruthSim
    pos, vel, mass = TruthSim(CASE, Errors(0, 0, 0, 0), t0_s=T0_S).truth_si()
    est = OdometryState(pos, vel, T0_S, "", None, None)
    try:
        if state_first:
            session.on_state(est, T0_S)
            assert not out.thrust
            session.on_mass(mass, T0_S)
        else:
            session.on_mass(mass, T0_S)
            session.on_state(est, T0_S)
        assert _wait(lambda: len(out.thrust) == 1, 10.0)
        (stamp, thrust), = out.thrust
        assert stamp == T0_S and planner.plan is not None
        np.testing.assert_allclose(thrust, planner.plan.command_at(T0_S, pos, vel))
    finally:
        session.stop()


def test_a_restarted_node_does_not_fly_its_departure_nominal_days_into_the_flight():
    """Issue 49's fault: a node restarted without persist_file adopts its nominal plan file at
    the first estimate, day 3 of the flight. That plan (anchored at the estimate's stamp, from
    the departure state) does not fit the day-3 state: no command from it, an ERROR
    PLAN_DOES_NOT_FIT, and the command comes from the re-plan solved from that estimate (or
    is zero)."""
    from daddy_ros.config import bundled_plan
    from daddy_ros.planner import GuidancePlanner

    from test_feedback_laws import CASE
    flown = _planner().plan                        # the flight so far, on its nominal
    k = int(np.searchsorted(flown.start_times_s, flown.start_times_s[0] + 3 * DAY_S))
    est, t, m = _estimate(flown, k, 0.0)
    planner = GuidancePlanner(CASE, time_budget_s=10.0)   # (the re-plan may use all of it)
    out = _Outputs()
    session = GuidanceSession(planner, ReplanTrigger.for_planner(planner, STAGES_ONLY),
                              str(bundled_plan(CASE)), "", out, lambda: True, None)
    try:
        session.on_mass(m, t)
        session.on_state(est, t)
        nominal = [e for e in out.events if e[1] is Code.PLAN_DOES_NOT_FIT]
        assert nominal and float(nominal[0][2]["deviation_position_m"]) > 1e7
        assert _wait(lambda: any(s == t for s, _ in out.thrust), 200.0), out.events
        (_, thrust), = [(s, u) for s, u in out.thrust if s == t]
        plan = planner.plan
        assert (np.all(thrust == 0.0)
                or session.fit.check(plan, t, est.pos_m, est.vel_m_s).fits
                and np.allclose(thrust, plan.command_at(t, est.pos_m, est.vel_m_s)))
    finally:
        session.stop()


def test_a_cold_re_plan_that_fails_falls_back_to_the_warm_start_and_its_plan_fits():
    """The cold re-plan from an estimate the plan does not fit runs out of its budget (a loaded
    machine): the session re-plans warm from the plan in force, and the withheld command comes
    from that plan, which fits the estimate (not zero thrust, not the old plan)."""
    planner, session, out = _session()
    plan = planner.plan
    calls, replan = [], planner.replan

    def cold_starved(*args, cold=False, **kwargs):
        calls.append(cold)
        if not cold:
            return replan(*args, cold=False, **kwargs)
        # the cold solve's failure as the planner reports one (nothing stored)
        return ReplanOutcome(False, Level.ERROR, "time budget exceeded (injected)",
                             kwargs.get("request_id", ""), 60.0, None)
    planner.replan = cold_starved
    try:
        est, t = _send_off_plan(session, plan, 20000e3)
        # (the warm re-plan from 20,000 km may run to its budget: wait beyond it)
        assert _wait(lambda: any(s == pytest.approx(t) for s, _ in out.thrust),
                     planner.time_budget_s + 60.0)
        assert calls[:2] == [True, False]
        (_, thrust), = [(s, u) for s, u in out.thrust if s == pytest.approx(t)]
        new = planner.plan
        assert new is not plan and session.fit.check(new, t, est.pos_m, est.vel_m_s).fits
        np.testing.assert_allclose(thrust, new.command_at(t, est.pos_m, est.vel_m_s))
        assert np.any(thrust != 0.0) or np.all(new.command_at(t, est.pos_m, est.vel_m_s) == 0.0)
    finally:
        session.stop()


def test_no_thrust_is_commanded_from_a_re_plan_before_it_is_published():
    """A re-plan stores its plan before the worker publishes it; an estimate that arrives in
    between (and fits the new plan) is answered only after the plan's publication, from it:
    a client always holds the plan a thrust command comes from (the reliability campaign's
    restart fault judged a command against the path received before it, and once found the
    older plan's)."""
    planner, session, out = _session()
    log = []                                  # ("plan", plan) and ("thrust", stamp), in order
    out.publish_plan = lambda plan, stamp: log.append(("plan", plan))
    thrust = out.publish_thrust
    out.publish_thrust = lambda u, s: (log.append(("thrust", s)), thrust(u, s))
    stored, go = threading.Event(), threading.Event()
    solve = planner.replan

    def held_after_storing(*args, **kwargs):
        r = solve(*args, **kwargs)            # the new plan is in force, not yet published
        stored.set()
        go.wait(60.0)
        return r
    planner.replan = held_after_storing
    plan = planner.plan
    try:
        _, t = _send_off_plan(session, plan, 20000e3)          # a re-plan from it
        assert stored.wait(120.0)
        new = planner.plan
        assert new is not plan
        t2 = t + 0.3 * float(new.stage_dt_s[0])               # mid-stage: no stage re-plan
        x = session.fit.predicted(new, t2)
        session.on_mass(float(x[6]), t2)
        session.on_state(OdometryState(x[:3], x[3:6], t2, "", None, None), t2)
        assert ("thrust", t2) not in log                      # it waits for the publication
        go.set()
        assert _wait(lambda: ("thrust", t2) in log)
        assert log.index(("plan", new)) < log.index(("thrust", t2))
        (u,), = [[u for s, u in out.thrust if s == t2]]
        np.testing.assert_allclose(u, new.command_at(t2, x[:3], x[3:6]))
    finally:
        go.set()
        session.stop()
