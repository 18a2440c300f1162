"""Polynomial maps: evaluation at displaced points, composition, and convergence radius.

A "map" is a DA of shape ``(m, *batch)``: m output components, each a polynomial in the DA's n
variables, for a batch of expansion points (e.g. one flow map per trajectory stage).
"""
from __future__ import annotations

import functools
import math

import numpy as np

from ..errors import DaddyError
from .core import DA, _mul
from .monomials import MonomialTables, tables


_ONE = np.ones(1)


def monomial_values(dv: np.ndarray, T: MonomialTables) -> np.ndarray:
    """Values of all monomials at displacements ``dv``.

    Args:
        dv: (n, *batch) displacement of each variable from the expansion point.
    Returns:
        (M, *batch) monomial values (the constant monomial is 1).
    """
    dv = np.asarray(dv, dtype=float)
    if dv.shape[:1] != (T.n,):
        raise DaddyError(f"displacement must have leading axis n={T.n}, got shape {dv.shape}")
    if dv.ndim == 1 and T.k == 2:
        return np.concatenate((_ONE, dv, np.multiply.outer(dv, dv).ravel()[T.outer_a]))
    mv = np.empty((T.size,) + dv.shape[1:])
    mv[0] = 1.0
    mv[1:T.n + 1] = dv
    if T.k >= 2:
        b = T.block[2]
        np.multiply(dv[T.triu_i], dv[T.triu_j], out=mv[b])
    for d in range(3, T.k + 1):
        b = T.block[d]
        np.multiply(mv[T.parent[b]], dv[T.parent_var[b]], out=mv[b])
    return mv


def evaluate(p: DA, dv: np.ndarray) -> np.ndarray:
    """Evaluate the polynomial(s) at displacement(s) ``dv`` from their expansion point.

    Args:
        p: DA of shape (m, *batch) (or any shape).
        dv: (n,) one displacement for all, or (n, *batch) one per batch element.
    Returns:
        array of shape ``p.shape`` (broadcast with the batch of ``dv``).
    """
    mv = monomial_values(dv, p.T)
    if mv.ndim == 1:
        # one point for every polynomial: a matrix-vector product
        return (mv @ p.c.reshape(p.T.size, -1)).reshape(p.shape)
    c, m = p.c, mv
    if c.ndim == 3 and m.ndim == 2 and c.shape[2] == m.shape[1]:
        return np.einsum("mxb,mb->xb", c, m)  # a batch of maps, one point each
    # align mv's batch with the trailing axes of p's shape
    m = m.reshape(m.shape[:1] + (1,) * (c.ndim - m.ndim) + m.shape[1:]) if c.ndim > m.ndim else m
    return np.einsum("m...,m...->...", c, m) if c.shape == m.shape else (c * m).sum(axis=0)


