"""Calculus on polynomial maps (issue 47): the partial derivative of a DA, a partial
evaluation (some variables fixed), and the inverse of a map (DACE's fixed-point algorithm).

These are the operations of the DA-HDDP backward sweep on polynomials (Maestrini et al.,
sec. III: composition, differentiation and map inversion give the order-(k-1) feedback laws);
``maps.compose`` is the fourth.
"""
from __future__ import annotations

import functools

import numpy as np

from ..errors import DaddyError
from .core import DA, _wrap
from .maps import compose
from .monomials import tables

# the largest condition number a system is solved with where its answer needs 6 significant
# digits (cond * eps <= 1e-6): the feedback laws' inversions (``policy.LAW_MAX_CONDITION``) and
# the swept multipliers' step (``solver.multiplier_sweep``); docs/design-notes.md, "laws need
# digits"
SIX_DIGITS_CONDITION = 1e-6 / np.finfo(float).eps


def derivative(p: DA, i: int) -> DA:
    """dp/dx_i, a polynomial of order k - 1 in the same algebra (its degree-k coefficients
    are zero): the monomial x^a x_i of p gives (a_i + 1) x^a.

    Args:
        p: DA of any shape in n variables, order k.
        i: the variable, 0 <= i < n.
    Returns:
        DA of p's shape and algebra.
    """
    T = p.T
    if not (isinstance(i, (int, np.integer)) and 0 <= i < T.n):
        raise DaddyError(f"derivative: variable index must be an integer in [0, {T.n}), got {i!r}")
    target, source, factor = _derivative_table(T.n, T.k, int(i))
    c = np.zeros_like(p.c)
    c[target] = p.c[source] * factor.reshape((-1,) + (1,) * (p.c.ndim - 1))
    return _wrap(c, T)


@functools.lru_cache(maxsize=None)
def _derivative_table(n: int, k: int, i: int) -> tuple:
    """(target, source, factor): coefficient ``source`` of x^a x_i lands on ``target`` (x^a)
    times ``factor`` = a_i + 1, for every monomial x^a of degree < k."""
    T = tables(n, k)
    index = {tuple(e): m for m, e in enumerate(T.exponents.tolist())}
    target, source, factor = [], [], []
    for m, e in enumerate(T.exponents.tolist()):
        if sum(e) >= k:
            continue
        up = list(e)
        up[i] += 1
        target.append(m)
        source.append(index[tuple(up)])
        factor.append(float(up[i]))
    return np.array(target, int), np.array(source, int), np.array(factor)


def partial_evaluate(p: DA, fixed: dict) -> DA:
    """p with the variables ``fixed`` {i: displacement} set, the others still free: a DA in
    the same algebra that no longer depends on the fixed variables (their displacements are
    from the expansion point, as ``maps.evaluate`` takes them).

    Args:
        p: DA of any shape in n variables.
        fixed: {variable index: displacement (a float, or an array broadcast with p's batch)}.
    """
    T = p.T
    if not fixed:
        return p
    bad = [i for i in fixed if not (isinstance(i, (int, np.integer)) and 0 <= i < T.n)]
    if bad:
        raise DaddyError(f"partial_evaluate: variable indices must be integers in [0, {T.n}), "
                         f"got {bad[0]!r}")
    values = {int(i): np.asarray(v, float) for i, v in fixed.items()}
    batch = np.broadcast_shapes(*[v.shape for v in values.values()])
    g = np.zeros((T.size, T.n) + batch)
    g[1 + np.arange(T.n), np.arange(T.n)] = 1.0          # the identity: x_j -> x_j
    for i, v in values.items():
        if not np.all(np.isfinite(v)):
            raise DaddyError(f"partial_evaluate: the displacement of variable {i} is not finite")
        g[1 + i, i] = 0.0
        g[0, i] = v
    return compose(p, DA(g, T))


def invert(m: DA, max_condition: float | None = None) -> DA:
    """The inverse of the map m - m(0): the map N (constant part zero) with
    m(N(dy)) = m(0) + dy to the algebra's order, dy the displacement of the image from m(0).

    DACE's fixed point (Berz): with m = m(0) + L + NL (L linear, NL of degree >= 2),
    N <- L^-1 (I - NL o N), starting from L^-1; each pass makes one more order exact, so
    k - 1 passes give order k.

    Args:
        m: DA of shape (n, *batch) in n variables (a map of the space onto itself, one per
            batch element).
        max_condition: the largest condition number of the linear part taken as invertible
            (default 1 / eps: numerically singular only; a caller needing digits in the inverse
            asks for fewer).
    Returns:
        DA of m's shape and algebra.
    Raises:
        DaddyError: m is not square, or its linear part is singular (not invertible there).
    """
    T = m.T
    if m.shape[:1] != (T.n,):
        raise DaddyError(f"invert: a map of {T.n} variables needs {T.n} components, got shape "
                         f"{m.shape}")
    batch = m.shape[1:]
    lin = np.moveaxis(m.c[1:T.n + 1], (0, 1), (-1, -2))   # (*batch, n_out, n_in)
    cond = np.linalg.cond(lin)
    limit = 1.0 / np.finfo(float).eps if max_condition is None else max_condition
    if not np.all(np.isfinite(cond) & (cond < limit)):
        raise DaddyError(f"invert: the map's linear part is singular (condition number "
                         f"{np.max(cond):.3g}): the map has no inverse at its expansion point")
    inv = np.linalg.inv(lin)                               # (*batch, n_in, n_out)

    def apply_inverse(c):   # L^-1 applied to the component axis of coefficients (M, n, *batch)
        return np.einsum("...ij,mj...->mi...", inv, c)
    nonlinear = m.c.copy()
    nonlinear[:T.n + 1] = 0.0
    nonlinear = _wrap(nonlinear, T)
    identity = np.zeros((T.size, T.n) + batch)
    identity[1 + np.arange(T.n), np.arange(T.n)] = 1.0
    n_c = apply_inverse(identity)
    for _ in range(T.k - 1):
        n_c = apply_inverse(identity - compose(nonlinear, _wrap(n_c, T)).c)
    return _wrap(n_c, T)


__all__ = ["derivative", "partial_evaluate", "invert"]
