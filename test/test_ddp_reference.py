"""The backward sweeps against a reference DDP written here, as crocoddyl tests its solvers
against an independent Python one: a dense, plain-numpy Riccati recursion on the textbook
Q expansion (Q_x, Q_u, Q_xx, Q_ux, Q_uu from l_z, l_zz, f_z, f_zz, V_x, V_xx), with none of the
bordered matrices, DA compositions or unrolled inverses of ``solver.sweeps`` and
``solver.linalg``. Std (Alg. 7) drops the dynamics' second derivatives; Hess (Alg. 9) and Q
(Alg. 10, the cost-to-go polynomial composed with the stage map: the same terms at order 2)
keep them. The stage maps' first derivatives are checked against central differences of the
float flow, so the reference's inputs do not come from the DA engine alone."""
import numpy as np
import pytest

from daddy_core.da import functions as dm
from daddy_core.dynamics import Dynamics
from daddy_core.problem import Problem, flow_step
from daddy_core.solver.lagrangian import Multipliers
from daddy_core.solver.options import Sweep
from daddy_core.solver.sweeps import Stages, backward_sweep


def _orbit_raise(N: int) -> Problem:
    """A planar orbit raise (mu = 1) with a thrust bound and a nonlinear terminal constraint:
    dynamics with non-zero second derivatives, and an augmented cost with penalty terms."""
    def rhs(t, x, u):
        k = (x[0] * x[0] + x[1] * x[1]) ** -1.5
        return dm.stack([x[2], x[3], -x[0] * k + u[0], -x[1] * k + u[1]])

    return Problem(
        name="orbit_raise", nu=2, x0=np.array([1.0, 0.0, 0.0, 1.0]), x_target=np.zeros(4),
        stage_dt=np.full(N, 0.3), step=flow_step(Dynamics(rhs, scalar_components=True)),
        stage_cost=lambda x, u, dt, hom: (u[0] * u[0] + u[1] * u[1]) * dt
        + (x[0] * x[0]) * (0.01 * dt),
        terminal_cost=lambda x, xt: (x[0] * x[0] + x[1] * x[1]) * 10.0,
        g_teq=lambda x, xt: dm.stack([x[0] * x[3] - x[1] * x[2] - 1.1]),
        g_ineq=lambda x, u, dt: dm.stack([(u[0] * u[0] + u[1] * u[1]) * 100.0 - 1.0]))


def _stages(N: int, seed: int) -> Stages:
    prob = _orbit_raise(N)
    rng = np.random.default_rng(seed)
    U = 0.05 * rng.normal(size=(N, 2))
    U[0] = [0.12, 0.02]   # past the thrust bound: its penalty's curvature enters Q_uu there
    X = prob.rollout(U)
    mult = Multipliers.initial(prob, 10.0)
    mult.lam_t[...] = 0.1 * rng.normal(size=mult.lam_t.shape)
    return Stages(prob, X, U, mult, (0.0, 1e-2), 1e-6)


def _reference_sweep(st: Stages, second_order: bool, rho: float):
    """Textbook DDP backward pass: a (N, nu), b (N, nu, nx), dv1 = sum a.Q_u,
    dv2 = sum a.Q_uu.a / 2."""
    nx, nu, N = st.problem.nx, st.problem.nu, st.problem.N
    fz = np.moveaxis(st.F.gradient(), 1, 0)      # (N, nx, nx + nu)
    fzz = np.moveaxis(st.F.hessian(), 1, 0)      # (N, nx, nx + nu, nx + nu)
    Vx, Vxx = st.phix.copy(), st.phixx.copy()
    a, b = np.zeros((N, nu)), np.zeros((N, nu, nx))
    dv1 = dv2 = 0.0
    for k in reversed(range(N)):
        fx, fu = fz[k][:, :nx], fz[k][:, nx:]
        lx, lu = st.lz[k][:nx], st.lz[k][nx:]
        lxx, lux, luu = st.lzz[k][:nx, :nx], st.lzz[k][nx:, :nx], st.lzz[k][nx:, nx:]
        Qx = lx + fx.T @ Vx
        Qu = lu + fu.T @ Vx
        Qxx = lxx + fx.T @ Vxx @ fx
        Qux = lux + fu.T @ Vxx @ fx
        Quu = luu + fu.T @ Vxx @ fu
        if second_order:
            H = np.einsum("i,iab->ab", Vx, fzz[k])
            Qxx, Qux, Quu = Qxx + H[:nx, :nx], Qux + H[nx:, :nx], Quu + H[nx:, nx:]
        M = np.linalg.inv(Quu + rho * np.eye(nu))
        a[k], b[k] = -M @ Qu, -M @ Qux
        dv1 += a[k] @ Qu
        dv2 += 0.5 * a[k] @ Quu @ a[k]
        Vx = Qx + b[k].T @ Qu + Qux.T @ a[k] + b[k].T @ Quu @ a[k]
        Vxx = Qxx + b[k].T @ Qux + Qux.T @ b[k] + b[k].T @ Quu @ b[k]
        Vxx = 0.5 * (Vxx + Vxx.T)
    return a, b, dv1, dv2


@pytest.mark.parametrize("sweep", list(Sweep))
@pytest.mark.parametrize("N, seed, rho", [(3, 0, 0.0), (8, 1, 0.0), (8, 2, 1e-3), (13, 4, 0.1)])
def test_backward_sweep_matches_a_dense_reference_riccati_recursion(sweep, N, seed, rho):
    """(The cases are ones whose Q_uu + rho I is positive definite at every stage: the
    reference has no Gauss-Newton fallback.)"""
    st = _stages(N, seed)
    gains = backward_sweep(st, sweep, rho)
    assert gains is not None
    a, b, dv1, dv2 = _reference_sweep(st, second_order=sweep is not Sweep.STD, rho=rho)
    scale = max(1.0, np.max(np.abs(a)))
    np.testing.assert_allclose(gains.a, a, rtol=1e-9, atol=1e-11 * scale)
    np.testing.assert_allclose(gains.b, b, rtol=1e-9, atol=1e-11 * max(1.0, np.max(np.abs(b))))
    assert gains.dv1 == pytest.approx(dv1, rel=1e-9, abs=1e-14)
    assert gains.dv2 == pytest.approx(dv2, rel=1e-9, abs=1e-14)
    assert gains.clipped == 0


def test_the_second_order_terms_matter_on_this_problem():
    """The reference's Std and Hess gains differ here (else the test above could not tell the
    sweeps apart)."""
    st = _stages(8, 1)
    a_std = _reference_sweep(st, False, 0.0)[0]
    a_hess = _reference_sweep(st, True, 0.0)[0]
    assert np.max(np.abs(a_std - a_hess)) > 1e-6 * np.max(np.abs(a_std))


def test_the_stage_maps_first_derivatives_are_the_flows():
    """f_z of the stage maps against central differences of the float flow (step 1e-6)."""
    st = _stages(5, 4)
    prob = st.problem
    fz = np.moveaxis(st.F.gradient(), 1, 0)
    h = 1e-6
    for k in range(prob.N):
        z = np.concatenate([st.X[k], st.U[k]])
        for j in range(z.size):
            e = np.zeros_like(z)
            e[j] = h
            plus = prob.stage_flow((z + e)[:prob.nx], (z + e)[prob.nx:], k)
            minus = prob.stage_flow((z - e)[:prob.nx], (z - e)[prob.nx:], k)
            np.testing.assert_allclose(fz[k][:, j], (plus - minus) / (2 * h), atol=1e-7)