def compose(p: DA, g: DA) -> DA:
    """Plug the map ``g`` into ``p``: returns the DA of p(g - g.cons ... ) i.e. P_p(g(dy)).

    ``p``'s n variables are displacements; ``g`` (shape (n, *batch)) gives each displacement as a
    polynomial in ``g``'s variables. The constant part of ``g`` is the displacement at which ``p``
    is evaluated, so ``compose(p, shift + identity)`` re-centres ``p`` at ``shift``.

    Args:
        p: DA of shape (*sp) in n variables.
        g: DA of shape (n, *sg) in any number of variables.
    Returns:
        DA of shape broadcast(sp, sg) in ``g``'s variables.
    """
    T, G = p.T, g.T
    if g.shape[:1] != (T.n,):
        raise DaddyError(f"compose: inner map must have {T.n} components, got shape {g.shape}")
    # monomials of g as DA: mono[m] = mono[parent[m]] * g[parent_var[m]]
    mono = np.empty((G.size, T.size) + g.shape[1:])
    mono[:, 0] = 0.0
    mono[0, 0] = 1.0
    mono[:, 1:T.n + 1] = g.c
    sparse = _sparse_components(g.c, G)
    dense = [v for v in range(T.n) if v not in sparse]
    for d in range(2, T.k + 1):
        b = T.block[d]
        if not sparse:
            mono[:, b] = _mul(mono[:, T.parent[b]], g.c[:, T.parent_var[b]], G)
            continue
        cols = np.arange(b.start, b.stop)
        at = cols[np.isin(T.parent_var[b], dense)]
        if at.size:
            mono[:, at] = _mul(mono[:, T.parent[at]], g.c[:, T.parent_var[at]], G)
        for v, nz in sparse.items():
            at = cols[T.parent_var[b] == v]
            if at.size:
                mono[:, at] = _times_sparse(mono[:, T.parent[at]], g.c[:, v], nz, G)
    # out[q, *s] = sum_m p[m, *sp] * mono[q, m, *sg]
    pc = p.c
    sp, sg = pc.shape[1:], g.shape[1:]
    shape = np.broadcast_shapes(sp, sg)
    pc = pc.reshape((T.size,) + (1,) * (len(shape) - len(sp)) + sp)
    mono = mono.reshape(mono.shape[:2] + (1,) * (len(shape) - len(sg)) + sg)
    out = np.einsum("m...,qm...->q...", np.broadcast_to(pc, (T.size,) + shape),
                    np.broadcast_to(mono, mono.shape[:2] + shape), optimize=False)
    return DA(out, G)


# a component of an inner map with at most this many nonzero coefficients (an identity
# variable has one, a shifted one two) is multiplied monomial by monomial in ``compose``
_SPARSE_TERMS = 3


def _sparse_components(gc: np.ndarray, G: MonomialTables) -> dict:
    """{component v: its nonzero monomials} of the inner map's coefficients gc (M, n, *s) for
    the components with at most ``_SPARSE_TERMS`` of them (over the whole batch)."""
    if G.k < 3:
        return {}
    nonzero = np.any(gc != 0.0, axis=tuple(range(2, gc.ndim))) if gc.ndim > 2 else gc != 0.0
    counts = nonzero.sum(axis=0)
    return {v: np.flatnonzero(nonzero[:, v]) for v in range(gc.shape[1])
            if counts[v] <= _SPARSE_TERMS}


def _times_sparse(a: np.ndarray, b: np.ndarray, nz: np.ndarray, G: MonomialTables) -> np.ndarray:
    """The truncated product of a (M, *sa) with b (M, *sb), b nonzero only on the monomials
    ``nz``: the sum over them of b_q times a shifted by monomial q (``_shifts``)."""
    shape = (G.size,) + np.broadcast_shapes(a.shape[1:], b.shape[1:])
    out = np.zeros(shape)
    for q in nz.tolist():
        source, target = _shifts(G.n, G.k, q)
        out[target] += a[source] * b[q]
    return out


@functools.lru_cache(maxsize=None)
def _shifts(n: int, k: int, q: int) -> tuple:
    """(source, target): monomial source times monomial q is monomial target (degree <= k)."""
    T = tables(n, k)
    hit = T.pair_j == q
    return T.pair_i[hit], T.pair_target[hit]


def shift(p: DA, dv) -> DA:
    """Re-centre ``p`` at displacement ``dv`` (shape (n,) or (n, *batch)): p(dv + dx).

    Order 2 (the solver's maps) in closed form: the value is p(dv), the gradient gains the
    quadratic terms' derivative at dv, the quadratic terms are unchanged -- the same truncated
    polynomial as the general composition, for a few BLAS calls. Other orders by Taylor's
    shift one variable at a time (``_taylor_shift``): the same polynomial as ``compose`` with
    the shifted identity, without its products of polynomials.
    """
    dv = np.asarray(dv, dtype=float)
    T, c = p.T, p.c
    if dv.shape[:1] != (T.n,):
        raise DaddyError(f"shift: displacement must have leading axis n={T.n}, got {dv.shape}")
    if T.k == 2 and c.ndim == 3 and dv.ndim == 2 and c.shape[2] == dv.shape[1]:
        return DA(_shift_stages(c, dv, T), T)
    shape = np.broadcast_shapes(c.shape[1:], dv.shape[1:])
    c = np.broadcast_to(c, (T.size,) + shape)
    d = np.broadcast_to(dv.reshape(dv.shape[:1] + (1,) * (len(shape) - dv.ndim + 1)
                                   + dv.shape[1:]), (T.n,) + shape)
    if T.k != 2:
        return DA(_taylor_shift(c, d, T), T)
    n, q = T.n, c[T.block[2]]                                     # (n(n+1)/2, *shape)
    out = np.empty((T.size,) + shape)
    out[0] = evaluate(DA(c, T), d)
    out[1:n + 1] = _gradient_at(c, q, d[T.triu_i], d[T.triu_j], n)
    out[n + 1:] = q
    return DA(out, T)


