"""Monomial bookkeeping for truncated Taylor polynomials in ``n`` variables to order ``k``.

Coefficients are stored in graded order: the constant, then the ``n`` linear monomials
(variable 0, 1, ...), then the degree-2 monomials x_i x_j (i <= j) in row-major upper-triangular
order, then degree 3, ... Each degree block lists the sorted index tuples produced by
``itertools.combinations_with_replacement(range(n), d)``, so the order-2 block is exactly
``numpy.triu_indices(n)``.

Every table here depends only on ``(n, k)`` and is immutable; ``tables(n, k)`` memoises them.
"""
from __future__ import annotations

import functools
import itertools
import math
from dataclasses import dataclass

import numpy as np

from ..errors import DaddyError

MAX_ORDER = 6
MAX_VARIABLES = 64


@dataclass(frozen=True)
class MonomialTables:
    """Index tables for one (n variables, order k) algebra.

    Attributes:
        n, k: number of variables and truncation order.
        size: number of monomials M = C(n + k, k).
        exponents: (M, n) exponent of each variable in each monomial.
        block: list of k + 1 slices; ``block[d]`` selects the degree-d monomials.
        parent, parent_var: (M,) for degree >= 1, monomial m = parent[m] * x[parent_var[m]];
            -1 for the constant.
        pair_i, pair_j, pair_target: products of monomials i and j (deg i + deg j <= k) that land
            on monomial ``pair_target``; sorted by target so ``np.add.reduceat`` can sum them.
        pair_starts: (M,) start of each target's run in the pair arrays.
        triu_i, triu_j: (n(n+1)/2,) the variable pair of each degree-2 monomial.
        offdiag: (n(n+1)/2,) True where triu_i != triu_j.
        outer_a, outer_b: rows of a flattened outer product summing to each degree-2 product.
        sym_factor: (n(n+1)/2,) 2.0 off the diagonal, 1.0 on it.
        factorial: (M,) product of factorials of the exponents (coefficient -> derivative factor).
    """

    n: int
    k: int
    size: int
    exponents: np.ndarray
    block: tuple
    parent: np.ndarray
    parent_var: np.ndarray
    pair_i: np.ndarray
    pair_j: np.ndarray
    pair_target: np.ndarray
    pair_starts: np.ndarray
    triu_i: np.ndarray
    triu_j: np.ndarray
    offdiag: np.ndarray
    factorial: np.ndarray
    outer_a: np.ndarray
    outer_b: np.ndarray
    sym_factor: np.ndarray


@functools.lru_cache(maxsize=64)
def tables(n: int, k: int) -> MonomialTables:
    """Build (once) the monomial tables for ``n`` variables at order ``k``."""
    if not (isinstance(n, (int, np.integer)) and 1 <= n <= MAX_VARIABLES):
        raise DaddyError(f"DA variable count n must be an integer in [1, {MAX_VARIABLES}], got {n!r}")
    if not (isinstance(k, (int, np.integer)) and 1 <= k <= MAX_ORDER):
        raise DaddyError(f"DA order k must be an integer in [1, {MAX_ORDER}], got {k!r}")
    n, k = int(n), int(k)
    monos: list[tuple[int, ...]] = []
    blocks = []
    for d in range(k + 1):
        start = len(monos)
        monos.extend(itertools.combinations_with_replacement(range(n), d))
        blocks.append(slice(start, len(monos)))
    index = {m: i for i, m in enumerate(monos)}
    size = len(monos)
    exponents = np.zeros((size, n), dtype=np.int64)
    for i, m in enumerate(monos):
        for v in m:
            exponents[i, v] += 1
    parent = np.full(size, -1)
    parent_var = np.full(size, -1)
    for i, m in enumerate(monos):
        if m:
            parent[i] = index[m[:-1]]
            parent_var[i] = m[-1]
    pi, pj, pt = [], [], []
    for i, a in enumerate(monos):
        # (the monomials of degree <= k - deg a: the first blocks, in graded order)
        for j, b in enumerate(monos[:blocks[k - len(a)].stop]):
            pi.append(i)
            pj.append(j)
            pt.append(index[tuple(sorted(a + b))])
    order = np.argsort(pt, kind="stable")
    pair_i = np.asarray(pi)[order]
    pair_j = np.asarray(pj)[order]
    pair_target = np.asarray(pt)[order]
    pair_starts = np.searchsorted(pair_target, np.arange(size))
    ti, tj = np.triu_indices(n)
    fact = np.array([np.prod([math.factorial(int(e)) for e in row]) for row in exponents], dtype=float)
    return MonomialTables(
        n=n, k=k, size=size, exponents=exponents, block=tuple(blocks),
        parent=parent, parent_var=parent_var,
        pair_i=pair_i, pair_j=pair_j, pair_target=pair_target, pair_starts=pair_starts,
        triu_i=ti, triu_j=tj, offdiag=ti != tj, factorial=fact,
        # rows of the flattened outer product a1 (x) b1 (n*n rows + one zero row at n*n) whose
        # sum gives each degree-2 coefficient: (i, j) and (j, i) off the diagonal, (i, i) once.
        outer_a=ti * n + tj, outer_b=np.where(ti != tj, tj * n + ti, n * n),
        # (n(n+1)/2,) 2 off the diagonal, 1 on it: (a1 . dx)^2 has coefficients sym_factor a_i a_j
        sym_factor=np.where(ti != tj, 2.0, 1.0),
    )
