"""DA derivatives of a one-stage CR3BP flow map (7 states + 3 controls = 10 variables) against
complex-step (order 1) and finite differences of complex-step gradients (order 2) of the very
same float integrator."""
import numpy as np
import pytest

from daddy_core import da
from daddy_core.integrators import rk4, rk78
from daddy_core.catalogue import load_case

CASE = load_case("halo_l2_l1")
RHS = CASE.rhs()
DT = 20.0 * 86400 / CASE.units.tu_s / 110
Z0 = np.concatenate([CASE.x0, [0.05, -0.1, 0.12]])  # a thrusting stage


def flow(z, integrator):
    # floats go through the batched code path (batch of one), exactly as the DA does
    col = z[:, None]
    if integrator == "rk78":
        out = rk78(RHS, col[:7], col[7:], 0.0, np.array([DT]), tol=1e-13)
    else:
        out = rk4(RHS, col[:7], col[7:], 0.0, np.array([DT]), steps=20)
    return out[:, 0]


def complex_step_jacobian(z, integrator, h=1e-30):
    J = np.empty((7, 10))
    for j in range(10):
        zc = z.astype(complex)
        zc[j] += 1j * h
        J[:, j] = flow(zc, integrator).imag / h
    return J


@pytest.mark.parametrize("integrator", ["rk4", "rk78"])
def test_order1_matches_complex_step(integrator):
    m = flow(da.variables(Z0, order=2), integrator)
    J = complex_step_jacobian(Z0, integrator)
    np.testing.assert_allclose(m.cons, flow(Z0, integrator), rtol=1e-14, atol=1e-15)
    err = np.abs(m.gradient() - J) / np.maximum(np.abs(J), 1e-8 * np.abs(J).max())
    assert err.max() <= 1e-12, err.max()


def test_order2_matches_differenced_complex_step():
    m = flow(da.variables(Z0, order=2), "rk4")
    H = m.hessian()  # (7, 10, 10)
    # central differences of exact (complex-step) Jacobians: truncation O(h^2) ~ 1e-10 relative,
    # round-off ~ 1e-16 / h ~ 1e-11: a 1e-7 relative bound leaves a margin of ~1000.
    h = 1e-5
    Hfd = np.empty_like(H)
    for i in range(10):
        zp, zm = Z0.copy(), Z0.copy()
        zp[i] += h
        zm[i] -= h
        Hfd[:, :, i] = (complex_step_jacobian(zp, "rk4") - complex_step_jacobian(zm, "rk4")) / (2 * h)
    scale = np.abs(Hfd).max()
    assert np.max(np.abs(H - Hfd) / scale) <= 1e-7
    # symmetric by construction, and the finite differences agree with that
    np.testing.assert_allclose(Hfd, np.swapaxes(Hfd, 1, 2), atol=1e-7 * scale)


def test_batched_expansion_equals_single():
    rng = np.random.default_rng(0)
    Z = Z0[:, None] + rng.normal(scale=1e-3, size=(10, 5))
    mb = flow(da.variables(Z, order=2), "rk78")
    for j in [0, 3]:
        ms = flow(da.variables(Z[:, j], order=2), "rk78")
        np.testing.assert_allclose(mb.c[:, :, j], ms.c, rtol=1e-10, atol=1e-14)
