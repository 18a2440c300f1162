"""Batched second-order expansions of a trajectory: stage maps, augmented costs, constraints.

All stages are expanded in one vectorised DA call (batch axis = stage). The DA variables of a
stage are z = [dx (nx), du (nu)], n = nx + nu of them.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import da
from ..da import functions as dm
from ..errors import DaddyError


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
    def initial(cls, problem, mu0: float) -> "Multipliers":
        x = problem.x0[:, None]
        u = np.zeros((problem.nu, 1))
        g, ni = problem.path_constraints(x, u, problem.stage_dt[:1])
        gt, nti = problem.terminal_constraints(problem.x0)
        nc = 0 if g is None else g.shape[0]
        nt = 0 if gt is None else gt.shape[0]
        N = problem.N
        return cls(np.zeros((nc, N)), np.full((nc, N), mu0), np.zeros(nt), np.full(nt, mu0), ni, nti)


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


def max_violation(g, n_ineq: int) -> float:
    """Max constraint violation: max(g, 0) for inequalities, |g| for equalities."""
    if g is None or np.size(g) == 0:
        return 0.0
    g = np.asarray(g, dtype=float)
    v = np.abs(g)
    v[:n_ineq] = np.maximum(g[:n_ineq], 0.0)
    return float(v.max())


class Stages:
    """The expansions of one nominal trajectory (X, U) for the current multipliers.

    Attributes:
        X: (N+1, nx), U: (N, nu) nominal.
        F: DA (nx, N): second-order stage maps in z = [dx, du].
        radius: (N,) convergence radii of F at accuracy eps_da.
        lz: (N, n), lzz: (N, n, n): derivatives of the augmented stage cost.
        phix: (nx,), phixx: (nx, nx): derivatives of the augmented terminal cost.
        cost: augmented cost J of the nominal.
    """

    def __init__(self, problem, X, U, mult: Multipliers, hom, eps_da: float, F=None):
        self.problem = problem
        self.X = np.asarray(X, dtype=float)
        self.U = np.asarray(U, dtype=float)
        self.mult = mult
        self.hom = hom
        self.eps_da = eps_da
        self.F = F if F is not None else expand_dynamics(problem, self.X[:-1], self.U,
                                                                 problem.stage_dt)
        self.radius = da.radius(self.F, eps_da)
        self._expand_costs()

    @property
    def n(self) -> int:
        return self.problem.nx + self.problem.nu

    def _expand_costs(self):
        p = self.problem
        z = da.variables(np.concatenate([self.X[:-1].T, self.U.T]), order=2)
        lt = augmented_stage_cost(p, z[:p.nx], z[p.nx:], self.mult, self.hom)
        if not isinstance(lt, da.DA):  # a cost without any dependence on (x, u)
            lt = da.constant(lt, self.n) + z[0] * 0.0
        self.lz = lt.gradient()
        self.lzz = lt.hessian()
        phi = augmented_terminal_cost(p, da.variables(self.X[-1], order=2), self.mult)
        self.phix = phi.gradient()
        self.phixx = phi.hessian()
        self.cost = float(np.sum(lt.cons) + phi.cons)


def expand_dynamics(problem, X: np.ndarray, U: np.ndarray, dt: np.ndarray, values=None):
    """Order-2 stage maps at (X[k], U[k]) for the given stages, in one batched call.

    Args:
        X: (B, nx) stage start states; U: (B, nu) controls; dt: (B,) stage durations.
        values: (nx, B) the stage flows f(X[k], U[k]) when the caller has integrated them
            already (a forward pass, Newton's residual): they become the maps' constant parts,
            and a step that ``takes_values`` does not integrate them again.
    Returns:
        DA of shape (nx, B) in n = nx + nu variables.
    """
    if X.shape[0] == 0:
        raise DaddyError("expand_dynamics needs at least one stage")
    z = da.variables(np.concatenate([X.T, U.T]), order=2)
    x, u = z[:problem.nx], z[problem.nx:]
    if values is None:
        return problem.step(x, u, dt)
    if getattr(problem.step, "takes_values", False):
        return problem.step(x, u, dt, values=values)
    F = problem.step(x, u, dt)
    F.c[0] = values
    return F


def maps_at(problem, F, dz: np.ndarray, inside: np.ndarray, X: np.ndarray, U: np.ndarray,
            values=None):
    """Stage maps at a new nominal from maps F of a nearby one (paper eq. 11 / Alg. 8).

    The stages flagged ``inside`` (deviation within F's convergence radius) are re-centred by
    one batched composition, the others re-expanded in one batched DA call.

    Args:
        F: DA (nx, N) order-2 stage maps at the old nominal.
        dz: (n, N) deviations [dx; du] of the new nominal's stages from the old.
        inside: (N,) bool, stages to re-centre.
        X: (N+1, nx) or (N, nx) new stage start states; U: (N, nu) new controls.
        values: (nx, N) the exact stage flows at the new nominal, if known (see
            ``expand_dynamics``); the re-expanded stages take theirs.
    Returns:
        DA (nx, N) centred at (X[k], U[k]).
    """
    if not np.any(inside):
        return expand_dynamics(problem, X[:problem.N], U, problem.stage_dt, values)
    c = np.empty_like(F.c)
    idx_in, idx_out = np.flatnonzero(inside), np.flatnonzero(~inside)
    c[..., idx_in] = da.shift(F[:, idx_in], dz[:, idx_in]).c
    if idx_out.size:
        c[..., idx_out] = expand_dynamics(problem, X[idx_out], U[idx_out],
                                          problem.stage_dt[idx_out],
                                          None if values is None else values[:, idx_out]).c
    return da.DA(c, F.T)


@dataclass
class StageMaps:
    """Order-2 stage maps kept with the point they were expanded at, so that a nearby
    trajectory can use them (paper eq. 11): a Dyn rollout, or re-centring instead of expanding.

    Attributes:
        F: DA (nx, N) maps of the stages in z = [dx, du].
        X: (N, nx) stage start states and U: (N, nu) controls of the expansion point.
        radius: (N,) convergence radius of each map; 0 for a map that must not be used (e.g.
            a stage whose duration has changed).
    """

    F: da.DA
    X: np.ndarray
    U: np.ndarray
    radius: np.ndarray

    @classmethod
    def of(cls, F, X: np.ndarray, U: np.ndarray, eps_da: float) -> "StageMaps":
        """Maps F at (X[k], U[k]) (X may carry the final state as an extra row)."""
        N = U.shape[0]
        return cls(F, np.asarray(X, float)[:N].copy(), np.asarray(U, float).copy(),
                   da.radius(F, eps_da))

    @property
    def N(self) -> int:
        return self.U.shape[0]

    def deviation(self, X: np.ndarray, U: np.ndarray, reach: float = 1.0):
        """dz (n, N) of the stages (X[k], U[k]) from the expansion point, and (N,) whether each
        lies inside ``reach`` times its map's radius."""
        dz = np.concatenate([(X[:self.N] - self.X).T, (U - self.U).T])
        return dz, np.sqrt(np.sum(dz * dz, axis=0)) < self.radius * reach

    def at(self, problem, X: np.ndarray, U: np.ndarray, values=None, reach: float = 1.0):
        """DA (nx, N) maps at (X[k], U[k]): re-centred inside ``reach`` times the radius,
        expanded elsewhere (``values``: as for ``maps_at``). Beyond the radius (reach > 1) the
        re-centred values and derivatives carry more than the radius's truncation error: for
        callers that replace the values by exact ones and only need approximate derivatives."""
        dz, inside = self.deviation(X, U, reach)
        return maps_at(problem, self.F, dz, inside, X, U, values)

    def rollout(self, problem, U: np.ndarray, reach: float = 1.0) -> tuple[np.ndarray, int]:
        """Propagate U (N, nu) from problem.x0, evaluating a stage's map where the stage lies
        inside ``reach`` times its radius and integrating it otherwise (the Dyn forward pass,
        Alg. 8, with no feedback; reach > 1: a start for Newton, whose residuals are exact).
        Returns X (N+1, nx) and the number of stages served by a polynomial."""
        N = problem.N
        X = np.empty((N + 1, problem.nx))
        X[0] = problem.x0
        served = 0
        radius = self.radius * reach
        for k in range(N):
            dz = np.concatenate([X[k] - self.X[k], U[k] - self.U[k]])
            if np.sqrt(dz @ dz) < radius[k]:
                X[k + 1] = da.evaluate(self.F[:, k], dz)
                served += 1
            else:
                X[k + 1] = problem.stage_flow(X[k], U[k], k)
        return X, served

    def tail(self, k0: int, first_valid: bool) -> "StageMaps":
        """The maps of stages k0.. (a shifted plan); the first one is unusable unless
        ``first_valid`` (its stage kept its duration)."""
        r = self.radius[k0:].copy()
        if not first_valid:
            r[0] = 0.0
        return StageMaps(self.F[:, k0:], self.X[k0:], self.U[k0:], r)


def augmented_stage_cost(problem, x, u, mult: Multipliers, hom):
    """l~ (eq. 8) of every stage, (N,): floats or DA alike."""
    lt = problem.stage_cost(x, u, problem.stage_dt, hom)
    g, _ = problem.path_constraints(x, u, problem.stage_dt)
    return lt if g is None else lt + penalty(g, mult.lam, mult.mu, mult.n_ineq)


def augmented_terminal_cost(problem, xn, mult: Multipliers):
    """phi~ (eq. 8) at the final state: float or DA alike."""
    phi = problem.terminal_cost(xn, problem.x_target)
    gt, _ = problem.terminal_constraints(xn)
    return phi if gt is None else phi + penalty(gt, mult.lam_t, mult.mu_t, mult.n_tineq)


def augmented_cost(problem, X, U, mult: Multipliers, hom) -> float:
    """Augmented cost J~ of a trajectory in floats (the forward pass's J*)."""
    return float(np.sum(augmented_stage_cost(problem, X[:-1].T, U.T, mult, hom))
                 + augmented_terminal_cost(problem, X[-1], mult))


def constraint_values(problem, X, U):
    """Path constraints (n_c, N) and terminal constraints (n_t,) in floats (None if absent)."""
    g, ni = problem.path_constraints(X[:-1].T, U.T, problem.stage_dt)
    gt, nti = problem.terminal_constraints(X[-1])
    return g, ni, gt, nti


def total_violation(problem, X, U) -> float:
    g, ni, gt, nti = constraint_values(problem, X, U)
    return max(max_violation(g, ni), max_violation(gt, nti))
