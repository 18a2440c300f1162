"""Truncated multivariate Taylor polynomials ("DA") with numpy coefficient storage.

A ``DA`` holds the Taylor expansion, to order ``k`` in ``n`` variables, of an array-valued function
of array ``shape``. Coefficients live in one array ``c`` of shape ``(M, *shape)``: the monomial
axis first, the batch axes after it (see ``monomials`` for the monomial order). Putting the batch
last keeps the gathers of whole coefficient rows contiguous, which is what makes a batch of B
stage expansions cost about as many numpy calls as one.

Indexing a DA indexes ``shape`` exactly like a numpy array (``x[0]`` of a state of shape (7, B) is
the first component of all B expansions), so dynamics written for numpy arrays of shape (nx, B)
run unchanged on DA. Arithmetic with floats and numpy arrays follows numpy broadcasting on
``shape``.
"""
from __future__ import annotations

import numbers
from collections.abc import Sequence

import numpy as np

from ..errors import DaddyError, DomainError
from .monomials import MonomialTables, tables


class DA:
    """A (batch of) truncated Taylor polynomial(s). See the module docstring for the layout."""

    __slots__ = ("c", "T")
    __array_ufunc__ = None  # numpy defers to our reflected operators (arr * da -> da.__rmul__)
    __array_priority__ = 100

    def __init__(self, coeffs: np.ndarray, tab: MonomialTables):
        if type(coeffs) is not np.ndarray or coeffs.dtype != float:
            coeffs = np.asarray(coeffs, dtype=float)
        if coeffs.shape[:1] != (tab.size,):
            raise DaddyError(
                f"DA coefficients must have leading axis {tab.size} (n={tab.n}, k={tab.k}), "
                f"got shape {coeffs.shape}")
        self.c = coeffs
        self.T = tab

    # ------------------------------------------------------------------ descriptors
    @property
    def n(self) -> int:
        return self.T.n

    @property
    def order(self) -> int:
        return self.T.k

    @property
    def shape(self) -> tuple:
        return self.c.shape[1:]

    @property
    def ndim(self) -> int:
        return self.c.ndim - 1

    def __len__(self) -> int:
        if not self.shape:
            raise TypeError("len() of a scalar DA")
        return self.shape[0]

    def __repr__(self) -> str:
        return f"DA(n={self.n}, order={self.order}, shape={self.shape})"

    def __getitem__(self, key) -> "DA":
        if type(key) is int:   # the common case in dynamics: x[0]
            return _wrap(self.c[:, key], self.T)
        if not isinstance(key, tuple):
            key = (key,)
        return _wrap(self.c[(slice(None),) + key], self.T)

    def __iter__(self):
        for i in range(len(self)):
            yield self[i]

    def copy(self) -> "DA":
        return DA(self.c.copy(), self.T)

    def reshape(self, *shape) -> "DA":
        if len(shape) == 1 and isinstance(shape[0], tuple):
            shape = shape[0]
        return DA(self.c.reshape((self.T.size,) + tuple(shape)), self.T)

    # ------------------------------------------------------------------ extraction
    @property
    def cons(self) -> np.ndarray:
        """Constant part, shape ``shape``."""
        return self.c[0]

    def linear(self) -> np.ndarray:
        """Order-1 coefficients = gradient, shape ``(*shape, n)``."""
        return np.moveaxis(self.c[1:self.n + 1], 0, -1)

    gradient = linear

    def hessian(self) -> np.ndarray:
        """Second derivatives, shape ``(*shape, n, n)`` (requires order >= 2)."""
        if self.order < 2:
            raise DaddyError("hessian() needs a DA of order >= 2")
        T = self.T
        q = np.moveaxis(self.c[T.block[2]], 0, -1)  # (*shape, n(n+1)/2)
        H = np.zeros(self.shape + (T.n, T.n))
        H[..., T.triu_i, T.triu_j] = q
        H[..., T.triu_j, T.triu_i] = q
        diag = np.arange(T.n)
        H[..., diag, diag] *= 2.0
        return H

    def derivative_tensor(self, degree: int) -> np.ndarray:
        """Coefficients of ``degree`` multiplied by the exponent factorials (partial derivatives)."""
        b = self.T.block[degree]
        f = self.T.factorial[b].reshape((-1,) + (1,) * self.ndim)
        return self.c[b] * f

    # ------------------------------------------------------------------ helpers
    def _check(self, other: "DA") -> None:
        if other.T is not self.T:
            raise DaddyError(
                f"cannot combine DA of (n={self.n}, order={self.order}) with "
                f"DA of (n={other.n}, order={other.order})")

    def _nilpotent(self) -> np.ndarray:
        d = self.c.copy()
        d[0] = 0.0
        return d

    # ------------------------------------------------------------------ arithmetic
    def __neg__(self) -> "DA":
        return _wrap(-self.c, self.T)

    def __pos__(self) -> "DA":
        return self

    # Each operator first takes the cases right-hand sides are made of -- a Python float, or a
    # DA of the same algebra and shape -- without the general path's conversions and broadcasts
    # (the same arithmetic: a third of an operation's cost on a small batch).
    def __add__(self, other) -> "DA":
        if type(other) is float:
            c = self.c.copy()
            c[0] += other
            return _wrap(c, self.T)
        if type(other) is DA and other.T is self.T and other.c.shape == self.c.shape:
            return _wrap(self.c + other.c, self.T)
        if isinstance(other, DA):
            self._check(other)
            a, b = _align(self.c, other.c)
            return _wrap(a + b, self.T)
        other = _as_array(other, "addend")
        c = _broadcast_coeffs(self.c, other)
        c[0] += other
        return _wrap(c, self.T)

    __radd__ = __add__

    def __sub__(self, other) -> "DA":
        if type(other) is float:
            c = self.c.copy()
            c[0] -= other
            return _wrap(c, self.T)
        if type(other) is DA and other.T is self.T and other.c.shape == self.c.shape:
            return _wrap(self.c - other.c, self.T)
        if isinstance(other, DA):
            self._check(other)
            a, b = _align(self.c, other.c)
            return _wrap(a - b, self.T)
        other = _as_array(other, "subtrahend")
        c = _broadcast_coeffs(self.c, other)
        c[0] -= other
        return _wrap(c, self.T)

    def __rsub__(self, other) -> "DA":
        if type(other) is float:
            c = -self.c
            c[0] += other
            return _wrap(c, self.T)
        other = _as_array(other, "minuend")
        c = -_broadcast_coeffs(self.c, other)
        c[0] += other
        return _wrap(c, self.T)

    def __mul__(self, other) -> "DA":
        if type(other) is float:
            return _wrap(self.c * other, self.T)
        if isinstance(other, DA):
            if other is self:   # x * x: the squares of distances in every gravity term
                return _wrap(_square(self.c, self.T), self.T)
            if other.T is not self.T:
                self._check(other)
            return _wrap(_mul(self.c, other.c, self.T), self.T)
        other = _as_array(other, "factor")
        return _wrap(_scale(self.c, other), self.T)

    __rmul__ = __mul__

    def __truediv__(self, other) -> "DA":
        if isinstance(other, DA):
            return self * other.reciprocal()
        other = _as_array(other, "divisor")
        if np.any(other == 0):
            raise DomainError("division of a DA by zero")
        return DA(_scale(self.c, 1.0 / other), self.T)

    def __rtruediv__(self, other) -> "DA":
        return self.reciprocal() * other

    def __pow__(self, p) -> "DA":
        if isinstance(p, DA):
            from .functions import exp, log
            return exp(p * log(self))
        if not isinstance(p, numbers.Real):
            raise DaddyError(f"DA power must be a real scalar, got {type(p).__name__}")
        if p == 0:
            return DA(_constant_like(self.c, 1.0), self.T)
        if p == 1:
            return self
        if p == 2:
            return self * self
        if p == 3:
            return self * self * self
        if p == 0.5:
            return self.sqrt()
        return self._power(float(p))

    # comparisons act on the constant part (branching in dynamics, e.g. step control)
    def __lt__(self, other):
        return self.cons < _cons(other)

    def __le__(self, other):
        return self.cons <= _cons(other)

    def __gt__(self, other):
        return self.cons > _cons(other)

    def __ge__(self, other):
        return self.cons >= _cons(other)

    def __abs__(self) -> "DA":
        s = np.sign(self.cons)
        if np.any(s == 0):
            raise DomainError("abs() of a DA whose constant part is 0 is not differentiable")
        return self * s

    # ------------------------------------------------------------------ elementary functions
    def series(self, derivs: Sequence[np.ndarray | float]) -> DA:
        """Compose the univariate Taylor series ``sum_j derivs[j] * (self - cons)**j``.

        Args:
            derivs: sequence of k + 1 arrays broadcastable to ``shape``: f^(j)(cons) / j!.
        """
        T = self.T
        k = T.k
        if k == 1:
            out = self.c * derivs[1]
            out[0] = derivs[0]
            return DA(out, T)
        if k == 2:
            # f0 + f1 d + f2 d^2: d^2's coefficients are a_i a_j, doubled off the diagonal
            # (the doubling is folded into f2, exactly: a power of two)
            n = T.n
            c = self.c
            out = c * derivs[1]
            out[0] = derivs[0]
            a1 = c[1:n + 1]
            out[n + 1:] += a1[T.triu_i] * a1[T.triu_j] * _times_offdiag2(derivs[2], T, c.ndim - 1)
            return _wrap(out, T)
        d = self._nilpotent()
        r = _constant_like(d, 0.0) + 0.0
        r[0] = derivs[k]
        for j in range(k - 1, -1, -1):
            r = _mul(r, d, T)
            r[0] += derivs[j]
        return DA(r, T)

    def reciprocal(self) -> "DA":
        a0 = self.cons
        if not (np.isfinite(a0) & (a0 != 0)).all():
            raise DomainError(f"1/x of a DA whose constant part is {_first_bad(a0, a0 != 0)}")
        inv = 1.0 / a0
        derivs = [inv]
        for _ in range(self.order):
            derivs.append(-derivs[-1] * inv)
        return self.series(derivs)

    def sqrt(self) -> "DA":
        a0 = self.cons
        if not (a0 > 0).all():
            raise DomainError(f"sqrt of a DA whose constant part is {_first_bad(a0, a0 > 0)} "
                              "(must be > 0)")
        return self._power(0.5, checked=True)

    def _power(self, p: float, checked: bool = False) -> "DA":
        a0 = self.cons
        integer = float(p).is_integer()
        if not checked and not integer and not (a0 > 0).all():
            raise DomainError(f"x**{p} of a DA whose constant part is {_first_bad(a0, a0 > 0)} "
                              "(must be > 0)")
        if integer and p < 0 and (a0 == 0).any():
            raise DomainError(f"x**{p} of a DA whose constant part is 0")
        inv = 1.0 / a0
        derivs = [a0 ** p]   # f^(j) / j! = C(p, j) a0^(p - j)
        for j in range(1, self.order + 1):
            derivs.append(derivs[-1] * inv * ((p - j + 1) / j))
        return self.series(derivs)

    def tanh(self) -> "DA":
        """tanh: its derivatives are polynomials in t = tanh(cons), P_{j+1} = P_j' (1 - t^2),
        so no exponential of a large argument overflows."""
        t = np.tanh(self.cons)
        P = np.polynomial.Polynomial([0.0, 1.0])
        one_minus = np.polynomial.Polynomial([1.0, 0.0, -1.0])
        derivs, fact = [t], 1.0
        for j in range(1, self.order + 1):
            P = P.deriv() * one_minus
            fact *= j
            derivs.append(P(t) / fact)
        return self.series(derivs)

    def exp(self) -> "DA":
        e = np.exp(self.cons)
        derivs = [e]
        for j in range(1, self.order + 1):
            derivs.append(derivs[-1] / j)
        return self.series(derivs)

    def log(self) -> "DA":
        a0 = self.cons
        if not np.all(a0 > 0):
            raise DomainError(f"log of a DA whose constant part is {_first_bad(a0, a0 > 0)} "
                              "(must be > 0)")
        inv = 1.0 / a0
        derivs = [np.log(a0)]
        for j in range(1, self.order + 1):
            derivs.append((-1.0) ** (j + 1) / j * inv ** j)
        return self.series(derivs)

    def _cyclic_series(self, phase: int) -> "DA":
        """sin (phase 0) or cos (phase 1): the derivatives cycle through s, c, -s, -c."""
        s, c = np.sin(self.cons), np.cos(self.cons)
        cyc = (s, c, -s, -c)
        derivs = []
        fact = 1.0
        for j in range(self.order + 1):
            fact *= max(j, 1)
            derivs.append(cyc[(j + phase) % 4] / fact)
        return self.series(derivs)

    def sin(self) -> "DA":
        return self._cyclic_series(0)

    def cos(self) -> "DA":
        return self._cyclic_series(1)

    def tan(self) -> "DA":
        return self.sin() / self.cos()

    def arctan(self) -> "DA":
        # atan(a) = atan(a0) + atan(z), z = (a - a0) / (1 + a0 a) has no constant part.
        a0 = self.cons
        z = (self - a0) / (1.0 + a0 * self)
        return _atan_nilpotent(z) + np.arctan(a0)


