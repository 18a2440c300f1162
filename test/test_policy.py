"""Polynomial feedback laws (issue 47, ``daddy_core/policy.py``) on the issue's planar orbit
raise: the law of the first stage against the issue's Taylor coefficients of the re-optimised
control, and against re-solves of perturbed problems in this test (its error falls by at least
5x per order); an LQ problem's law against its closed form; refusals named."""
from dataclasses import replace

import numpy as np
import pytest

from daddy_core.da import functions as dm
from daddy_core.dynamics import Dynamics
from daddy_core.errors import DaddyError
from daddy_core.policy import Policy, feedback_policy, tracking_policy, tracking_problem
from daddy_core.problem import Problem, flow_step
from daddy_core.solver import Solution, SolverOptions, solve

R1 = 1.5
TIGHT = SolverOptions(kkt=dict(tol=1e-10))


def _rhs(t, x, u):
    k = (x[0] * x[0] + x[1] * x[1]) ** -1.5
    return dm.stack([x[2], x[3], -x[0] * k + u[0], -x[1] * k + u[1]])


def _on_circle(x, xt):
    return dm.stack([dm.sqrt(x[0] * x[0] + x[1] * x[1]) - R1, x[0] * x[2] + x[1] * x[3],
                     x[0] * x[3] - x[1] * x[2] - np.sqrt(R1)])


def _orbit_raise(x0):
    """The issue's problem: mu = 1, 40 stages of 3 pi / 40, RK4 with 4 sub-steps, L = |u|^2 dt,
    arrival anywhere on the circular orbit of radius 1.5, no thrust bound."""
    return Problem(name="orbit_raise", nu=2, x0=np.asarray(x0, float), x_target=np.zeros(4),
                   stage_dt=np.full(40, 3 * np.pi / 40),
                   step=flow_step(Dynamics(_rhs), "rk4", rk4_steps=4),
                   stage_cost=lambda x, u, dt, hom: (u[0] * u[0] + u[1] * u[1]) * dt,
                   terminal_cost=lambda x, xt: x[0] * 0.0, g_teq=_on_circle)


@pytest.fixture(scope="module")
def raise_policy():
    problem = _orbit_raise([1.0, 0.0, 0.0, 1.0])
    sol = solve(problem, np.full((40, 2), 1e-3), options=TIGHT)
    return problem, sol, feedback_policy(problem, sol, order=3)


def _coefficients(law, var, order):
    """The law's Taylor coefficients along one state variable, degrees 1..order: (order, nu)."""
    e = law.T.exponents
    return np.array([law.c[np.flatnonzero((e[:, var] == d) & (e.sum(axis=1) == d))[0]]
                     for d in range(1, order + 1)])


def test_the_first_stages_law_has_the_issues_taylor_coefficients(raise_policy):
    problem, sol, policy = raise_policy
    assert sol.cost == pytest.approx(0.0037561617, abs=1e-10)
    assert policy.offset < 1e-8          # the solution is the laws' stationary point
    np.testing.assert_allclose(sol.U[0], [-0.00345770, 0.01781139], atol=1e-8)
    c = _coefficients(policy.law(0), 0, 3)          # along the radial position
    np.testing.assert_allclose(c[0], [0.0028946, -0.0745348], rtol=0, atol=1e-6)
    np.testing.assert_allclose(c[1], [0.42081, 0.04117], rtol=1e-3)
    np.testing.assert_allclose(c[2], [-0.28, -11.67], rtol=2e-2)
    c = _coefficients(policy.law(0), 3, 3)          # along the tangential velocity
    np.testing.assert_allclose(c[1, 0], 0.7457, rtol=1e-3)
    np.testing.assert_allclose(c[2], [2.0, -33.4], rtol=2e-2)
    # a law is the truncated Taylor series: the order-2 build is the order-3 law truncated
    low = feedback_policy(problem, sol, order=2)
    np.testing.assert_allclose(low.coefficients, policy.truncated(2).coefficients,
                               rtol=1e-6, atol=1e-10)   # round-off through the inversions


@pytest.mark.parametrize("var", [0, 3])
def test_the_laws_error_against_re_solves_falls_with_each_order(raise_policy, var):
    """Perturbed by +-0.003 in the radial position or the tangential velocity, re-solved from
    the nominal solution: the first control the order-1, -2, -3 laws give, against the
    re-solve's, at least 5x closer per order."""
    problem, sol, policy = raise_policy
    errors = np.zeros(3)
    for delta in (0.003, -0.003):
        x0 = problem.x0.copy()
        x0[var] += delta
        again = solve(_orbit_raise(x0), sol, options=TIGHT)
        assert again.max_violation < 1e-10
        for i, order in enumerate((1, 2, 3)):
            u = policy.truncated(order).control(0, x0)
            errors[i] = max(errors[i], np.abs(u - again.U[0]).max())
    assert errors[0] < 2e-5
    assert errors[0] >= 5 * errors[1] and errors[1] >= 5 * errors[2]


