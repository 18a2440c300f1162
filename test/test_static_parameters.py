"""Static parameters and free time of flight (issue 46, first part): the issue's independent
optima (free-ToF double integrator, minimum time), a static parameter of an LQ problem against
its KKT system solved directly, a continuous right-hand side with a free time, and bad input
named by field."""
import math

import numpy as np
import pytest

from daddy_core.da import functions as dm
from daddy_core.errors import DaddyError
from daddy_core.problem import Problem, flow_step
from daddy_core.solver import Solution, SolverOptions, solve
from daddy_core.static_parameters import StaticParameter, with_free_time, with_parameters

TIGHT = SolverOptions(kkt=dict(tol=1e-9))   # the issue's 1e-6 on T needs the KKT end game


def _zoh(x, u, dt):
    """Rest-to-rest double integrator, one axis, zero-order hold."""
    return dm.stack([x[0] + x[1] * dt + 0.5 * u[0] * dt * dt, x[1] + u[0] * dt])


def _rest_to_rest(distance, N, step=_zoh, stage_cost=None, g_ineq=None):
    return Problem(name="rest_to_rest", x0=np.zeros(2), x_target=np.array([distance, 0.0]),
                   stage_dt=np.full(N, 0.5), step=step,
                   stage_cost=stage_cost or (lambda x, u, dt, hom=(0.0, 1.0): u[0] * u[0] * dt),
                   terminal_cost=lambda x, xt: 0.0 * x[0],
                   g_teq=lambda x, xt: dm.stack([x[0] - xt[0], x[1] - xt[1]]), g_ineq=g_ineq,
                   nu=1)


def test_free_time_double_integrator_reaches_the_issues_optimum():
    """D = 10, N = 20, J = sum u^2 dt + T: T* = 7.7508155, J* = 10.3344207 (= 4 T* / 3), its
    energy part 2.5836052."""
    sol = solve(with_free_time(_rest_to_rest(10.0, 20), 1.0, 50.0, time_cost=1.0),
                np.zeros((20, 1)), fuel_optimal=False, options=TIGHT)
    assert sol.converged
    T = sol.parameters["tof"]
    assert T == pytest.approx(7.7508155, abs=1e-6)
    assert sol.cost == pytest.approx(10.3344207, abs=1e-6)
    assert sol.cost - T == pytest.approx(2.5836052, abs=1e-6)
    np.testing.assert_allclose(sol.X[-1, :2], [10.0, 0.0], atol=1e-8)
    assert Solution.from_json(sol.to_json()).parameters == sol.parameters   # in the JSON too


def test_free_time_on_a_continuous_right_hand_side():
    """The same optimum with the dynamics as a right-hand side integrated by RK78: the rates
    are scaled by T / T_ref over the stage grid."""
    def rhs(t, x, u):
        return dm.stack([x[1], u[0] + 0.0 * x[0]])
    p = _rest_to_rest(10.0, 20, step=flow_step(rhs))
    sol = solve(with_free_time(p, 1.0, 50.0, time_cost=1.0), np.zeros((20, 1)),
                fuel_optimal=False, options=TIGHT)
    assert sol.converged
    assert sol.parameters["tof"] == pytest.approx(7.7508155, abs=1e-6)


@pytest.mark.filterwarnings("error::RuntimeWarning")   # trial steps overflow: not the user's
def test_minimum_time_is_bang_bang_with_the_switch_halfway():
    """D = 1, |u| <= 1, N = 20, J = T: T* = 2, u = +1 then -1, switching at N / 2.

    The solve reaches T* to 1e-8, but the run does not report converged. At this vertex 41
    constraints are active on 40 variables, and the optimality measure's banded multipliers
    leave about 5e-3 (a dense bounded least squares finds 3e-15: docs/parameters.md)."""
    def bound(x, u, dt):
        return dm.stack([u[0] - 1.0, -u[0] - 1.0])
    p = _rest_to_rest(1.0, 20, stage_cost=lambda x, u, dt, hom=(0.0, 1.0): 0.0 * u[0],
                      g_ineq=bound)
    sol = solve(with_free_time(p, 0.1, 20.0, guess=4.0, time_cost=1.0), np.zeros((20, 1)),
                fuel_optimal=False)
    assert sol.parameters["tof"] == pytest.approx(2.0, abs=1e-8)
    np.testing.assert_allclose(sol.U[:10, 0], 1.0, atol=1e-8)
    np.testing.assert_allclose(sol.U[10:, 0], -1.0, atol=1e-8)
    assert sol.max_violation < 1e-8


