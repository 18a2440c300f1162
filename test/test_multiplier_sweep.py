"""The terminal multipliers swept with the controls (``MultiplierUpdate.SWEEP``, HDDP) and the
stage maps' order (``DDPOptions.map_order``): the DA-HDDP paper's LQ test (one iteration at
every map order 2-6) against the LQ's closed form, and a nonlinear problem's optimum unchanged
by either option."""
import sys
from pathlib import Path

import numpy as np
import pytest

from daddy_core.da import functions as dm
from daddy_core.errors import DaddyError
from daddy_core.problem import Problem
from daddy_core.solver import Solution, SolverOptions, solve
from daddy_core.solver.ddp import DDPStats, ddp
from daddy_core.solver.lagrangian import Multipliers
from daddy_core.solver.options import Method, MultiplierUpdate
from daddy_core.solver.sweeps import Stages

sys.path.insert(0, str(Path(__file__).parent))
from test_policy import _orbit_raise  # noqa: E402

N = 10
X0 = np.ones(6)
TARGET = np.array([2.0, 4.0, 1.0, -0.5, 1.5, -2.5])   # the paper's x_t (sec. IV.A)


def _lq() -> Problem:
    """The paper's LQ in one phase: r+ = r + v, v+ = v + u, L = |u|^2, x_N = x_t."""
    def step(x, u, dt):
        return dm.stack([x[i] + x[i + 3] for i in range(3)] + [x[i + 3] + u[i] for i in range(3)])
    return Problem(name="lq", nu=3, x0=X0, x_target=TARGET, stage_dt=np.ones(N), step=step,
                   stage_cost=lambda x, u, dt, hom: u[0] * u[0] + u[1] * u[1] + u[2] * u[2],
                   terminal_cost=lambda x, xt: 0.0 * x[0],
                   g_teq=lambda x, xt: dm.stack([x[i] - xt[i] for i in range(6)]))


def _lq_optimum() -> tuple[np.ndarray, float, np.ndarray]:
    """min |u|^2 subject to x_N = x_t, by numpy: x_N = A^N x0 + sum_k A^(N-1-k) B u_k = M u + c,
    u* = M^T (M M^T)^-1 (x_t - c). Returns u* (N, 3), J* and the multipliers of
    J + lam^T (x_N - x_t), lam* = -2 (M M^T)^-1 (x_t - c)."""
    A = np.eye(6)
    A[:3, 3:] = np.eye(3)
    B = np.vstack([np.zeros((3, 3)), np.eye(3)])
    M = np.hstack([np.linalg.matrix_power(A, N - 1 - k) @ B for k in range(N)])
    c = np.linalg.matrix_power(A, N) @ X0
    y = np.linalg.solve(M @ M.T, TARGET - c)
    u = M.T @ y
    return u.reshape(N, 3), float(u @ u), -2.0 * y


def _one_iteration(problem, update: MultiplierUpdate, order: int,
                   method: Method = Method.DYN) -> Stages:
    """The nominal after one DDP iteration from zero controls and zero multipliers."""
    opts = SolverOptions(ddp=dict(max_iter=1, map_order=order),
                         aul=dict(multiplier_update=update))
    st = Stages(problem, problem.rollout(np.zeros((N, 3))), np.zeros((N, 3)),
                Multipliers.initial(problem, opts.aul.mu_init), (0.0, 1e-2), opts.eps_da,
                order=order)
    return ddp(st, method, opts, DDPStats()).stages


@pytest.mark.parametrize("method", [Method.DYN, Method.QDYN, Method.HESS])
@pytest.mark.parametrize("order", [2, 3, 4, 5, 6])
def test_the_lq_problem_is_solved_by_one_iteration_at_every_map_order(order, method):
    problem = _lq()
    U_star, J_star, _ = _lq_optimum()
    st = _one_iteration(problem, MultiplierUpdate.SWEEP, order, method)
    assert st.order == order
    np.testing.assert_allclose(st.U, U_star, atol=1e-10)
    np.testing.assert_allclose(st.X[-1], TARGET, atol=1e-10)
    assert abs(float(np.sum(st.U ** 2)) - J_star) < 1e-10 * J_star
    assert J_star == pytest.approx(2.9742424242, abs=1e-10)   # the two-phase problem's J


def test_without_the_swept_multipliers_one_iteration_does_not_reach_the_lq_optimum():
    """The AUL's own update moves the multipliers only after a DDP solve: its first iteration
    ends at the penalised optimum, off the target (what the swept multipliers change)."""
    st = _one_iteration(_lq(), MultiplierUpdate.FIRST_ORDER, 2)
    assert np.max(np.abs(st.X[-1] - TARGET)) > 1e-2


def test_a_solve_with_swept_multipliers_ends_in_one_aul_iteration_on_the_lq():
    sol = solve(_lq(), np.zeros((N, 3)), fuel_optimal=False,
                options=SolverOptions(aul=dict(multiplier_update="sweep")))
    assert sol.converged
    assert sol.iterations["aul"] == 1
    U_star, _, lam_star = _lq_optimum()
    np.testing.assert_allclose(sol.U, U_star, atol=1e-9)
    np.testing.assert_allclose(sol.duals["lam_t"], lam_star, rtol=1e-8, atol=1e-10)


@pytest.mark.parametrize("update, order", [("sweep", 2), ("first_order", 3)])
def test_a_nonlinear_optimum_is_the_same_with_swept_multipliers_or_third_order_maps(update, order):
    """The orbit raise (test_policy's problem; J* = 0.0037561617 by the issue's independent
    reference) solved with either option reaches the default solve's optimum."""
    sol = solve(_orbit_raise([1.0, 0.0, 0.0, 1.0]), np.full((40, 2), 1e-3),
                options=SolverOptions(aul=dict(multiplier_update=update),
                                      ddp=dict(map_order=order)))
    assert sol.converged
    assert sol.cost == pytest.approx(0.0037561617, rel=1e-8)
    assert sol.max_violation < 1e-6


@pytest.mark.parametrize("value", [1, 7, True, 2.5, 3.0, "3"])
def test_a_map_order_outside_2_to_6_is_refused_by_name(value):
    with pytest.raises(DaddyError, match="options.ddp.map_order"):
        SolverOptions(ddp=dict(map_order=value))


def test_daddy_solve_takes_the_map_order_and_the_multiplier_update(tmp_path, capsys):
    """The command line's --map-order and --multiplier-update reach the solver (the double
    integrator's terminal rows swept: one AUL solve, where eq. 9 takes several), and are
    refused by name where they do not apply."""
    from daddy_core.cli import main
    path = tmp_path / "di.json"
    assert main(["solve", "double_integrator", "--map-order", "3", "--multiplier-update",
                 "sweep", "--quiet", "--json", str(path)]) == 0
    sol = Solution.from_json(path)
    assert sol.converged and sol.iterations["aul"] == 1
    assert sol.cost == pytest.approx(1.1272727272727, rel=1e-10)   # the closed-form cost
    assert main(["solve", "double_integrator", "--map-order", "7", "--quiet"]) == 2
    assert "options.ddp.map_order" in capsys.readouterr().err
    assert main(["solve", "dro_dro", "--parametrisation", "costate", "--multiplier-update",
                 "sweep", "--quiet"]) == 2
    assert "--multiplier-update" in capsys.readouterr().err