def test_an_lq_law_is_its_closed_form_and_is_exact_at_any_distance():
    """x+ = A x + B u, J = sum u^2, x_N fixed: the optimal first control is linear in x0,
    u_0(x0) = -B^T (A^T)^(N-1) W^-1 (A^N x0 - x_t) / 1 with W the reachability Gramian (from
    numpy); the order-1 law equals it, and its higher terms vanish."""
    N = 6
    A = np.array([[1.0, 0.5], [0.0, 1.0]])
    B = np.array([[0.125], [0.5]])
    target = np.array([3.0, -1.0])

    def step(x, u, dt):
        return dm.stack([x[0] + 0.5 * x[1] + 0.125 * u[0], x[1] + 0.5 * u[0]])
    problem = Problem(name="lq", nu=1, x0=np.array([1.0, 0.0]), x_target=target,
                      stage_dt=np.full(N, 0.5), step=step,
                      stage_cost=lambda x, u, dt, hom: u[0] * u[0],
                      terminal_cost=lambda x, xt: 0.0 * x[0],
                      g_teq=lambda x, xt: dm.stack([x[0] - xt[0], x[1] - xt[1]]))
    sol = solve(problem, np.zeros((N, 1)), options=TIGHT)
    policy = feedback_policy(problem, sol, order=3)
    Ak = [np.linalg.matrix_power(A, j) for j in range(N + 1)]
    W = sum(Ak[N - 1 - j] @ B @ B.T @ Ak[N - 1 - j].T for j in range(N))
    x0 = np.array([1.7, -0.4])
    exact = (B.T @ Ak[N - 1].T @ np.linalg.solve(W, target - Ak[N] @ x0))
    np.testing.assert_allclose(policy.control(0, x0), exact, rtol=1e-9, atol=1e-10)
    assert np.abs(policy.coefficients[0, 1 + 2:]).max() < 1e-9     # no terms above degree 1
    # the last stage alone cannot reach both target rows: no law there
    assert not policy.has_law[-1] and policy.has_law[:-1].all()
    with pytest.raises(DaddyError, match="no feedback law"):
        policy.control(N - 1, x0)


def test_a_policy_round_trips_through_its_record(raise_policy):
    _, _, policy = raise_policy
    back = Policy.from_dict(policy.to_dict())
    x = np.array([1.001, 0.0, 0.0, 0.999])
    np.testing.assert_array_equal(back.control(0, x), policy.control(0, x))
    assert list(back.has_law) == list(policy.has_law)


def test_active_bounds_are_held_in_the_laws():
    """Rest to rest over 10 in 5 s with |u| <= 2: the unbounded optimum's peak 2.4 saturates
    the first and last stages. Perturbed by 0.01 in position, the laws (the bound held on the
    saturated stages) give every stage's re-solved control, flown stage by stage from the
    perturbed start, to 1e-6 (the active set unchanged; the laws are affine here)."""
    def step(x, u, dt):
        return dm.stack([x[0] + x[1] * dt + 0.5 * u[0] * dt * dt, x[1] + u[0] * dt])
    problem = Problem(name="bounded", nu=1, x0=np.array([0.0, 0.0]),
                      x_target=np.array([10.0, 0.0]), stage_dt=np.full(10, 0.5), step=step,
                      stage_cost=lambda x, u, dt, hom: u[0] * u[0] * dt,
                      terminal_cost=lambda x, xt: 0.0 * x[0],
                      g_teq=lambda x, xt: dm.stack([x[0] - xt[0], x[1] - xt[1]]),
                      g_ineq=lambda x, u, dt: dm.stack([u[0] * u[0] - 4.0]),
                      labels={"g_ineq": ("thrust bound",)})
    sol = solve(problem, np.zeros((10, 1)), options=TIGHT)
    assert sol.converged and np.abs(sol.U[0, 0]) == pytest.approx(2.0, abs=1e-8)
    policy = feedback_policy(problem, sol, order=2)
    x0 = problem.x0 + np.array([0.01, 0.0])
    again = solve(problem.with_x0(x0), sol, options=TIGHT)
    assert again.converged
    x = x0
    for k in range(problem.N):
        u = policy.control(k, x) if policy.has_law[k] else again.U[k]
        np.testing.assert_allclose(u, again.U[k], atol=1e-6)
        x = np.asarray(step(x, u, 0.5))
    np.testing.assert_allclose(x, problem.x_target, atol=1e-6)
    with pytest.raises(DaddyError, match="order"):
        feedback_policy(problem, sol, order=7)