@functools.lru_cache(maxsize=None)
def _variable_shifts(n: int, k: int) -> tuple:
    """For each variable i, for j = 1..k: (target, source, weight) with monomial source =
    target * x_i^j and weight = C(e_i(target) + j, j), over the targets of degree <= k - j --
    the terms of p(.., x_i + a, ..) = sum_j weight * c[source] * a^j x^target."""
    T = tables(n, k)
    index = {tuple(e): m for m, e in enumerate(T.exponents.tolist())}
    degree = T.exponents.sum(axis=1)
    out = []
    for i in range(n):
        per_power = []
        for j in range(1, k + 1):
            target = np.flatnonzero(degree <= k - j)
            e = T.exponents[target].copy()
            e[:, i] += j
            source = np.array([index[tuple(row)] for row in e.tolist()], dtype=np.int64)
            weight = np.array([math.comb(int(b) + j, j) for b in T.exponents[target, i]],
                              dtype=float)
            per_power.append((target, source, weight))
        out.append(tuple(per_power))
    return tuple(out)


def _taylor_shift(c: np.ndarray, d: np.ndarray, T: MonomialTables) -> np.ndarray:
    """Coefficients (M, *shape) of p(d + x) from p's c (M, *shape), d (n, *shape): the shift
    by one variable at a time, each a sum over the powers of its displacement (exact in
    exact arithmetic; the truncation is p's own)."""
    out = np.array(c, dtype=float)
    extra = (1,) * (c.ndim - 1)
    for i, per_power in enumerate(_variable_shifts(T.n, T.k)):
        a = d[i]
        if not np.any(a):
            continue
        prev, power = out, np.ones_like(a)
        out = prev.copy()
        for target, source, weight in per_power:
            power = power * a
            out[target] += prev[source] * weight.reshape((-1,) + extra) * power
    return out


def _gradient_at(c: np.ndarray, q: np.ndarray, di, dj, n: int) -> np.ndarray:
    """The gradient (n, *shape) at a displacement of order-2 polynomials with coefficients c
    (M, *shape) and degree-2 block q: d/dz_a of c_ab z_a z_b at dv is c_ab dv_b (and c_ab dv_a
    for b; 2 c_aa dv_a when a = b), summed by the scatter matrices. di, dj: the displacement
    of each degree-2 monomial's first and second variable, broadcastable to q."""
    lin = (q * dj).reshape(len(q), -1)
    lin2 = (q * di).reshape(len(q), -1)
    grad = _SCATTER_I[n] @ lin + _SCATTER_J[n] @ lin2
    return c[1:n + 1] + grad.reshape(c[1:n + 1].shape)


# batch size from which ``_shift_stages`` accumulates the gradient one monomial at a time
# (a fixed ~0.25 ms of Python for 110 accumulations, then the least memory traffic: B = 110
# 0.38 ms against 0.69 ms with the scatter products, B = 4960 13 ms against 30; B = 10 0.28
# against 0.06 ms)
_SHIFT_LOOP_MIN_BATCH = 64