def _atan_nilpotent(z: DA) -> DA:
    """atan(z) for a DA with zero constant part: z - z^3/3 + z^5/5 - ..."""
    derivs = [np.zeros(z.shape)]
    for j in range(1, z.order + 1):
        derivs.append(np.full(z.shape, 0.0 if j % 2 == 0 else (-1.0) ** ((j - 1) // 2) / j))
    return z.series(derivs)


_new = object.__new__


def _wrap(c: np.ndarray, tab: MonomialTables) -> DA:
    """A DA around coefficients the kernels just built (a float array with leading axis
    ``tab.size``), without the public constructor's checks (a third of its cost)."""
    d = _new(DA)
    d.c = c
    d.T = tab
    return d


def _times_offdiag2(f, T: MonomialTables, ndim: int) -> np.ndarray:
    """f (broadcastable to a batch shape of ``ndim`` axes) times 2 on the off-diagonal degree-2
    monomials, 1 on the diagonal: shape (n(n+1)/2, *batch) up to broadcasting."""
    f = np.asarray(f, dtype=float)
    return T.sym_factor.reshape((-1,) + (1,) * max(ndim, f.ndim)) * f


# ---------------------------------------------------------------------- constructors
def variables(point, order: int = 2, n: int | None = None, first: int = 0) -> DA:
    """DA variables ``point[i] + dx_{first+i}``.

    Args:
        point: (m, *batch) expansion point(s) of m consecutive variables.
        order: truncation order k.
        n: total number of DA variables (default m).
        first: index of the DA variable attached to ``point[0]``.
    Returns:
        DA of shape (m, *batch).
    """
    point = _as_array(point, "point")
    if point.ndim == 0:
        point = point.reshape(1)
    m = point.shape[0]
    n = m if n is None else n
    if first < 0 or first + m > n:
        raise DaddyError(f"variables {first}..{first + m - 1} do not fit in n={n} DA variables")
    if not np.all(np.isfinite(point)):
        raise DaddyError("DA expansion point contains NaN or inf")
    tab = tables(n, order)
    c = np.zeros((tab.size,) + point.shape)
    c[0] = point
    idx = np.arange(m)
    c[1 + first + idx, idx] = 1.0
    return DA(c, tab)


def constant(value, n: int, order: int = 2) -> DA:
    """A DA with only a constant part, shape of ``value``."""
    value = _as_array(value, "value")
    tab = tables(n, order)
    c = np.zeros((tab.size,) + value.shape)
    c[0] = value
    return DA(c, tab)


# ---------------------------------------------------------------------- kernels
def _as_array(x, name: str) -> np.ndarray:
    if isinstance(x, np.ndarray):
        return x if x.dtype == float else x.astype(float)
    if isinstance(x, numbers.Real):
        return np.asarray(float(x))
    try:
        return np.asarray(x, dtype=float)
    except (TypeError, ValueError) as exc:
        raise DaddyError(f"cannot combine a DA with {name} of type {type(x).__name__}") from exc


def _cons(x):
    return x.cons if isinstance(x, DA) else x


def _first_bad(a0: np.ndarray, ok: np.ndarray):
    a0 = np.asarray(a0)
    bad = a0[~np.asarray(ok, dtype=bool)] if a0.ndim else a0
    return float(bad.flat[0]) if bad.size else float(np.asarray(a0).flat[0])


def _align(a: np.ndarray, b: np.ndarray):
    """Pad the batch axes so (M, *sa) and (M, *sb) broadcast on the batch shape."""
    if a.ndim < b.ndim:
        a = a.reshape(a.shape[:1] + (1,) * (b.ndim - a.ndim) + a.shape[1:])
    elif b.ndim < a.ndim:
        b = b.reshape(b.shape[:1] + (1,) * (a.ndim - b.ndim) + b.shape[1:])
    return a, b


def _scale(c: np.ndarray, s: np.ndarray) -> np.ndarray:
    if s.ndim >= c.ndim:
        c = c.reshape(c.shape[:1] + (1,) * (s.ndim - c.ndim + 1) + c.shape[1:])
    return c * s


def _broadcast_coeffs(c: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Copy of ``c`` broadcast to the batch shape of ``broadcast(c.shape[1:], s.shape)``."""
    shape = np.broadcast_shapes(c.shape[1:], s.shape)
    if shape == c.shape[1:]:
        return c.copy()
    c = c.reshape(c.shape[:1] + (1,) * (len(shape) - c.ndim + 1) + c.shape[1:])
    return np.broadcast_to(c, c.shape[:1] + shape).copy()


def _constant_like(c: np.ndarray, value: float) -> np.ndarray:
    out = np.zeros_like(c)
    out[0] = value
    return out


# below this many batch elements the generic product table (3 numpy calls) beats the block kernel
_SMALL_BATCH = 12


def _outer_sym(a1: np.ndarray, b1: np.ndarray, T: MonomialTables) -> np.ndarray:
    """Degree-2 coefficients of (a1 . dx)(b1 . dx) for linear parts a1, b1 of shape (n, *s)."""
    n = T.n
    F = np.empty((n * n + 1,) + a1.shape[1:])
    np.multiply(a1[:, None], b1[None, :], out=F[:-1].reshape((n, n) + a1.shape[1:]))
    F[-1] = 0.0
    return np.add(F[T.outer_a], F[T.outer_b])


def _square(a: np.ndarray, T: MonomialTables) -> np.ndarray:
    """Truncated square of a coefficient array (M, *s): at order 2 on a large batch, a * 2 a0
    (the constant halved back) plus the symmetric quadratic block a_i a_j (doubled off the
    diagonal) from one product of two gathers, instead of the general kernel's outer product.
    Bit-identical to ``_mul(a, a)``: every doubling is exact."""
    if T.k != 2 or a[0].size <= _SMALL_BATCH:
        return _mul(a, a, T)
    n = T.n
    out = a * (2.0 * a[0])
    out[0] *= 0.5
    a1 = a[1:n + 1]
    out[n + 1:] += a1[T.triu_i] * a1[T.triu_j] * _times_offdiag2(1.0, T, a.ndim - 1)
    return out


def _mul(a: np.ndarray, b: np.ndarray, T: MonomialTables) -> np.ndarray:
    """Truncated product of two coefficient arrays (M, *sa) x (M, *sb)."""
    if a.shape != b.shape:
        a, b = _align(a, b)
        shape = (T.size,) + np.broadcast_shapes(a.shape[1:], b.shape[1:])
        a, b = np.broadcast_to(a, shape), np.broadcast_to(b, shape)
    n = T.n
    if T.k == 2 and a[0].size > _SMALL_BATCH:
        # Specialised order-2 kernel: a b0 + a0 b is right in every block but the constant
        # (2 a0 b0, halved), and the quadratic block gains the product of the linear parts.
        out = a * b[0]
        out += a[0] * b
        out[0] *= 0.5
        out[n + 1:] += _outer_sym(a[1:n + 1], b[1:n + 1], T)
        return out
    if T.k == 1 and a[0].size > _SMALL_BATCH:
        out = np.empty(a.shape)
        np.multiply(a[0], b[0], out=out[0, ...])
        np.multiply(a[1:], b[0], out=out[1:])
        out[1:] += a[0] * b[1:]
        return out
    # generic product table: fewest numpy calls, best for small batches and orders > 2
    prod = a[T.pair_i] * b[T.pair_j]
    return np.add.reduceat(prod, T.pair_starts, axis=0)