def test_solve_returns_the_policy_it_is_asked_for_and_its_json_keeps_it(tmp_path):
    problem = _orbit_raise([1.0, 0.0, 0.0, 1.0])
    sol = solve(problem, np.full((40, 2), 1e-3),
                options=SolverOptions(kkt=dict(tol=1e-10), policy=dict(order=2)))
    assert sol.policy is not None and sol.policy.order == 2 and sol.policy_error is None
    path = tmp_path / "raise.json"
    sol.to_json(path)
    back = type(sol).from_json(path)
    x = np.array([1.002, 0.0, 0.001, 1.0])
    np.testing.assert_array_equal(back.policy.control(3, x), sol.policy.control(3, x))
    plain = solve(problem, sol)
    assert plain.policy is None and plain.policy_error is None
    with pytest.raises(DaddyError, match="policy.order"):
        SolverOptions(policy=dict(order=9))


def test_daddy_solve_builds_the_laws_it_is_asked_for(tmp_path, capsys):
    """Earth-Mars energy-optimal: laws on every stage the terminal rows leave one to (the
    thrust bound inactive); fuel-optimal: the exact fuel form's laws (``test_fuel_laws...``)."""
    from daddy_core.cli import main
    path = tmp_path / "em.json"
    assert main(["solve", "earth_mars", "--energy", "--policy", "1", "--quiet",
                 "--json", str(path)]) == 0
    assert "feedback laws of order 1: 38 of 40 stages" in capsys.readouterr().out
    sol = Solution.from_json(path)
    assert sol.policy.order == 1 and sol.policy.has_law.sum() == 38
    assert main(["solve", "earth_mars", "--fuel", "--policy", "1", "--quiet"]) == 0
    assert "feedback laws of order 1:" in capsys.readouterr().out
    assert main(["solve", "earth_mars", "--policy", "9", "--quiet"]) == 2


def test_fuel_laws_of_a_bang_bang_optimum_correct_the_plan_after_a_dispersion():
    """Earth-Mars fuel-optimal (bang-bang, one intermediate-throttle stage): the exact fuel
    form's order-1 laws -- throttle bounds held, coasting directions held -- flown at the
    re-solved states of a start 1e-3 off in each position and velocity component, give the
    re-solve's thrust at least 4x closer than the plan's (measured 6.8-125x) on every stage
    with a law."""
    from daddy_core.catalogue import load_case, problem_from_case
    from daddy_core.solver import case_options
    case = load_case("earth_mars")
    problem = problem_from_case(case)
    opts = case_options(case, True, policy=dict(order=1))
    sol = solve(problem, case.cold_guess(problem.N), fuel_optimal=True, options=opts)
    policy = sol.policy
    assert policy is not None and policy.frame is not None and policy.has_law[:30].all()
    laws = np.flatnonzero(policy.has_law)
    for var in range(6):
        for delta in (1e-3, -1e-3):
            x0 = problem.x0.copy()
            x0[var] += delta
            again = solve(problem.with_x0(x0), sol, fuel_optimal=True,
                          options=case_options(case, True))
            assert again.converged
            law = max(np.abs(policy.thrust(k, again.X[k]) - again.U[k]).max() for k in laws)
            plan = max(np.abs(sol.U[k] - again.U[k]).max() for k in laws)
            assert law * 4 < plan, (var, delta, law, plan)


def test_a_fuel_solve_without_the_exact_end_game_gets_the_laws_of_the_problem_it_solved():
    """Earth-Mars fuel-optimal without polishing ends at the pseudo-Huber step (no exact fuel
    form ran): its laws are that problem's (controls = thrust), not the exact form's."""
    from daddy_core.catalogue import load_case, problem_from_case
    from daddy_core.solver import case_options
    case = load_case("earth_mars")
    problem = problem_from_case(case)
    sol = solve(problem, case.cold_guess(problem.N), fuel_optimal=True, polish=False,
                options=case_options(case, True, policy=dict(order=1)))
    assert not sol.exact_fuel
    assert sol.policy is not None and sol.policy.frame is None


