"""The DA engine's calculus (issue 47, ``da/calculus.py``): map inversion against closed forms
(arcsin's series, the polar map of the Cartesian one) and round trips at every order,
derivatives against the derivative's own expansion, partial evaluation against full
evaluation, and bad input named."""
import math

import numpy as np
import pytest

from daddy_core.da import functions as dm
from daddy_core.da.calculus import derivative, invert, partial_evaluate
from daddy_core.da.core import variables
from daddy_core.da.maps import compose, evaluate
from daddy_core.errors import DaddyError

ORDERS = range(1, 7)


@pytest.mark.parametrize("k", ORDERS)
def test_the_inverse_of_sine_is_the_arcsine_series(k):
    arcsin = [0.0, 1.0, 0.0, 1 / 6, 0.0, 3 / 40, 0.0]       # y + y^3/6 + 3 y^5/40 + ...
    n = invert(variables([0.0], order=k).sin())
    np.testing.assert_allclose(n.c[:, 0], arcsin[:k + 1], rtol=0, atol=1e-15)


@pytest.mark.parametrize("k", ORDERS)
def test_the_inverse_of_the_polar_to_cartesian_map_is_the_cartesian_to_polar_map(k):
    """(r, theta) -> (r cos theta, r sin theta) at (2, 0.7), inverted, against the expansion
    of (sqrt(x^2 + y^2), atan(y / x)) at its image (x > 0 there)."""
    rt = variables([2.0, 0.7], order=k)
    cart = dm.stack([rt[0] * rt[1].cos(), rt[0] * rt[1].sin()])
    xy = variables(cart.cons, order=k)
    polar = dm.stack([(xy[0] * xy[0] + xy[1] * xy[1]).sqrt(), (xy[1] / xy[0]).arctan()])
    inv = invert(cart)
    assert np.all(inv.c[0] == 0.0)
    np.testing.assert_allclose(inv.c[1:], polar.c[1:], rtol=0, atol=1e-12)


def _near_identity_maps(k, rng):
    """A batch of 5 maps of three variables with a well-conditioned linear part."""
    v = variables(rng.normal(size=(3, 5)), order=k)
    return dm.stack([v[0] + 0.3 * v[1] * v[2] + 0.2 * v[0].sin(),
                     v[1] - 0.2 * v[0] * v[0] + 0.4 * v[2],
                     0.5 * v[2].exp() + 0.5 * v[0] - 0.1 * v[1] * v[1] * v[1]])


@pytest.mark.parametrize("k", ORDERS)
def test_a_map_composed_with_its_inverse_is_the_identity_at_every_order(k):
    rng = np.random.default_rng(47 + k)
    m = _near_identity_maps(k, rng)
    n = invert(m)
    identity = variables(np.zeros((3, 5)), order=k, n=3)
    scale = max(1.0, np.abs(n.c).max())
    # m(N(dy)) = m(0) + dy, and N(m(dx) - m(0)) = dx
    np.testing.assert_allclose(compose(m, n).c, (identity + m.cons).c, rtol=0, atol=1e-13 * scale)
    np.testing.assert_allclose(compose(n, m - m.cons).c, identity.c, rtol=0, atol=1e-13 * scale)


def test_invert_refuses_a_singular_or_non_square_map():
    x = variables([0.0, 0.0], order=3)
    with pytest.raises(DaddyError, match="singular"):
        invert(dm.stack([x[0] + x[1], 2.0 * (x[0] + x[1]) + x[0] * x[1]]))
    with pytest.raises(DaddyError, match="needs 2 components"):
        invert(dm.stack([x[0], x[1], x[0] * x[1]]))


@pytest.mark.parametrize("k", ORDERS)
def test_the_derivative_is_the_expansion_of_the_derivative_to_one_order_less(k):
    """d/dx0 exp(x0) sin(x1) = exp(x0) sin(x1), d/dx1 = exp(x0) cos(x1): each expanded at
    order k, its degree-k terms dropped."""
    x = variables([0.3, -1.1], order=k)
    p = x[0].exp() * x[1].sin()
    for i, exact in ((0, p), (1, x[0].exp() * x[1].cos())):
        d = derivative(p, i)
        low = exact.c.copy()
        low[x.T.block[k]] = 0.0
        np.testing.assert_allclose(d.c, low, rtol=0, atol=1e-14)


def test_partial_evaluation_is_evaluation_with_those_variables_fixed():
    rng = np.random.default_rng(7)
    x = variables([0.2, -0.4, 1.0], order=4)
    p = dm.stack([x[0] * x[1].exp() + x[2] * x[1] * x[1], (x[0] + x[2]).cos() * x[1]])
    q = partial_evaluate(p, {1: 0.3})
    touches_x1 = q.T.exponents[:, 1] > 0
    assert np.all(q.c[touches_x1] == 0.0)
    for _ in range(5):
        dv = rng.normal(scale=0.2, size=3)
        fixed = dv.copy()
        fixed[1] = 0.3
        np.testing.assert_allclose(evaluate(q, dv), evaluate(p, fixed), rtol=1e-13, atol=1e-14)
    # every variable fixed: the value at that point
    all_fixed = partial_evaluate(p, {0: 0.1, 1: -0.2, 2: 0.05})
    np.testing.assert_allclose(all_fixed.cons, evaluate(p, np.array([0.1, -0.2, 0.05])),
                               rtol=1e-13)
    assert np.all(all_fixed.c[1:] == 0.0)


def test_bad_variable_indices_are_named():
    x = variables([0.0, 0.0], order=2)
    with pytest.raises(DaddyError, match="variable index"):
        derivative(x[0], 2)
    with pytest.raises(DaddyError, match="variable indices"):
        partial_evaluate(x[0], {-1: 0.0})
    with pytest.raises(DaddyError, match="not finite"):
        partial_evaluate(x[0], {0: math.nan})
