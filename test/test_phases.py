"""Multi-phase problems (issue 46, second part): the seed's two-phase LQ problem against the
issue's values and its KKT system solved with numpy (controls, the phase-2 static controls,
the terminal and junction multipliers), a three-phase problem with a velocity jump and unequal
stages against its own KKT system, and bad phases named by field."""
import numpy as np
import pytest

from daddy_core.da import functions as dm
from daddy_core.errors import DaddyError
from daddy_core.phases import Phase, link_multipliers, multi_phase, phase_slices
from daddy_core.solver import SolverOptions, solve
from daddy_core.static_parameters import StaticParameter

TIGHT = SolverOptions(kkt=dict(tol=1e-10))
X_T = np.array([2.0, 4.0, 1.0, -0.5, 1.5, -2.5])


def _zoh(x, u, dt):
    """r+ = r + v dt + u dt^2 / 2, v+ = v + u dt (3-D); the seed's r+ = r + v at dt = 1 with
    its v+ = v + u is the same map without the u dt^2 / 2 term: ``_seed``."""
    return dm.stack([x[i] + x[i + 3] * dt + 0.5 * u[i] * dt * dt for i in range(3)]
                    + [x[i + 3] + u[i] * dt for i in range(3)])


def _seed(x, u, dt):
    return dm.stack([x[i] + x[i + 3] for i in range(3)] + [x[i + 3] + u[i] for i in range(3)])


def _energy(x, u, dt, hom=(0.0, 1.0)):
    return u[0] * u[0] + u[1] * u[1] + u[2] * u[2]


def _continuity(jump=np.zeros(6)):
    return lambda x_end, x_start, omega: dm.stack([x_start[i] - x_end[i] - jump[i]
                                                   for i in range(6)])


def _phase_start(names):
    return lambda omega: dm.stack([omega[i] for i in range(len(names))])


def _target(x, xt):
    return dm.stack([x[i] - xt[i] for i in range(6)])


def _kkt(blocks, x0, jumps):
    """min sum |u|^2 s.t. x_N = x_t for the linear stages ``blocks`` [(A, B), ...] with state
    jumps {stage index: jump} added before that stage: (u (N, 3), lambda_t (6,), states)."""
    N = len(blocks)
    def final_map(k):   # the map from the state before stage k to x_N
        P = np.eye(6)
        for A, _ in reversed(blocks[k:]):
            P = P @ A
        return P
    M = np.hstack([final_map(k + 1) @ blocks[k][1] for k in range(N)])
    free = final_map(0) @ x0 + sum(final_map(k) @ j for k, j in jumps.items())
    K = np.block([[2 * np.eye(3 * N), M.T], [M, np.zeros((6, 6))]])
    z = np.linalg.solve(K, np.concatenate([np.zeros(3 * N), X_T - free]))
    return z[:3 * N].reshape(N, 3), z[3 * N:], final_map


def test_the_seed_two_phase_lq_problem():
    """The issue's values (J*, omega_2*, u_k, Table 1's multipliers under the issue's sign
    convention) and the KKT system solved with numpy, to round-off."""
    names = [f"w{i}" for i in range(6)]
    one = Phase("one", np.ones(5), _seed, _energy, link=_continuity())
    two = Phase("two", np.ones(5), _seed, _energy, start=_phase_start(names),
                params=tuple(StaticParameter(n, -50.0, 50.0, 0.0, 1.0) for n in names))
    problem = multi_phase("seed_lq", np.ones(6), X_T, [one, two], lambda x, xt: 0.0 * x[0],
                          nu=3, g_teq=_target)
    sol = solve(problem, np.zeros((10, 3)), fuel_optimal=False, options=TIGHT)
    assert sol.converged
    assert sol.cost == pytest.approx(2.9742424242, abs=1e-9)
    omega = np.array([sol.parameters[n] for n in names])
    np.testing.assert_allclose(omega, [39 / 11, 85 / 33, 163 / 33, -1 / 11, -5 / 33, 4 / 33],
                               atol=1e-9)
    k = np.arange(10)
    np.testing.assert_allclose(sol.U[:, :3], np.column_stack(
        [-3 / 11 + 3 / 110 * k, -5 / 11 + 37 / 330 * k, -2 / 55 - 23 / 330 * k]), atol=1e-9)
    A = np.eye(6)
    A[[0, 1, 2], [3, 4, 5]] = 1.0
    B = np.vstack([np.zeros((3, 3)), np.eye(3)])
    u, lam_t, _ = _kkt([(A, B)] * 10, np.ones(6), {})
    np.testing.assert_allclose(sol.U[:, :3], u, atol=1e-9)
    np.testing.assert_allclose(sol.duals["lam_t"], lam_t, atol=1e-9)
    # Table 1 (printed to 6 digits): lambda_2 (terminal) as printed; lambda_1 its negative under psi_1 = x_2,1 - x_1,6
    np.testing.assert_allclose(sol.duals["lam_t"], [0.0545455, 0.224242, -0.139394,
                                                    0.0545455, -1.10909, 1.32727], atol=5e-6)
    lam_1 = link_multipliers(problem, [one, two], sol.duals)["one->two"]
    np.testing.assert_allclose(lam_1, -np.linalg.matrix_power(A, 5).T @ lam_t, atol=1e-9)
    np.testing.assert_allclose(-lam_1, [0.0545455, 0.224242, -0.139394, 0.327273, 0.0121212,
                                        0.630303], atol=5e-6)
    assert [s.stop - s.start for s in phase_slices(problem, [one, two])] == [5, 5]


