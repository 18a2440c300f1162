"""The augmented Lagrangian of paper eq. 8: multipliers, the penalty, augmented costs.

    J~ = sum_k [ l(x_k, u_k) + (lam_k + I_mu,k / 2 g_k) . g_k ]
         + phi(x_N) + (lam_t + I_mu,t / 2 g_t) . g_t

Written once for floats and DA (the DDP model expands these same functions); the outer loop that
updates the multipliers (eq. 9) is ``aul``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..da import functions as dm
from ..problem import Problem


@dataclass
class Multipliers:
    """AUL duals and penalties (paper eq. 8-9): path (n_c, N) and terminal (n_t,)."""

    lam: np.ndarray
    mu: np.ndarray
    lam_t: np.ndarray
    mu_t: np.ndarray
    n_ineq: int
    n_tineq: int

    @classmethod
    def initial(cls, problem: Problem, mu0: float) -> "Multipliers":
        """Zero duals and penalties mu0, sized by one evaluation of the constraints."""
        x = problem.x0[:, None]
        u = np.zeros((problem.nu, 1))
        g, ni = problem.path_constraints(x, u, problem.stage_dt[:1])
        gt, nti = problem.terminal_constraints(problem.x0)
        nc = 0 if g is None else g.shape[0]
        nt = 0 if gt is None else gt.shape[0]
        N = problem.N
        return cls(np.zeros((nc, N)), np.full((nc, N), mu0), np.zeros(nt), np.full(nt, mu0), ni,
                   nti)

    def take_duals(self, duals: dict | None) -> None:
        """Adopt warm-start duals {"lam": (n_c, N), "lam_t": (n_t,)} where their shapes fit
        and they are finite (else keep the zero duals)."""
        if not duals:
            return
        lam = np.asarray(duals.get("lam", []), float)
        lam_t = np.asarray(duals.get("lam_t", []), float)
        if lam.shape == self.lam.shape and lam_t.shape == self.lam_t.shape and \
                np.all(np.isfinite(lam)) and np.all(np.isfinite(lam_t)):
            self.lam[...] = lam
            self.lam_t[...] = lam_t

    def as_duals(self) -> dict:
        """The duals as JSON-ready lists (``Solution.duals``)."""
        return {"lam": self.lam.tolist(), "lam_t": self.lam_t.tolist()}


def penalty(g, lam, mu, n_ineq: int):
    """sum_i (lam_i + I_mu,i / 2 g_i) g_i over the first axis (paper eq. 8).

    I_mu,i = 0 for an inequality that is satisfied (g_i < 0) with lam_i = 0, else mu_i; the
    active set is decided on the constant part, so the same set is used for values and
    derivatives.
    """
    g0 = dm.cons(g)
    imu = np.array(mu, dtype=float, copy=True)
    if n_ineq:
        inactive = (g0[:n_ineq] < 0) & (lam[:n_ineq] == 0)
        imu[:n_ineq] = np.where(inactive, 0.0, imu[:n_ineq])
    terms = (lam + imu * 0.5 * g) * g
    out = terms[0]
    for i in range(1, len(terms)):
        out = out + terms[i]
    return out


def augmented_stage_cost(problem: Problem, x, u, mult: Multipliers, hom):
    """l~ (eq. 8) of every stage, (N,): floats or DA alike."""
    lt = problem.stage_cost(x, u, problem.stage_dt, hom)
    # the sampled g_path rows (the last inequalities) of a stage where every one is inactive
    # add exactly zero (``penalty``): their sub-stage expansions are skipped
    lam_path = mult.lam[mult.n_ineq - problem.n_path_rows:mult.n_ineq]
    g, _ = problem.path_constraints(
        x, u, problem.stage_dt,
        in_use=lambda g0: np.any(~((g0 < 0) & (lam_path == 0)), axis=0))
    return lt if g is None else lt + penalty(g, mult.lam, mult.mu, mult.n_ineq)


def augmented_terminal_cost(problem: Problem, xn, mult: Multipliers):
    """phi~ (eq. 8) at the final state: float or DA alike."""
    phi = problem.terminal_cost(xn, problem.x_target)
    gt, _ = problem.terminal_constraints(xn)
    return phi if gt is None else phi + penalty(gt, mult.lam_t, mult.mu_t, mult.n_tineq)


def augmented_cost_terms(problem: Problem, X, U, mult: Multipliers, hom):
    """The terms of J~ for a trajectory X (N+1, nx), U (N, nu) in floats: (every stage's l~
    (N,), phi~)."""
    return (augmented_stage_cost(problem, X[:-1].T, U.T, mult, hom),
            augmented_terminal_cost(problem, X[-1], mult))


def augmented_cost(problem: Problem, X, U, mult: Multipliers, hom) -> float:
    """Augmented cost J~ of a trajectory X (N+1, nx), U (N, nu) in floats (the forward pass's
    J*)."""
    stages, terminal = augmented_cost_terms(problem, X, U, mult, hom)
    return float(np.sum(stages) + terminal)