@pytest.fixture(scope="module")
def raise_plan():
    """A plan of the orbit raise that meets its terminal rows but is not its optimum: the
    optimum of another cost, (u_r^2 + 9 u_t^2) dt (a warm re-plan stopped early is such a
    plan)."""
    problem = _orbit_raise([1.0, 0.0, 0.0, 1.0])
    other = replace(problem, stage_cost=lambda x, u, dt, hom: (u[0] * u[0] + 9 * u[1] * u[1]) * dt)
    sol = solve(other, np.full((40, 2), 1e-3), options=TIGHT)
    assert sol.max_violation < 1e-12
    return problem, sol


@pytest.mark.parametrize("var", [0, 3])
def test_tracking_laws_are_the_least_correction_of_any_feasible_plan(raise_plan, var):
    """The tracking laws of a plan that is not the problem's optimum have no constant term
    (feedback_policy's laws would jump towards the optimum), and their first control is the
    re-solved least-correction problem's to an error falling >= 5x per order."""
    problem, sol = raise_plan
    policy = tracking_policy(problem, sol.X, sol.U, order=3)
    assert policy.offset < 1e-10
    errors = np.zeros(3)
    for delta in (0.003, -0.003):
        x0 = problem.x0.copy()
        x0[var] += delta
        again = solve(tracking_problem(_orbit_raise(x0), sol.U), np.zeros((40, 2)), options=TIGHT)
        assert again.max_violation < 1e-10
        for i, order in enumerate((1, 2, 3)):
            u = policy.truncated(order).control(0, x0)
            errors[i] = max(errors[i], np.abs(u - (sol.U[0] + again.U[0])).max())
    assert errors[0] < 2e-5
    assert errors[0] >= 5 * errors[1] and errors[1] >= 5 * errors[2]


def test_the_tracking_problem_steps_one_state_as_the_plan_does(raise_plan):
    """A float call with one state and one correction (as a backward propagation makes) is
    the plan's stage flown with the corrected control, for every stage (it was an (nu, nu)
    control: the one-stage reshape meant for batches)."""
    problem, sol = raise_plan
    tracking = tracking_problem(problem, sol.U)
    for k in (0, 17, problem.N - 1):
        x, t0, dt = sol.X[k], problem.stage_t0[k], problem.stage_dt[k]
        np.testing.assert_allclose(tracking.step(x, np.zeros(2), dt, t0),
                                   problem.step(x, sol.U[k], dt, t0), rtol=0, atol=1e-15)


def test_flying_tracking_laws_stage_by_stage_meets_the_terminal_rows(raise_plan):
    """Flown in closed loop from a perturbed start (the last stage, which cannot move three
    terminal rows alone, has no law and flies the plan), the order-2 laws end >= 50x nearer
    the target orbit than the plan flown open loop."""
    problem, sol = raise_plan
    policy = tracking_policy(problem, sol.X, sol.U, order=2)
    assert policy.has_law[:-1].all() and not policy.has_law[-1]
    for delta in (0.003, -0.003):
        x = problem.x0 + np.array([delta, 0.0, 0.0, 0.0])
        open_loop = x.copy()
        for k in range(problem.N):
            u = policy.control(k, x) if policy.has_law[k] else sol.U[k]
            x = problem.step.flow(x, u, problem.stage_dt[k], problem.stage_t0[k])
            open_loop = problem.step.flow(open_loop, sol.U[k], problem.stage_dt[k],
                                          problem.stage_t0[k])
        miss = np.abs(_on_circle(x, None)).max()
        assert miss * 50 < np.abs(_on_circle(open_loop, None)).max()


def test_the_matrix_sweep_of_order_1_laws_is_the_da_sweep(raise_policy, raise_plan, monkeypatch):
    """Order-1 laws without held rows are swept on matrices (``policy._sweep_quadratic``): the
    same laws as the DA sweep, optimal and tracking."""
    import daddy_core.policy as policy_module
    problem, sol, _ = raise_policy
    _, plan = raise_plan
    fast = [feedback_policy(problem, sol, 1), tracking_policy(problem, plan.X, plan.U, 1)]
    monkeypatch.setattr(policy_module, "_sweep_quadratic", lambda *args: None)
    slow = [feedback_policy(problem, sol, 1), tracking_policy(problem, plan.X, plan.U, 1)]
    for a, b in zip(fast, slow):
        np.testing.assert_array_equal(a.has_law, b.has_law)
        np.testing.assert_allclose(a.coefficients, b.coefficients, rtol=1e-9, atol=1e-12)
