"""Evaluation, composition and convergence radius of polynomial maps."""
import numpy as np
import pytest

from daddy_core import da
from daddy_core.errors import DaddyError


def poly_map(k, shape=(4,)):
    x = da.variables(np.full((2,) + shape, 0.5) + np.arange(shape[0]) * 0.1, order=k)
    return da.stack([da.exp(x[0]) * x[1], da.sin(x[0] + x[1] * x[1])])


@pytest.mark.parametrize("k", [1, 2, 3, 4])
def test_evaluate_matches_truncated_series(k):
    m = poly_map(k)
    dv = np.array([1e-3, -2e-3])
    got = da.evaluate(m, dv)
    x0 = 0.5 + np.arange(4) * 0.1
    exact = np.stack([np.exp(x0 + dv[0]) * (x0 + dv[1]), np.sin(x0 + dv[0] + (x0 + dv[1]) ** 2)])
    # truncation error O(|dv|^(k+1))
    assert np.max(np.abs(got - exact)) < 50 * (3e-3) ** (k + 1)
    # batched displacement, one per element
    dvb = np.tile(dv[:, None], (1, 4))
    np.testing.assert_allclose(da.evaluate(m, dvb), got, rtol=1e-14)


@pytest.mark.parametrize("k", [2, 3])
def test_composition_associative_and_shift(k):
    rng = np.random.default_rng(1)
    t = da.tables(2, k)
    f, g, h = (da.DA(rng.normal(size=(t.size, 2)) * 0.3, t) for _ in range(3))
    # inner maps must have zero constant part to compose truncated maps associatively
    g.c[0] = 0.0
    h.c[0] = 0.0
    lhs = da.compose(da.compose(f, g), h)
    rhs = da.compose(f, da.compose(g, h))
    np.testing.assert_allclose(lhs.c, rhs.c, rtol=1e-12, atol=1e-13)
    # identity
    ident = da.variables(np.zeros(2), order=k)
    np.testing.assert_allclose(da.compose(f, ident).c, f.c, atol=1e-15)
    # re-centring then evaluating at 0 equals evaluating at the shift
    s = np.array([0.05, -0.02])
    np.testing.assert_allclose(da.shift(f, s).cons, da.evaluate(f, s), rtol=1e-13)
    # plugging a map into a polynomial equals evaluating on its constants
    np.testing.assert_allclose(da.compose(f, ident + s).cons, da.evaluate(f, s), rtol=1e-13)


@pytest.mark.parametrize("shape, dv_shape", [((7, 12), (5, 12)), ((7, 70), (5, 70)),
                                             ((7, 12), (5, 1, 12)),
                                             ((3,), (5,)), ((4,), (5, 4)), ((), (5,))])
def test_order2_shift_equals_composition(shape, dv_shape):
    # the closed-form order-2 re-centring is the general composition with dv + identity
    rng = np.random.default_rng(3)
    t = da.tables(5, 2)
    f = da.DA(rng.normal(size=(t.size,) + shape), t)
    dv = rng.normal(size=dv_shape) * 0.3
    fast = da.shift(f, dv)
    slow = da.compose(f, da.variables(dv, order=2, n=5))
    assert fast.c.shape == slow.c.shape
    np.testing.assert_allclose(fast.c, slow.c, rtol=1e-13, atol=1e-14)
    with pytest.raises(DaddyError, match="leading axis"):
        da.shift(f, np.zeros(4))


def test_radius_order2_formula_and_inf():
    x = da.variables([1.0, 2.0], order=2)
    p = da.stack([x[0] * 3.0 + x[1] * x[1], x[0] * 1.0, x[0] * x[0] + 0.0 * x[1]])
    a1, a2 = 3.0, 1.0
    r = da.radius(p, 1e-6, axis=None)
    np.testing.assert_allclose(r[0], (1e-6 * (a1 + 4.0) / a2 ** 2) ** (1 / 3))  # d(x1^2) adds 4
    assert np.isinf(r[1])  # no order-2 terms: exact
    np.testing.assert_allclose(r[2], (1e-6 * 2.0 / 1.0) ** (1 / 3))
    np.testing.assert_allclose(da.radius(p, 1e-6), min(r))


def test_radius_is_a_useful_accuracy_bound():
    # the truncation error at the radius is of the order of eps
    x = da.variables([0.3, 0.2], order=2)
    m = da.stack([da.exp(x[0] * x[1] + x[0]), da.sin(x[1]) / (1.2 + x[0])])
    eps = 1e-8
    r = da.radius(m, eps)
    rng = np.random.default_rng(2)
    for _ in range(20):
        d = rng.normal(size=2)
        d *= r / np.linalg.norm(d)
        exact = np.array([np.exp((0.3 + d[0]) * (0.2 + d[1]) + 0.3 + d[0]),
                          np.sin(0.2 + d[1]) / (1.5 + d[0])])
        assert np.max(np.abs(da.evaluate(m, d) - exact)) < 100 * eps


def test_radius_higher_order_consistent_with_order2_rule():
    x = da.variables([0.1], order=4)
    p = da.exp(x[0] * 2.0)
    r = float(da.radius(p[None], 1e-8))
    # coefficients 2^i/i! decay like a geometric series beyond order 2; r must be finite > 0
    assert 0 < r < 1


@pytest.mark.parametrize("k", [1, 3, 4, 5, 6])
def test_shift_at_any_order_is_the_composition_with_the_shifted_identity(k):
    """Taylor's shift (orders other than 2) gives the polynomial ``compose`` gives, for a batch
    of maps with one displacement each and for one displacement for all."""
    rng = np.random.default_rng(k)
    x = da.variables(rng.normal(size=(4, 5)), order=k)
    p = da.stack([da.sin(x[0]) * da.exp(x[1]) + x[3] ** 3, x[0] * x[2] / (2 + x[1] ** 2)])
    for dv in (rng.normal(size=(4, 5)) * 0.3, rng.normal(size=4) * 0.3):
        got = da.shift(p, dv)
        want = da.compose(p, da.variables(dv, order=k, n=4))
        np.testing.assert_allclose(got.c, want.c, rtol=1e-12, atol=1e-13 * np.abs(want.c).max())
    # and re-centring back returns the polynomial (exact for a polynomial of degree <= k)
    q = da.DA(rng.normal(size=(da.tables(3, k).size, 2)), da.tables(3, k))
    dv = rng.normal(size=3)
    np.testing.assert_allclose(da.shift(da.shift(q, dv), -dv).c, q.c, rtol=1e-10, atol=1e-10)
