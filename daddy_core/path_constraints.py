"""Path constraints that hold between the nodes: g_path(x(t), u_k) <= 0 for every t of every
stage, not only at the stage points.

A constraint on the state along a continuous trajectory is a semi-infinite constraint: one
inequality per instant. It is solved here as semi-infinite programs are (Hettich & Kortanek
1993, discretisation and exchange):

1. **Sampling.** Each stage's constraint is imposed at ``Problem.path_samples`` points inside
   it, the states x(t_k + j h_k / M), j = 1..M, reached by the stage's own flow from
   (x_k, u_k) (``sampled``). The rows are ordinary stage inequalities of (x_k, u_k): the
   augmented Lagrangian, the Newton polishing to 1e-10 and the KKT test take them as they take
   the thrust bound; on DA they are the expansions of the sub-stage flows, so DDP sees how a
   control moves the trajectory between nodes. j = M is the stage's end, which covers every
   node after x0.
2. **Exchange.** Between samples the constraint can still dip (a flyby's minimum distance
   falls between them). ``dense_margin`` re-propagates every stage with DOP853 on a fine grid
   and refines each stage's worst point; where the dense maximum of g exceeds zero, the
   solver tightens that stage's sampled rows by the measured excess (``tightened``) and solves
   the last homotopy step again from there, until the dense check holds
   (``solver.path_exchange``).

Why not the integrated smoothed violation of Pontryagin-Bellman DDP (Sidhoum & Oguri 2025, an
extra state dq/dt = softplus_eps(g) driven to zero by a penalty)? Its integral is positive
wherever the smoothing is, so it cannot be met as an equality: it is a penalty, whose optimum
sits a margin inside the boundary set by the sharpness eps and the penalty weight (their halo
transfer: 121 / 77 / 630 km beyond r_min = 20,000 / 25,000 / 30,000 km), and the node
inequalities cannot be polished by Newton to a boundary the penalty never reaches. Sampled rows
are ordinary inequalities: the solution touches the boundary where the optimum wants it (the
sampled points meet it to tol_newton) and the exchange makes the continuous constraint hold
between them with an excess per stage that is measured, not assumed.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .da import functions as dm
from .da.core import DA, constant, variables
from .errors import DaddyError
from .integrators import dop853_batch

# grid points per stage of the dense check, before each stage's worst point is refined
_DENSE_GRID = 24
# ternary-search refinements of each stage's worst grid point (its bracket shrinks by 2/3 each:
# 2 / _DENSE_GRID * (2/3)^30 ~ 4e-7 of the stage)
_REFINE_STEPS = 30


def sampled(problem, x, u, dt, t0, in_use=None):
    """The sampled path-constraint rows of B stages starting at x (nx, B) under u (nu, B), with
    lengths dt (B,) and starts t0 (B,) -- the problem's first B stages: (M n_p, B), sample j's
    n_p components in rows j n_p .. (j + 1) n_p - 1, each plus ``Problem.path_offset`` (the
    exchange's tightening of its stage). Floats or DA alike: the sub-stage states come from
    the problem's stage flow.

    in_use: None, or a function of the rows' values (M n_p, B) -> (B,) bool, the stages whose
    rows the caller uses. On DA, the rows are then evaluated on floats first and expanded only
    on those stages; the others carry their values with zero derivatives. The sub-stage
    expansions are most of a constrained solve's cost (a halo transfer with a keep-out that
    never binds: two thirds of it), and where the caller discards a row's derivatives they are
    wasted: the augmented Lagrangian's inactive inequalities (g < 0 with a zero multiplier:
    their term is exactly zero, ``lagrangian.augmented_stage_cost``). (Not Newton's inactive
    rows: its model checks that a step keeps them met, with their derivatives.)"""
    if in_use is not None and isinstance(x, DA):
        values = _sampled(problem, x.cons, dm.cons(u), dt, t0, np.arange(np.size(dt)))
        k = np.flatnonzero(in_use(values))
        if k.size < np.size(dt):
            out = constant(values, x.n, x.order)
            if k.size:
                part = _sampled(problem, x[:, k], u[:, k], np.asarray(dt)[k],
                                np.asarray(t0)[k], k)
                out.c[:, :, k] = part.c
            return out
    return _sampled(problem, x, u, dt, t0, np.arange(np.size(dt)))


def _sampled(problem, x, u, dt, t0, stages: np.ndarray):
    """``sampled`` of the stages ``stages`` (indices into the problem's, for the offsets)."""
    M = problem.path_samples
    h = np.asarray(dt, dtype=float) / M
    rows, xs = [], x
    for j in range(M):
        xs = problem.step(xs, u, h, np.asarray(t0, dtype=float) + j * h)
        g = problem.g_path(xs, u)
        if problem.path_offset is not None:
            g = g + problem.path_offset[:, stages]
        rows.append(g)
    return rows[0] if M == 1 else dm.concatenate(rows)


def violated_at_start(problem, u0: np.ndarray, tol: float) -> str | None:
    """Why no trajectory can hold g_path, or None: a component violated (> tol) at x0, the
    fixed start, that no control changes (its derivative in u is zero there, e.g. a keep-out
    sphere around x0). A solve would only find out after its augmented Lagrangian stalled
    (minutes), and the exchange cannot tighten the start."""
    nx = problem.nx
    z = variables(np.concatenate([problem.x0, np.asarray(u0, float)])[:, None], order=1)
    g = problem.g_path(z[:nx], z[nx:])
    value = np.asarray(dm.cons(g), dtype=float)[:, 0]
    du = np.zeros_like(value) if not isinstance(g, DA) else \
        np.abs(g.c[1 + nx:1 + nx + problem.nu, :, 0]).max(axis=0)
    bad = np.flatnonzero((value > tol) & (du == 0))
    if bad.size == 0:
        return None
    i = int(bad[0])
    return (f"infeasible: g_path[{i}] is {value[i]:.3e} above its bound at x0, the fixed "
            "start, whatever the control: no trajectory from x0 can hold it")


@dataclass(frozen=True)
class PathMargin:
    """The path constraint along a re-propagated trajectory (``dense_margin``).

    Attributes:
        excess: (n_p, N) each stage's dense maximum of each component minus the largest of
            its sampled values: how far the constraint rises between the samples.
        worst: (n_p, N) each stage's dense maximum of each component.
        where: (n_p, N) the fraction of the stage where it lies (0: the stage's start node).
        margin (property): -max over every stage, instant and component of g_path: the true
            minimum margin (>= 0: the constraint holds everywhere; in g_path's units).
        stage, tau (properties): where the margin is smallest (stage index, fraction of it).
    """

    excess: np.ndarray
    worst: np.ndarray
    where: np.ndarray

    @property
    def _smallest(self) -> tuple[int, int]:
        return np.unravel_index(int(np.argmax(self.worst)), self.worst.shape)

    @property
    def margin(self) -> float:
        return float(-self.worst[self._smallest])

    @property
    def stage(self) -> int:
        return int(self._smallest[1])

    @property
    def tau(self) -> float:
        return float(self.where[self._smallest])


def _states_at(problem, X: np.ndarray, U: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """(nx, N) the state of every stage k at fraction tau[k] of it, by DOP853 from X[k] at
    rtol = atol = 1e-12 (tau = 0: X[k] itself)."""
    h = problem.stage_dt * tau
    x = X[:-1].T.copy()
    move = h > 0
    if np.any(move):
        x[:, move] = dop853_batch(problem.rhs, x[:, move], U[move].T, problem.stage_t0[move],
                                  h[move], rtol=1e-12, atol=1e-12)
    return x


def dense_margin(problem, X: np.ndarray, U: np.ndarray) -> PathMargin:
    """The true minimum margin of ``problem.g_path`` along (X (N+1, nx), U (N, nu)): every
    stage re-propagated from its own start X[k] with DOP853 (rtol = atol = 1e-12) to a grid of
    ``_DENSE_GRID`` instants (batched over stages), each stage's worst instant per component
    then refined by a ternary search on the two grid intervals around its grid maximum (g along
    a stage is smooth: that bracket holds the stage's maximum, or the maximum is at its end and
    the grid point is the answer). ``path_offset`` is not applied: the margin is that of the
    constraint as the user wrote it."""
    if problem.g_path is None:
        raise DaddyError("dense_margin: the problem has no g_path")
    if problem.rhs is None:
        raise DaddyError("dense_margin: g_path needs the continuous dynamics (problem.rhs)")
    X, U = np.asarray(X, float), np.asarray(U, float)
    N, M = problem.N, problem.path_samples

    def g_at(tau):   # (n_p, N) g_path at fraction tau (N,) of every stage
        return np.asarray(problem.g_path(_states_at(problem, X, U, tau), U.T), dtype=float)

    grid = np.linspace(0.0, 1.0, _DENSE_GRID + 1)
    G = np.stack([g_at(np.full(N, t)) for t in grid])                   # (K+1, n_p, N)
    samples = np.stack([g_at(np.full(N, j / M)) for j in range(1, M + 1)])  # (M, n_p, N)
    worst, where = G.max(axis=0), grid[G.argmax(axis=0)]                # (n_p, N)
    for i in range(G.shape[1]):
        lo = np.clip(where[i] - 1.0 / _DENSE_GRID, 0.0, 1.0)
        hi = np.clip(where[i] + 1.0 / _DENSE_GRID, 0.0, 1.0)
        for _ in range(_REFINE_STEPS):
            a, b = (2.0 * lo + hi) / 3.0, (lo + 2.0 * hi) / 3.0
            left = g_at(a)[i] > g_at(b)[i]        # the maximum lies in [lo, b]
            lo, hi = np.where(left, lo, a), np.where(left, b, hi)
        mid = 0.5 * (lo + hi)
        top = g_at(mid)[i]
        better = top > worst[i]
        worst[i] = np.where(better, top, worst[i])
        where[i] = np.where(better, mid, where[i])
    return PathMargin(worst - samples.max(axis=0), worst, where)


def tightened(offset: np.ndarray | None, pm: PathMargin, tol: float) -> np.ndarray | None:
    """The exchange step: the sampled rows' offsets (n_p, N), raised on every stage whose dense
    maximum exceeds ``tol`` to the larger of 1.25 times the stage's excess (what g rises
    between its samples above the largest of them: with the samples held that far inside,
    the dense maximum is below zero) and the old offset plus 1.25 times the violation (the
    trajectory moved when it was solved again; the offset then still grows). A quarter more
    than measured because the solution moves when it is solved again. None when no stage
    needs it.

    Why the excess and not only the violation: the samples need not be active where the
    constraint is violated (Earth-Mars with the Sun 0.9 AU away: the closest approach fell
    between two samples 2.7e-5 and 5.1e-5 AU inside the bound, the dense maximum 8.7e-6
    above it); tightening by the violation alone changed nothing until the offsets had
    grown past the samples' slack (four rounds instead of one).

    A stage whose worst point is its start node (k >= 1) is not tightened: that node is the
    previous stage's last sample, so the previous stage's offset grows by 1.25 times the
    violation (what is left there is the difference between the stage's flow and its samples'
    sub-steps, ~1e-9). Tightening the stage itself by its excess held all its samples far
    inside for nothing (the keep-out rendezvous: 5.3 m for 6.9e-10 km)."""
    over = pm.worst > tol
    if not np.any(over):
        return None
    base = np.zeros_like(pm.worst) if offset is None else np.array(offset, dtype=float)
    at_start = over & (pm.where <= 0.0)
    at_start[:, 0] = False                          # (x0 is fixed: no earlier sample holds it)
    inside = over & ~at_start
    new = base.copy()
    new[inside] = np.maximum(1.25 * pm.excess[inside], base[inside] + 1.25 * pm.worst[inside])
    i, k = np.nonzero(at_start)
    np.maximum.at(new, (i, k - 1), base[i, k - 1] + 1.25 * pm.worst[i, k])
    return new
