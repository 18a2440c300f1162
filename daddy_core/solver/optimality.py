"""First-order optimality of a trajectory: how far (X, U) is from a KKT point of the problem
(the measure ``Solution.kkt_residual`` reports next to ``max_violation``).

DDP stops on a relative cost decrease below tol_ddp, which says little on an ill-conditioned
problem: along a stiff direction the gradient can be large while the decrease a step can make,
|g|^2 / (2 lambda), is tiny (the halo transfer stopped by tol_ddp = 1e-4 from a 1e-6 guess sits
0.36 kg from the optimum with a residual of 0.6; at tol_ddp = 1e-7 it reaches the optimum with
0.004). This measure looks at the gradients themselves, over Y = [u_0, x_1, ..., u_{N-1}, x_N]
as Newton's polishing does, with every constraint -- stage defects h_k = x_{k+1} - f(x_k, u_k),
path and terminal equalities and inequalities -- in the rows of D = dGamma/dY:

    min over mu (inequality components >= 0) of  |c + D^T mu|^2 + sum_ineq (g_i mu_i)^2,

c the cost gradient. The second term is complementarity: an inequality far from its bound
(g_i << 0) can only take a multiplier at a price. The normal equations (D D^T + diag(g_I^2))
mu = -D c are block-tridiagonal like Newton's Sigma and take the same banded Cholesky (linear in
N); an inequality whose multiplier comes out negative is held at zero and the system solved
again (a few passes; bounded). Reported, relative to the largest cost-gradient component:

    stationarity    = |c + D^T mu|_inf / |c|_inf,
    complementarity = max_ineq |mu_i g_i| / |c|_inf,
    kkt_residual    = max of the two.

0 at a KKT point of the problem as posed (the fuel cost at the last homotopy step's (h,
delta)); scale-free in the cost, but not in the variables: compare it across solves of one
problem, not across problems.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import da
from ..errors import DaddyError
from ..problem import Problem
from .newton import BandedSigma, ConstraintModel, stage_columns
from .stage_maps import StageMaps, expand_dynamics

_HOLD = 1e12          # diagonal that holds a negative inequality multiplier at zero
_MAX_PASSES = 8       # active-set passes of the non-negative least squares
_REFINE = 4           # refinement passes of each least-squares solve (``_multipliers``)


@dataclass(frozen=True)
class Optimality:
    """The relative first-order optimality figures of one trajectory (module docstring)."""

    stationarity: float
    complementarity: float
    multipliers: np.ndarray   # mu, in the rows of ``every_constraint``'s model
    gradient: np.ndarray      # c, the cost gradient over Y (``cost_gradient``)

    @property
    def kkt_residual(self) -> float:
        return max(self.stationarity, self.complementarity)

    def constraint_multipliers(self, N: int, nx: int, n_path: int, n_terminal: int):
        """The multipliers of the problem's own constraints, path (n_path, N) and terminal
        (n_terminal,), read from the rows of ``every_constraint``'s model -- [g_k, h_k] for
        each stage, then g_N, every row present -- without the stage defects' (the costates);
        None when the multipliers do not have that many rows."""
        mu, rows = self.multipliers, N * (n_path + nx)
        if mu.size != rows + n_terminal:
            return None
        return mu[:rows].reshape(N, n_path + nx)[:, :n_path].T.copy(), mu[rows:].copy()


def objective(problem: Problem, X, U, hom) -> float:
    """The problem's own cost sum l + phi (no augmented-Lagrangian terms)."""
    return float(np.sum(problem.stage_cost(X[:-1].T, U.T, problem.stage_dt, hom))
                 + problem.terminal_cost(X[-1], problem.x_target))


def cost_gradient(problem: Problem, X: np.ndarray, U: np.ndarray, hom) -> np.ndarray:
    """d(sum l + phi)/dY, (N * (nu + nx),), Y = [u_0, x_1, u_1, ..., u_{N-1}, x_N]."""
    p = problem
    nx, nu, N = p.nx, p.nu, p.N
    z = da.variables(np.concatenate([X[:-1].T, U.T]), order=1)
    lz = _gradient(p.stage_cost(z[:nx], z[nx:], p.stage_dt, hom), (N, nx + nu))
    phix = _gradient(p.terminal_cost(da.variables(X[-1], order=1), p.x_target), (nx,))
    cols = stage_columns(np.arange(N), nx, nu)
    keep = cols >= 0                 # (x_0 is fixed)
    c = np.zeros(N * (nx + nu))
    c[cols[keep]] = lz[keep]         # each column belongs to one stage's cost
    c[cols[-1, :nx] + nx + nu] += phix   # x_N: the state columns of stage N
    return c


