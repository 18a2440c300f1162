"""Uncertainty propagation without sampling (issue 47): the terminal state of a flight as a
polynomial in the initial-state error, through the problem's own stage maps on DA and, between
the nodes, the solution's feedback laws (``daddy_core.policy``), then its mean and covariance
in closed form for a Gaussian error.

    dx_0 ~ N(0, P0)
    x_{k+1} = f_k(x_k, U_k + law_k(x_k - X_k))      (open loop where a stage has no law)
    x_N - X_N = p(dx_0),  a polynomial of order k in nx variables

Moments: with dx_0 = C xi (C C^T = P0, xi standard normal) the polynomial is one in xi, whose
monomial moments are the products of the one-dimensional ones, E[xi^e] = (e - 1)!! for even e
and 0 for odd; the covariance takes the products p_i p_j in an algebra of order 2k, so it is
exact for the polynomial (k <= 3, the DA engine's order 6). What it leaves out is the flow's
terms above order k, which the test measures against a Monte Carlo of the same flight.
Initial-state errors only; execution errors are not modelled here.
"""
from __future__ import annotations

import numpy as np

from .da.core import DA, _mul, constant, variables
from .da.maps import compose
from .da.monomials import MAX_ORDER, tables
from .errors import DaddyError
from .problem import Problem


def terminal_polynomial(problem: Problem, X, U, policy=None, order: int = 2) -> DA:
    """x_N - X_N as a polynomial (DA (nx,), nx variables, ``order``) of the initial-state
    deviation, flying U (N, nu) from X[0] (N+1, nx), corrected by ``policy``'s laws where it has
    them (None: open loop)."""
    X, U = np.asarray(X, float), np.asarray(U, float)
    nx, N = problem.nx, problem.N
    if not (isinstance(order, int) and 1 <= order <= MAX_ORDER // 2):
        raise DaddyError(f"uncertainty order must be an integer in [1, {MAX_ORDER // 2}], got "
                         f"{order!r}")
    x = variables(X[0][:, None], order=order)                      # (nx, 1)
    dt, t0 = problem.stage_dt, problem.stage_t0
    for k in range(N):
        if policy is not None and policy.has_law[k]:
            if policy.order > order:
                raise DaddyError(f"uncertainty: the policy's order {policy.order} exceeds the "
                                 f"propagation's {order}")
            u = policy.flown(k, x - X[k][:, None])                    # (nu, 1)
        else:
            u = constant(U[k][:, None], nx, order)
        x = problem.step(x, u, dt[k:k + 1], t0[k:k + 1])
    return x[:, 0] - X[-1]


def monte_carlo(problem: Problem, X, U, policy, cov, samples: int,
                rng: np.random.Generator) -> np.ndarray:
    """The same flight as ``terminal_polynomial``'s, sampled: ``samples`` initial deviations
    drawn from N(0, cov), each flown through the problem's stages (the laws where ``policy``
    has them, unclipped, as the polynomial flies them). Returns the deviations (nx, S) and the
    terminal deviations x_N - X_N (nx, S)."""
    X, U = np.asarray(X, float), np.asarray(U, float)
    dx0 = rng.multivariate_normal(np.zeros(problem.nx), cov, size=samples,
                                  method="eigh").T
    x = X[0][:, None] + dx0
    for k in range(problem.N):
        u = (policy.thrust(k, x) if policy is not None and policy.has_law[k]
             else np.repeat(U[k][:, None], samples, axis=1))
        x = problem.step(x, u, np.repeat(problem.stage_dt[k], samples),
                         np.repeat(problem.stage_t0[k], samples))
    return dx0, x - X[-1][:, None]


def gaussian_moments(p: DA, cov) -> tuple[np.ndarray, np.ndarray]:
    """Mean (m,) and covariance (m, m) of the polynomial p (DA (m,), n variables, order
    k <= 3) of a Gaussian deviation N(0, cov), cov (n, n), in closed form (module
    docstring)."""
    n, k = p.T.n, p.T.k
    cov = np.asarray(cov, float)
    if cov.shape != (n, n) or not np.allclose(cov, cov.T):
        raise DaddyError(f"covariance must be a symmetric ({n}, {n}) matrix, got {cov.shape}")
    if 2 * k > MAX_ORDER:
        raise DaddyError(f"gaussian_moments needs order <= {MAX_ORDER // 2}, got {k}")
    w, V = np.linalg.eigh(cov)
    if w.min() < -1e-12 * max(1.0, w.max()):
        raise DaddyError("covariance must be positive semi-definite")
    C = V * np.sqrt(np.clip(w, 0.0, None))                          # C C^T = cov
    g = np.zeros((p.T.size, n))
    g[1:n + 1] = C.T                                                 # dx_i = sum_j C_ij xi_j
    q = compose(p, DA(g, p.T))                                       # in xi
    T2 = tables(n, 2 * k)
    c = np.zeros((T2.size,) + q.shape)
    c[:q.T.size] = q.c                                               # graded: the same prefix
    moments = _standard_normal_moments(T2.exponents)
    mean = moments @ c.reshape(T2.size, -1)
    m = q.shape[0]
    second = np.empty((m, m))
    for i in range(m):
        prod = _mul(c[:, i:i + 1], c, T2)                            # (M2, m): q_i q_j
        second[i] = moments @ prod
    covariance = second - np.outer(mean, mean)
    return mean, 0.5 * (covariance + covariance.T)


def _standard_normal_moments(exponents: np.ndarray) -> np.ndarray:
    """E[xi^e] of each monomial for independent standard normals: prod (e_i - 1)!!, 0 if any
    e_i is odd."""
    def one(e):
        return 0.0 if e % 2 else float(np.prod(np.arange(e - 1, 0, -2))) if e else 1.0
    table = np.array([[one(e) for e in range(int(exponents.max()) + 1)]])
    return np.prod(table[0][exponents], axis=1)


__all__ = ["terminal_polynomial", "monte_carlo", "gaussian_moments"]