def _shift_stages(c: np.ndarray, dv: np.ndarray, T) -> np.ndarray:
    """``shift``'s closed form for a batch of maps with one displacement each -- c (M, m, B)
    the coefficients of m components at B expansion points, dv (n, B) -- without broadcasting
    dv over the m components first (the general path evaluates the value at an (n, m, B)
    displacement: 70 ms for 4960 stages, where this takes 13). Small batches take
    ``_gradient_at``'s scatter products; large ones accumulate one monomial at a time (each
    adds c_ab dv_b to variable a and c_ab dv_a to b)."""
    n, m, B = T.n, c.shape[1], c.shape[2]
    q = c[T.block[2]]                                             # (n(n+1)/2, m, B)
    out = np.empty_like(c)
    out[0] = np.einsum("mxb,mb->xb", c, monomial_values(dv, T))
    out[n + 1:] = q
    grad = out[1:n + 1]
    if B < _SHIFT_LOOP_MIN_BATCH:   # two scatter products over (n(n+1)/2, m B) temporaries
        grad[...] = _gradient_at(c, q, dv[T.triu_i][:, None, :], dv[T.triu_j][:, None, :], n)
        return out
    grad[...] = c[1:n + 1]          # one accumulation per monomial and variable of its pair
    tmp = np.empty((m, B))
    for k, (a, b) in enumerate(zip(T.triu_i.tolist(), T.triu_j.tolist())):
        grad[a] += np.multiply(q[k], dv[b], out=tmp)
        grad[b] += np.multiply(q[k], dv[a], out=tmp)
    return out


class _Scatter(dict):
    """(n, n(n+1)/2) 0/1 matrices summing the degree-2 monomials' terms onto their first
    (``_SCATTER_I``) or second (``_SCATTER_J``) variable, built once per n."""

    def __init__(self, second: bool):
        super().__init__()
        self.second = second

    def __missing__(self, n: int) -> np.ndarray:
        i, j = np.triu_indices(n)
        m = np.zeros((n, len(i)))
        m[j if self.second else i, np.arange(len(i))] = 1.0
        self[n] = m
        return m


_SCATTER_I, _SCATTER_J = _Scatter(False), _Scatter(True)


def radius(p: DA, eps: float, axis: int | None = 0) -> np.ndarray:
    """Convergence-radius estimate of the polynomial(s) at accuracy ``eps``.

    Rule: with a_i the sum of |coefficients| of order i, fit log a_i = alpha + beta * i over the
    orders 1..k by least squares, extrapolate the first neglected order a_{k+1}, and return
    r = (eps / a_{k+1}) ** (1 / (k + 1)). At order 2 the fit passes through both points and this
    is exactly r = (eps * a1 / a2**2) ** (1/3). A component without order-1 or without order-2
    (top two orders at k > 2) terms is treated as exact: r = +inf.

    Args:
        p: DA of shape (m, *batch).
        eps: accuracy (same units as the polynomial's values).
        axis: component axis of ``p.shape`` to take the minimum over (None: per component).
    Returns:
        radius per batch element (or per component when ``axis`` is None).
    """
    T = p.T
    if T.k < 2:
        raise DaddyError("radius() needs order >= 2")
    a = np.stack([np.abs(p.c[T.block[d]]).sum(axis=0) for d in range(1, T.k + 1)])  # (k, *shape)
    with np.errstate(divide="ignore", invalid="ignore"):
        if T.k == 2:
            r = np.cbrt(eps * a[0] / (a[1] * a[1]))
        else:
            orders = np.arange(1, T.k + 1, dtype=float)
            la = np.log(a)
            om = orders.mean()
            w = (orders - om).reshape((-1,) + (1,) * (a.ndim - 1))
            beta = (w * (la - la.mean(axis=0))).sum(axis=0) / (w * w).sum()
            alpha = la.mean(axis=0) - beta * om
            r = (eps / np.exp(alpha + beta * (T.k + 1))) ** (1.0 / (T.k + 1))
        exact = (a[0] == 0) | (a[-1] == 0)
        r = np.where(exact | ~np.isfinite(r), np.inf, r)
    if axis is None:
        return r
    return r.min(axis=axis)


__all__ = ["monomial_values", "evaluate", "compose", "shift", "radius"]