def _gradient(value, shape: tuple) -> np.ndarray:
    """The gradient of a DA value (a constant: zeros of ``shape``)."""
    return value.gradient() if isinstance(value, da.DA) else np.zeros(shape)


def every_constraint(problem: Problem, X: np.ndarray, U: np.ndarray,
                     maps: StageMaps | None = None) -> ConstraintModel:
    """Newton's order-2 constraint model at (X, U) with every constraint in its rows (inactive
    inequalities too); the stage maps re-centred from ``maps`` where a stage lies within their
    radius (expanded elsewhere), or (None) expanded."""
    F = expand_dynamics(problem, X[:-1], U) if maps is None \
        else maps.at(problem, X, U)
    return ConstraintModel(problem, X, U, math.inf, F=F)


def optimality(problem: Problem, X: np.ndarray, U: np.ndarray, hom,
               maps: StageMaps | None = None,
               model: ConstraintModel | None = None) -> Optimality | None:
    """The first-order optimality of (X, U) (module docstring) for the stage cost at ``hom``.

    ``model``: ``every_constraint``'s model at (X, U), if built already; else built here, its
    stage maps re-centred from ``maps`` within their radius (None: every stage expanded).
    None when the figures cannot be evaluated (a non-finite iterate or derivative, a singular
    system).
    """
    if not (np.all(np.isfinite(X)) and np.all(np.isfinite(U))):
        return None
    try:
        model = model or every_constraint(problem, X, U, maps)
        c = cost_gradient(problem, X, U, hom)
        g = model.residual()   # constraint values in D's row order
        ineq = model.inequality_rows()
        mu = _multipliers(model.D, c, g, ineq)
    except (DaddyError, ArithmeticError, np.linalg.LinAlgError, ValueError):
        return None
    if mu is None:
        return None
    scale = float(np.max(np.abs(c), initial=0.0))
    r = c + model.D.T @ mu
    if not np.all(np.isfinite(r)):
        return None
    if scale == 0.0:   # no cost gradient: any residual is absolute
        scale = 1.0
    comp = float(np.max(np.abs(mu[ineq] * g[ineq]), initial=0.0))
    return Optimality(float(np.max(np.abs(r), initial=0.0)) / scale, comp / scale, mu, c)


def _multipliers(D, c: np.ndarray, g: np.ndarray, ineq: np.ndarray) -> np.ndarray | None:
    """The least-squares multipliers of the module docstring: (D D^T + diag(q)) mu = -D c with
    q = g^2 on inequality rows, inequalities with a negative multiplier held at zero.

    The normal equations square D's condition number: on the Earth transfers (rows from the
    orbit elements' to the time's scale) their solution left a stationarity residual of
    1e-4 at points where a QR solve gives 1e-9. Each solve is therefore refined on its own
    residual computed from D and c directly (corrected semi-normal equations, Bjorck 1987):
    mu += Sigma^{-1} (-D r - q mu), r = c + D^T mu, with the same factor, until the residual
    stops falling (``_REFINE`` passes at most)."""
    q = np.where(ineq, g * g, 0.0)
    held = np.zeros(ineq.shape, dtype=bool)
    tiny = 1e-14 * max(1.0, float(np.max(np.abs(D.data), initial=0.0)) ** 2)
    for _ in range(_MAX_PASSES):
        reg = q + np.where(held, _HOLD, 0.0)
        sigma = BandedSigma(D, reg + tiny)
        mu = sigma.solve(-(D @ c))
        best, best_size = mu, math.inf
        for _ in range(_REFINE + 1):
            if not np.all(np.isfinite(mu)):
                break
            r = c + D.T @ mu
            size = float(np.max(np.abs(r), initial=0.0))
            if not size < 0.5 * best_size:
                break
            best, best_size = mu, size
            mu = mu + sigma.solve(-(D @ r) - reg * mu)
        mu = best
        if not np.all(np.isfinite(mu)):
            return None
        negative = ineq & ~held & (mu < 0)
        if not negative.any():
            break
        held |= negative
    mu[held] = 0.0
    mu[ineq] = np.maximum(mu[ineq], 0.0)
    return mu