def test_a_static_parameter_of_an_lq_problem_is_its_kkt_solution():
    """x+ = A x + B (u + a), J = sum u^2 + 3 a^2, x_N fixed: a constant acceleration a chosen
    with the controls. The optimum from the KKT system of the quadratic program, solved with
    numpy, against the solver's."""
    N, dt, kappa = 8, 0.5, 3.0
    A = np.array([[1.0, dt], [0.0, 1.0]])
    B = np.array([0.5 * dt * dt, dt])
    target = np.array([4.0, -1.0])

    def step(xw, u, dt_):
        a = xw[2]
        return dm.stack([xw[0] + xw[1] * dt_ + 0.5 * (u[0] + a) * dt_ * dt_,
                         xw[1] + (u[0] + a) * dt_])

    p = Problem(name="lq_parameter", x0=np.zeros(2), x_target=target, stage_dt=np.full(N, dt),
                step=step, stage_cost=lambda xw, u, dt_, hom=(0.0, 1.0): u[0] * u[0],
                terminal_cost=lambda xw, xt: kappa * xw[2] * xw[2],
                g_teq=lambda xw, xt: dm.stack([xw[0] - xt[0], xw[1] - xt[1]]), nu=1)
    sol = solve(with_parameters(p, [StaticParameter("a", -10.0, 10.0, 0.0)]),
                np.zeros((N, 1)), fuel_optimal=False, options=TIGHT)
    assert sol.converged
    # the QP in z = [u_0..u_{N-1}, a]: x_N = sum_k A^(N-1-k) B (u_k + a) = M z
    cols = [np.linalg.matrix_power(A, N - 1 - k) @ B for k in range(N)]
    M = np.column_stack(cols + [np.sum(cols, axis=0)])
    H = np.diag([2.0] * N + [2.0 * kappa])
    K = np.block([[H, M.T], [M, np.zeros((2, 2))]])
    z = np.linalg.solve(K, np.concatenate([np.zeros(N + 1), target]))[:N + 1]
    assert sol.parameters["a"] == pytest.approx(z[N], abs=1e-8)
    np.testing.assert_allclose(sol.U[:, 0], z[:N], atol=1e-8)


@pytest.mark.parametrize("make, field", [
    (lambda p: with_parameters(p, [StaticParameter("a", -math.inf, 1.0)]), "'a'.*bounds"),
    (lambda p: with_parameters(p, [StaticParameter("a", 1.0, 1.0)]), "'a'.*lower < upper"),
    (lambda p: with_parameters(p, [StaticParameter("a", 0.0, 1.0, guess=2.0)]), "'a'.*guess"),
    (lambda p: with_parameters(p, [StaticParameter("a", 0, 1), StaticParameter("a", 0, 1)]),
     "distinct"),
    (lambda p: with_parameters(p, []), "non-empty"),
    (lambda p: with_free_time(p, 0.0, 5.0), "'tof'.*lower must be > 0"),
    (lambda p: with_free_time(p, 3.0, 2.0), "'tof'.*upper"),
    (lambda p: with_free_time(p, 1.0, 5.0, guess=9.0), "'tof'.*guess"),
    (lambda p: with_free_time(p, 1.0, 5.0, time_cost=math.nan), "time_cost"),
])
def test_bad_parameters_are_refused_by_name(make, field):
    with pytest.raises(DaddyError, match=field):
        make(_rest_to_rest(1.0, 4))


def test_a_non_autonomous_flow_keeps_its_stage_starts_through_the_parameters():
    """dx/dt = cos(t) + u from t_start = 1.3 (the rhs reads t): with a static parameter the
    stages start where the problem's do, and with a free time at its reference the flow is the
    problem's own; stretched by T / T_ref, the grid t_start + (t - t_start) T / T_ref is flown
    (closed form: x(T) = sin(t_start + T) - sin(t_start) + u T)."""
    from daddy_core.dynamics.rhs import Dynamics
    N, t_start = 4, 1.3
    rhs = Dynamics(lambda t, x, u: dm.stack([dm.cos(t) + u[0]]))
    p = Problem(name="clock", x0=np.zeros(1), x_target=np.zeros(1), stage_dt=np.full(N, 0.5),
                step=flow_step(rhs, "rk78", 1e-13), t_start=t_start,
                stage_cost=lambda x, u, dt, hom=(0.0, 1.0): u[0] * u[0] * dt,
                terminal_cost=lambda x, xt: x[0] * x[0], nu=1)
    U = np.full((N, 1), 0.2)
    exact = lambda T: math.sin(t_start + T) - math.sin(t_start) + 0.2 * T   # noqa: E731
    assert p.rollout(U)[-1, 0] == pytest.approx(exact(2.0), abs=1e-10)
    q = with_parameters(p, [StaticParameter("a", -1.0, 1.0, 0.0)])
    assert q.rollout(q.parameters.padded(U))[-1, 0] == pytest.approx(exact(2.0), abs=1e-10)
    for T in (2.0, 2.6):
        f = with_free_time(p, 1.0, 4.0, guess=T)
        assert f.rollout(f.parameters.padded(U))[-1, 0] == pytest.approx(exact(T), abs=1e-10)
