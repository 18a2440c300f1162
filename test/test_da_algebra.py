"""DA algebra against closed forms and ring identities."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from daddy_core import da
from daddy_core.errors import DaddyError, DomainError

finite = st.floats(min_value=-3, max_value=3, allow_nan=False)
positive = st.floats(min_value=0.2, max_value=3, allow_nan=False)


def rand_da(rng, n=3, k=3, shape=()):
    tab = da.tables(n, k)
    return da.DA(rng.normal(size=(tab.size,) + shape), tab)


@pytest.mark.parametrize("k", [1, 2, 3, 4])
def test_ring_identities(k):
    rng = np.random.default_rng(k)
    a, b, c = (rand_da(rng, 3, k, (5,)) for _ in range(3))
    close = lambda x, y: np.testing.assert_allclose(x.c, y.c, rtol=1e-12, atol=1e-12)
    close(a * b, b * a)
    close((a * b) * c, a * (b * c))
    close(a * (b + c), a * b + a * c)
    close(a - a, a * 0.0)
    close((a + 2.5) * 1.0, 2.5 + a)


@pytest.mark.parametrize("k", [2, 3, 4])
def test_generic_kernel_matches_specialised_order2(k):
    # the order-k product truncated to order 2 equals the order-2 product
    rng = np.random.default_rng(0)
    t2, tk = da.tables(3, 2), da.tables(3, k)
    a2 = da.DA(rng.normal(size=(t2.size, 4)), t2)
    b2 = da.DA(rng.normal(size=(t2.size, 4)), t2)
    ak = da.DA(np.concatenate([a2.c, np.zeros((tk.size - t2.size, 4))]), tk)
    bk = da.DA(np.concatenate([b2.c, np.zeros((tk.size - t2.size, 4))]), tk)
    np.testing.assert_allclose((ak * bk).c[:t2.size], (a2 * b2).c, rtol=1e-13)


@settings(max_examples=60, deadline=None)
@given(x=positive, y=finite, k=st.integers(1, 4))
def test_inverse_functions(x, y, k):
    v = da.variables([x, y], order=k)
    p = v[0] * 0.5 + v[1] * v[1] * 0.1 + 1.0  # positive constant part
    close = lambda u, w: np.testing.assert_allclose(u.c, w.c, rtol=1e-10, atol=1e-10)
    close(da.exp(da.log(p)), p)
    close(da.sqrt(p) * da.sqrt(p), p)
    close(p * (1.0 / p), p ** 0)
    close(da.sin(v[1]) ** 2 + da.cos(v[1]) ** 2, v[1] ** 0)
    close(da.tan(da.arctan(v[1])), v[1])
    close(p ** 2.5, da.exp(2.5 * da.log(p)))
    close(p ** -1.5, 1.0 / (p * da.sqrt(p)))


def test_derivatives_closed_form():
    x = da.variables([0.7, -1.3], order=4)
    f = da.exp(x[0]) * da.sin(x[1])
    # d^a/dx0^a d^b/dx1^b = e^x0 * sin^(b)(x1)
    e, s, c = np.exp(0.7), np.sin(-1.3), np.cos(-1.3)
    np.testing.assert_allclose(f.gradient(), [e * s, e * c], rtol=1e-14)
    np.testing.assert_allclose(f.hessian(), [[e * s, e * c], [e * c, -e * s]], rtol=1e-14)
    d3 = f.derivative_tensor(3)  # monomials (0,0,0),(0,0,1),(0,1,1),(1,1,1)
    np.testing.assert_allclose(d3, [e * s, e * c, -e * s, -e * c], rtol=1e-13)
    a = da.arctan2(x[1], x[0])
    r2 = 0.7 ** 2 + 1.3 ** 2
    np.testing.assert_allclose(a.cons, np.arctan2(-1.3, 0.7))
    np.testing.assert_allclose(a.gradient(), [1.3 / r2, 0.7 / r2], rtol=1e-14)
    h = da.hypot(x[0], x[1])
    np.testing.assert_allclose(h.gradient(), [0.7 / np.sqrt(r2), -1.3 / np.sqrt(r2)], rtol=1e-14)


def test_same_function_on_floats_arrays_and_da():
    def f(x):
        return da.sqrt(x[0] * x[0] + x[1] * x[1]) * da.cos(x[1]) / (1.0 + x[0])
    pts = np.array([[0.3, 1.2, 2.0], [0.4, -0.1, 0.5]])
    arr = f(pts)
    d = f(da.variables(pts, order=2))
    np.testing.assert_allclose(d.cons, arr, rtol=1e-15)
    for j in range(3):
        np.testing.assert_allclose(f(pts[:, j]), arr[j], rtol=1e-15)


def test_batch_shapes_and_numpy_interop():
    x = da.variables(np.ones((2, 5)), order=2)
    arr = np.arange(5.0)
    assert (arr * x[0]).shape == (5,)
    assert (x[0] + arr).shape == (5,)
    assert (x - np.ones((2, 1))).shape == (2, 5)
    s = da.stack([x[0], 1.0, x[1] * arr])
    assert s.shape == (3, 5)
    np.testing.assert_allclose(s.cons[1], 1.0)
    w = da.where(arr > 2, x[0], x[1] * 2)
    np.testing.assert_allclose(w.cons, np.where(arr > 2, 1.0, 2.0))
    assert bool(np.all(x[0] > 0.5))


def test_vector_keeps_python_floats_as_a_list_and_stacks_everything_else():
    """da.vector is stack for arrays and DA; Python floats stay the list (the single-state
    integrators' working type), and a Dynamics called on such lists still returns an array."""
    from daddy_core.catalogue import load_case
    assert da.vector([1.0, 2.5]) == [1.0, 2.5]
    for items in ([1.0, np.float64(2.0)], [np.ones(3), np.zeros(3)]):
        out = da.vector(items)
        assert isinstance(out, np.ndarray) and out.shape[0] == 2
    x = da.variables([1.0, 2.0], order=2)
    assert isinstance(da.vector([1.0, x[0]]), da.DA)
    case = load_case("earth_mars")
    dyn = case.rhs()
    dx_list = dyn(0.0, case.x0.tolist(), [0.1, 0.0, 0.0])
    assert isinstance(dx_list, np.ndarray)
    np.testing.assert_array_equal(dx_list, dyn(0.0, case.x0, np.array([0.1, 0.0, 0.0])))


def test_misuse_errors_name_the_problem():
    a = da.variables([1.0, 2.0], order=2)
    b = da.variables([1.0, 2.0, 3.0], order=2)
    with pytest.raises(DaddyError, match="n=2"):
        a[0] * b[0]
    with pytest.raises(DaddyError, match="order"):
        a[0] + da.variables([1.0, 2.0], order=3)[0]
    with pytest.raises(DomainError, match=r"sqrt .* -1"):
        da.sqrt(a[0] - 2.0)
    with pytest.raises(DomainError, match="log .* 0"):
        da.log(a[0] - 1.0)
    with pytest.raises(DomainError, match="1/x"):
        1.0 / (a[0] - 1.0)
    with pytest.raises(DaddyError, match="NaN"):
        da.variables([np.nan, 1.0])
    with pytest.raises(DaddyError, match="order"):
        da.variables([1.0], order=0)
    with pytest.raises(DaddyError, match="leading axis"):
        da.evaluate(a[0], np.zeros(3))


@pytest.mark.parametrize("order", [1, 2, 5])
def test_tanh_matches_its_exponential_form_and_saturates_without_overflow(order):
    """tanh of a DA: the same Taylor coefficients as 1 - 2 / (e^{2x} + 1) where that form is
    safe, and finite (the step's flat tails) where e^{2x} overflows."""
    from daddy_core.da import functions as dm
    x = da.variables(np.array([0.3, -1.2]), order=order)
    ref = 1.0 - 2.0 / (dm.exp(2.0 * x) + 1.0)
    np.testing.assert_allclose(dm.tanh(x).c, ref.c, rtol=1e-12, atol=1e-14)
    big = dm.tanh(da.variables(np.array([800.0, -800.0]), order=order))
    assert np.all(np.isfinite(big.c))
    np.testing.assert_allclose(big.c[0], [1.0, -1.0])
    np.testing.assert_allclose(big.c[1:], 0.0, atol=1e-300)