def test_three_phases_with_unequal_stages_and_a_velocity_jump():
    """Phase 1 (4 stages of 0.5) carries on into phase 2 (3 stages of 1.0); phase 3 (5 stages
    of 0.3) starts at its static controls, linked to phase 2's end plus a velocity jump: the
    optimum of the equivalent single problem with that jump, from numpy."""
    names = [f"s{i}" for i in range(6)]
    jump = np.array([0.0, 0.0, 0.0, 0.3, -0.2, 0.1])
    phases = [Phase("a", np.full(4, 0.5), _zoh, _energy),
              Phase("b", np.full(3, 1.0), _zoh, _energy, link=_continuity(jump)),
              Phase("c", np.full(5, 0.3), _zoh, _energy, start=_phase_start(names),
                    params=tuple(StaticParameter(n, -50.0, 50.0, 0.0, 1.0) for n in names))]
    x0 = np.array([1.0, 0.0, -1.0, 0.2, 0.0, 0.1])
    problem = multi_phase("three", x0, X_T, phases, lambda x, xt: 0.0 * x[0], nu=3,
                          g_teq=_target)
    sol = solve(problem, np.zeros((12, 3)), fuel_optimal=False, options=TIGHT)
    assert sol.converged

    def block(dt):
        A = np.eye(6)
        A[[0, 1, 2], [3, 4, 5]] = dt
        return A, np.vstack([0.5 * dt * dt * np.eye(3), dt * np.eye(3)])
    blocks = [block(0.5)] * 4 + [block(1.0)] * 3 + [block(0.3)] * 5
    u, _, _ = _kkt(blocks, x0, {7: jump})
    np.testing.assert_allclose(sol.U[:, :3], u, atol=1e-8)
    assert sol.cost == pytest.approx(float(np.sum(u * u)), abs=1e-9)
    # phase 3 starts at phase 2's end plus the jump
    end_b = sol.X[7, :6]
    np.testing.assert_allclose([sol.parameters[n] for n in names], end_b + jump, atol=1e-8)


@pytest.mark.parametrize("phases, field", [
    ([Phase("a", np.ones(2), _seed, _energy, link=_continuity())], r"phases\[0\].*link"),
    ([Phase("a", np.array([1.0, -1.0]), _seed, _energy)], r"phases\[0\].*stage_dt"),
    ([Phase("a", np.ones(2), _seed, _energy, link=lambda xe, xs, om: 1.0),
      Phase("b", np.ones(2), _seed, _energy)], r"phases\[0\].*link must return a vector"),
    ([Phase("a", np.ones(2), _seed, _energy, link=lambda xe, xs, om: xs[7] - xe[7]),
      Phase("b", np.ones(2), _seed, _energy)], r"phases\[0\].*link raised IndexError"),
    ([Phase("a", np.ones(2), _seed, _energy),
      Phase("b", np.ones(2), _seed, _energy, start=lambda om: np.zeros(4),
            params=(StaticParameter("w", -1.0, 1.0),))], r"phases\[1\].*start must return"),
    ([], "non-empty"),
])
def test_bad_phases_are_refused_by_field(phases, field):
    with pytest.raises(DaddyError, match=field):
        multi_phase("bad", np.ones(6), X_T, phases, lambda x, xt: 0.0 * x[0], nu=3)


def test_the_second_order_multiplier_update_solves_the_lq_problem_with_one_update():
    """Linear dynamics and constraints, quadratic cost: the Lagrangian's quadratic model is
    exact, so one second-order update gives the optimal multipliers and the next DDP solve
    ends feasible -- two AUL solves, no polishing -- where eq. 9's two solves are not there."""
    names = [f"w{i}" for i in range(6)]
    one = Phase("one", np.ones(5), _seed, _energy, link=_continuity())
    two = Phase("two", np.ones(5), _seed, _energy, start=_phase_start(names),
                params=tuple(StaticParameter(n, -50.0, 50.0, 0.0, 1.0) for n in names))
    problem = multi_phase("seed_lq", np.ones(6), X_T, [one, two], lambda x, xt: 0.0 * x[0],
                          nu=3, g_teq=_target)
    two_solves = dict(max_iter=2)
    sol = solve(problem, np.zeros((10, 3)), fuel_optimal=False, polish=False,
                options=SolverOptions(aul=dict(two_solves, multiplier_update="second_order")))
    assert sol.converged and sol.max_violation < 1e-12
    assert sol.cost == pytest.approx(2.9742424242, abs=1e-9)
    np.testing.assert_allclose(sol.duals["lam_t"], [3 / 55, 37 / 165, -23 / 165, 3 / 55,
                                                    -61 / 55, 73 / 55], atol=1e-9)
    first = solve(problem, np.zeros((10, 3)), fuel_optimal=False, polish=False,
                  options=SolverOptions(aul=two_solves))
    assert not first.converged and abs(first.parameters["w2"] - 163 / 33) > 1e-3


def test_an_unknown_multiplier_update_is_named():
    with pytest.raises(DaddyError, match="options.aul.multiplier_update"):
        SolverOptions(aul=dict(multiplier_update="third_order"))
