"""Stage maps (order 2 by default, ``DDPOptions.map_order`` up to 6) and their re-centring
(paper eq. 11), used by the Dyn forward pass (Alg. 8), Newton's constraint model and warm
starts.

All stages needing an expansion are expanded in one vectorised DA call (batch axis = stage). The
DA variables of a stage are z = [dx (nx), du (nu)], n = nx + nu of them.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import da
from ..errors import DaddyError
from ..problem import Problem


def expand_dynamics(problem: Problem, X: np.ndarray, U: np.ndarray, stages=slice(None),
                    values=None, order: int = 2) -> da.DA:
    """Stage maps of ``order`` (2-6) at (X[k], U[k]) for the given stages, in one batched call.

    Args:
        X: (B, nx) stage start states; U: (B, nu) controls; stages: which of the problem's
            stages they are (an index array or a slice; every stage by default), for their
            lengths and starts.
        values: (nx, B) the stage flows f(X[k], U[k]) when the caller has integrated them
            already (a forward pass, Newton's residual): they become the maps' constant parts
            (``StageStep.expand``, which does not integrate them again).
    Returns:
        DA of shape (nx, B) in n = nx + nu variables.
    """
    if X.shape[0] == 0:
        raise DaddyError("expand_dynamics needs at least one stage")
    z = da.variables(np.concatenate([X.T, U.T]), order=order)
    x, u = z[:problem.nx], z[problem.nx:]
    dt, t0 = problem.stage_dt[stages], problem.stage_t0[stages]
    if values is None:
        return problem.step(x, u, dt, t0)
    return problem.step.expand(x, u, dt, values, t0)


def maps_at(problem: Problem, F: da.DA, dz: np.ndarray, inside: np.ndarray, X: np.ndarray, U: np.ndarray,
            values=None) -> da.DA:
    """Stage maps at a new nominal from maps F of a nearby one (paper eq. 11 / Alg. 8).

    The stages flagged ``inside`` (deviation within F's convergence radius) are re-centred by
    one batched composition, the others re-expanded in one batched DA call.

    Args:
        F: DA (nx, N) stage maps at the old nominal (the new ones have their order).
        dz: (n, N) deviations [dx; du] of the new nominal's stages from the old.
        inside: (N,) bool, stages to re-centre.
        X: (N+1, nx) or (N, nx) new stage start states; U: (N, nu) new controls.
        values: (nx, N) the exact stage flows at the new nominal, if known (see
            ``expand_dynamics``); the re-expanded stages take theirs.
    Returns:
        DA (nx, N) centred at (X[k], U[k]).
    """
    if not np.any(inside):
        return expand_dynamics(problem, X[:problem.N], U, values=values, order=F.order)
    if np.all(inside):   # (a warm re-plan's usual case: no copies of every map by index)
        return da.shift(F, dz)
    c = np.empty_like(F.c)
    idx_in, idx_out = np.flatnonzero(inside), np.flatnonzero(~inside)
    c[..., idx_in] = da.shift(F[:, idx_in], dz[:, idx_in]).c
    if idx_out.size:
        c[..., idx_out] = expand_dynamics(problem, X[idx_out], U[idx_out], idx_out,
                                          None if values is None else values[:, idx_out],
                                          F.order).c
    return da.DA(c, F.T)


@dataclass
class StageMaps:
    """Stage maps kept with the point they were expanded at, so that a nearby
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

    def at(self, problem: Problem, X: np.ndarray, U: np.ndarray, values=None, reach: float = 1.0):
        """DA (nx, N) maps at (X[k], U[k]): re-centred inside ``reach`` times the radius,
        expanded elsewhere (``values``: as for ``maps_at``). Beyond the radius (reach > 1) the
        re-centred values and derivatives carry more than the radius's truncation error: for
        callers that replace the values by exact ones and only need approximate derivatives."""
        dz, inside = self.deviation(X, U, reach)
        return maps_at(problem, self.F, dz, inside, X, U, values)

    def rollout(self, problem: Problem, U: np.ndarray, reach: float = 1.0) -> tuple[np.ndarray, int]:
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
