"""Newton polishing of a DDP solution (paper Alg. 5, accelerated as Alg. 11).

The active constraints Gamma(Y) -- active path inequalities, path equalities, continuity
h_k = x_{k+1} - f(x_k, u_k) and terminal constraints -- are driven to zero by minimum-norm
Newton steps dY = -Delta^T (Delta Delta^T)^{-1} d over Y = [u_0, x_1, u_1, ..., u_{N-1}, x_N].

Weighted steps (``SolverOptions.newton.control_weight_floor`` > 0, problems with a thrust bound
u_max): the minimum of dY^T W^{-1} dY instead, dY = -W Delta^T (Delta W Delta^T)^{-1} d, with
W = 1 on the states and w_k = max(|u_k| / u_max, floor)^2 on the controls of stage k. The plain
step moves a coasting stage's control (|u| ~ 1e-3 u_max in a fuel-optimal plan) as much as a
thrusting one's; there the mass flow -|u| / c is far from its quadratic model, so the exact
residual after an outer iteration is the model's mass error and Newton converges linearly.
Weighted, the correction goes to the thrust arcs and coasting arcs keep coasting.

Alg. 11: the constraints are expanded to order 2 at Y once per outer iteration (one batched DA
call for all stages); inner iterations re-use the factorisation of Sigma = Delta Delta^T and
evaluate the polynomial model P_Gamma instead of integrating, while the model converges at rate
r = log d*_max / log d_max above eps_CV. Sigma is symmetric block-tridiagonal (rows ordered by
stage); it is factorised as a banded matrix (LAPACK pbtrf through scipy's cholesky_banded), whose
cost grows linearly with N -- no dense N_c^3 factorisation.

One entry point, ``polish``: it drives a guess to feasibility before DDP (a warm start's from
the previous plan's stage maps) and finishes a DDP solution, the same Alg. 11.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .. import da
from ..errors import DaddyError
from ..problem import Problem, largest, max_violation
from .deadline import Deadline, passed
from .options import SolverOptions
from .results import Status, StepResult, not_halved
from .stage_maps import StageMaps, expand_dynamics

# a run whose exact residual moved by less than _FLAT_TOL (relative) over each of its last
# _FLAT_ITER outer iterations has stalled (``newton``; with newton_stall_iter > 0 only)
_FLAT_ITER = 3
_FLAT_TOL = 1e-2
# a step whose iterate's exact residual is not finite is halved up to this many times
_NAN_CUTS = 10


def preload() -> None:
    """Import what Newton and the KKT polishing load on first use (scipy.sparse, scipy.linalg,
    scipy.sparse.linalg: ~0.4-0.6 s of CPU, most of this package's import cost, hence lazy).
    A long-lived process whose first solve has a latency budget (the guidance node) calls it
    at start-up; a one-shot script need not."""
    import scipy.linalg  # noqa: F401
    import scipy.sparse.linalg  # noqa: F401


@dataclass
class NewtonResult(StepResult):
    X: np.ndarray
    U: np.ndarray
    max_violation: float
    improved: bool                # X, U are an evaluated iterate (not the input given back)
    maps: StageMaps | None        # the last model's stage maps
    # the first model's maps when it was expanded afresh at the given (X, U), values the exact
    # flows: DDP's first expansion there, should it start from that point after all
    start_F: da.DA | None = None


def _active(g0: np.ndarray, n_ineq: int, active_tol: float) -> np.ndarray:
    """Rows of constraint values g0 that Newton drives to zero: every equality and the
    inequalities with g > -active_tol."""
    act = np.ones(g0.shape, dtype=bool)
    act[:n_ineq] = g0[:n_ineq] > -active_tol
    return act


def stage_columns(ks: np.ndarray, nx: int, nu: int) -> np.ndarray:
    """Columns of z_k = [x_k, u_k] in Y = [u_0, x_1, u_1, ..., u_{N-1}, x_N] for the stages
    ks, (len(ks), nx + nu): x_k is block k - 1's tail, u_k block k's head; x_0 is fixed, so
    stage 0's state columns come out negative (callers drop them)."""
    w = nx + nu
    z_cols = np.concatenate([np.arange(nu, w) - w, np.arange(nu)])
    return np.asarray(ks)[:, None] * w + z_cols[None, :]


class ConstraintModel:
    """Order-2 expansion of the active constraints at one Y (``active_tol`` = inf: every
    constraint, as ``optimality`` needs them)."""

    def __init__(self, problem: Problem, X, U, active_tol: float, F=None):
        p = self.p = problem
        self.X, self.U = X, U
        nx, N = p.nx, p.N
        self.F = expand_dynamics(p, X[:-1], U) if F is None else F   # (nx, N)
        z = da.variables(np.concatenate([X[:-1].T, U.T]), order=2)
        g, ni = p.path_constraints(z[:nx], z[nx:], p.stage_dt)
        self.G, self.n_ineq = g, ni
        if g is not None:
            self.g_active = _active(g.cons, ni, active_tol)             # (n_c, N)
        else:
            self.g_active = np.zeros((0, N), dtype=bool)
        xn = da.variables(X[-1], order=2)
        gt, nti = p.terminal_constraints(xn)
        self.Gt, self.n_tineq = gt, nti
        if gt is not None:
            self.t_active = _active(gt.cons, nti, active_tol)
        else:
            self.t_active = np.zeros(0, dtype=bool)
        # (N, n_c + nx) bool: the rows of [g_k; h_k] that are rows of D, in D's order
        self._stage_rows = np.concatenate([self.g_active, np.ones((nx, N), dtype=bool)]).T
        self._build_jacobian()

    # rows: [g_0 active, h_0, g_1 active, h_1, ..., g_{N-1}, h_{N-1}, g_N active]
    # columns: Y = [u_0, x_1, u_1, x_2, ..., u_{N-1}, x_N], block k = [u_k, x_{k+1}] of width n
    def _build_jacobian(self):
        p = self.p
        nx, nu, N = p.nx, p.nu, p.N
        w = nx + nu
        n_g = self.g_active.sum(axis=0)                              # (N,) active rows per stage
        start = np.concatenate([[0], np.cumsum(n_g + nx)])           # first row of each stage
        parts = []                                                   # (rows, cols, vals) blocks

        def stage_rows(rows, ks, Jz):
            """Rows depending on z_k = [x_k, u_k] (Jz: (m, n)); x_0 is fixed (no columns)."""
            cols = stage_columns(ks, nx, nu)
            keep = cols >= 0
            parts.append((np.broadcast_to(rows[:, None], cols.shape)[keep], cols[keep],
                          Jz[keep]))

        if self.G is not None and n_g.sum():
            gz = np.moveaxis(self.G.gradient(), 1, 0)                 # (N, n_c, n)
            ks, ii = np.nonzero(self.g_active.T)                     # stage-major order
            rank = np.arange(ks.size) - np.concatenate([[0], np.cumsum(n_g)])[ks]
            stage_rows(start[ks] + rank, ks, gz[ks, ii])
        fz = np.moveaxis(self.F.gradient(), 1, 0)                      # (N, nx, n)
        ks = np.repeat(np.arange(N), nx)
        ii = np.tile(np.arange(nx), N)
        h_rows = start[ks] + n_g[ks] + ii                            # h_k = x_{k+1} - f(x_k, u_k)
        stage_rows(h_rows, ks, -fz.reshape(N * nx, w))
        parts.append((h_rows, ks * w + nu + ii, np.ones(N * nx)))
        r = int(start[-1])
        if self.Gt is not None and self.t_active.any():
            gtx = self.Gt.gradient()[self.t_active]                  # (m, nx) on x_N
            m = gtx.shape[0]
            rows = np.repeat(np.arange(r, r + m), nx)
            parts.append((rows, np.tile((N - 1) * w + nu + np.arange(nx), m), gtx.ravel()))
            r += m
        self.n_rows = r
        rows, cols, vals = (np.concatenate(x) for x in zip(*parts))
        import scipy.sparse as sp   # (lazy: scipy.sparse is ~60 % of the package's import time)
        self.D = sp.csr_matrix((vals, (rows, cols)), shape=(r, N * w))

    def inequality_rows(self) -> np.ndarray:
        """(n_rows,) bool: which rows of D (and of ``residual()``) are inequalities."""
        ineq = np.concatenate([np.arange(self.g_active.shape[0]) < self.n_ineq,
                               np.zeros(self.p.nx, dtype=bool)])
        stage = np.broadcast_to(ineq, self._stage_rows.shape)[self._stage_rows]
        return np.concatenate([stage,
                               (np.arange(self.t_active.size) < self.n_tineq)[self.t_active]])

    def residual(self, dY: np.ndarray | None = None) -> np.ndarray:
        """Gamma(Y + dY) from the polynomial model (dY = None: at Y, i.e. exact values)."""
        p = self.p
        nx, nu, N = p.nx, p.nu, p.N
        w = nx + nu
        if dY is None:
            dY = np.zeros(N * w)
        blocks = dY.reshape(N, w)
        du = blocks[:, :nu]                                            # (N, nu)
        dxn = blocks[:, nu:]                                           # (N, nx): dx_{k+1}
        dx = np.vstack([np.zeros(nx), dxn[:-1]])                       # dx_k
        dz = np.concatenate([dx.T, du.T])                              # (n, N)
        fnext = da.evaluate(self.F, dz)                                # (nx, N)
        h = (self.X[1:] + dxn).T - fnext                               # (nx, N)
        if self.G is not None:
            h = np.concatenate([da.evaluate(self.G, dz), h])           # (n_c + nx, N)
        rows = h.T[self._stage_rows]      # stage-major: [g_k active, h_k] for k = 0 .. N-1
        if self.Gt is None:
            return rows
        return np.concatenate([rows, da.evaluate(self.Gt, dxn[-1])[self.t_active]])

    def apply(self, dY: np.ndarray, X: np.ndarray | None = None, U: np.ndarray | None = None):
        """(X, U) + dY (default: the model's own point)."""
        p = self.p
        w = p.nx + p.nu
        b = dY.reshape(p.N, w)
        X = (self.X if X is None else X).copy()
        X[1:] += b[:, p.nu:]
        return X, (self.U if U is None else U) + b[:, :p.nu]


def column_weights(problem: Problem, U: np.ndarray, floor: float) -> np.ndarray | None:
    """sqrt(W) of the weighted step over Y's columns (N * (nu + nx),): 1 on the states,
    max(|u_k| / u_max, floor) on the controls of stage k; None for plain steps (floor 0 or no
    thrust bound)."""
    if not floor or not problem.u_max:
        return None
    N, nu, w = problem.N, problem.nu, problem.nx + problem.nu
    s = np.ones((N, w))
    s[:, :nu] = control_scale(U, problem.u_max, floor)[:, None]
    return s.ravel()


def control_scale(U: np.ndarray, u_max: float, floor: float) -> np.ndarray:
    """(N,) max(|u_k| / u_max, floor), at most 1: how far a minimum-norm correction may move
    stage k's control (U (N, nu)); a coasting stage's little, so coasting arcs keep coasting."""
    return np.clip(np.linalg.norm(U, axis=1) / u_max, floor, 1.0)


class BandedSigma:
    """Cholesky factor of Sigma = D W D^T + diag(reg) in LAPACK banded storage, W =
    diag(scale^2) (scale None: W = I; reg: a number or one per row)."""

    def __init__(self, D: sp.csr_matrix, reg: float | np.ndarray,
                 scale: np.ndarray | None = None):
        from scipy.linalg import cholesky_banded
        if scale is not None:   # D sqrt(W): the columns scaled
            D = D.copy()
            D.data *= scale[D.indices]
        self.scale = scale
        S = (D @ D.T).tocoo()
        n = S.shape[0]
        upper = S.col >= S.row
        bw = int(np.max(S.col[upper] - S.row[upper])) if np.any(upper) else 0
        ab = np.zeros((bw + 1, n))
        ab[bw + S.row[upper] - S.col[upper], S.col[upper]] = S.data[upper]
        ab[bw] += reg
        self.cb = cholesky_banded(ab, lower=False)
        self.D = D

    def solve(self, b: np.ndarray) -> np.ndarray:
        """Sigma^{-1} b."""
        from scipy.linalg import cho_solve_banded
        return cho_solve_banded((self.cb, False), b)

    def step(self, d: np.ndarray) -> np.ndarray:
        """dY = -W D^T Sigma^{-1} d, with self.D = D sqrt(W)."""
        dY = -(self.D.T @ self.solve(d))
        return dY if self.scale is None else dY * self.scale


def _float_residual(problem: Problem, X, U, active_tol: float):
    """Gamma(Y) in floats: the stage flows f(x_k, u_k) (nx, N) from one batched float
    integration, max |Gamma(Y)| over the same active set as ``ConstraintModel.residual()``, and
    the iterate's infeasibility: the largest stage defect or constraint violation (an inequality
    counts by max(g, 0): Newton drives the near-active ones to g = 0, feasibility does not need
    it)."""
    fx = problem.stage_flows(X, U)                                          # (nx, N)
    defect = float(np.max(np.abs(X[1:].T - fx)))
    active, infeasible = [defect], [defect]
    g, ni, gt, nti = problem.constraint_values(X, U)
    for c, n_ineq in ((g, ni), (gt, nti)):
        if c is not None:
            c = np.asarray(c, dtype=float)
            active.append(float(np.max(np.abs(c[_active(c, n_ineq, active_tol)]), initial=0.0)))
            infeasible.append(max_violation(c, n_ineq))
    return fx, largest(*active), largest(*infeasible)


def exact_valued_maps(problem: Problem, maps: StageMaps | None, X, U, fx,
                      reach: float) -> da.DA:
    """Order-2 stage maps at (X[:-1], U) whose values are the exact float flows ``fx``.

    ``maps``: maps of a nearby trajectory (the previous outer iteration's, or given to
    ``newton``): re-centred where the stage lies within ``reach`` times their radius,
    re-expanded elsewhere; None: expand every stage. The constant part is then replaced by
    ``fx``, so the model's residual at Y is exact and only its derivatives carry the
    re-centring's truncation error.
    """
    F = expand_dynamics(problem, X[:-1], U, values=fx) if maps is None \
        else maps.at(problem, X, U, values=fx, reach=reach)   # a new DA either way
    F.c[0] = fx
    return F


def _flat(current: list) -> bool:
    """The exact residual stayed put: within _FLAT_TOL over each of the last _FLAT_ITER outer
    iterations. Such an iterate is where Newton's steps no longer move it (each outer
    iteration's model is solved anew, and a run that converges changes its residual by factors
    between iterations, after any detour; design notes: flat residual stop)."""
    last = np.asarray(current[-_FLAT_ITER - 1:])
    return (last.size > _FLAT_ITER
            and bool(np.all(np.abs(np.diff(last)) <= _FLAT_TOL * np.abs(last[:-1]))))


def polish(problem: Problem, X, U, opts: SolverOptions, deadline: Deadline | None = None,
           maps: StageMaps | None = None) -> NewtonResult:
    """Alg. 11 from (X, U) to max active-constraint violation <= opts.newton.tol: the polishing
    of a DDP solution, and the restoration of a guess (``SolverOptions.start.restore``).

    The constraint values Gamma(Y) are always exact (one batched float integration of every
    stage per outer iteration). The stage maps that give their derivatives are re-centred from
    the previous outer iteration's -- first from ``maps``, e.g. a previous plan's -- where the
    step stayed inside ``map_reach`` radii (paper eq. 11) and re-expanded elsewhere; an outer
    iteration that does not reduce the exact residual makes the next one expand afresh. A step
    whose iterate is not finite (it left the dynamics' domain) is halved. Stalls end the run
    early (``_stalled``). Converged: the returned (best) iterate meets every constraint to
    tol_newton, whether or not each near-active inequality reached its bound.
    """
    run = _Run(X.copy(), U.copy(), maps)
    status = Status.NEWTON_MAX_ITER
    while run.it < opts.newton.max_iter:
        if passed(deadline):
            status = deadline.status
            break
        fx, dmax, infeasibility = _residual(problem, run.X, run.U, opts.newton.active_tol)
        if not np.isfinite(dmax):
            # the step left the dynamics' domain (e.g. an orbit's eccentricity past 1 in
            # equinoctial elements, where the model's polynomials are still finite): halve it
            if run.last is None or run.cuts >= _NAN_CUTS:
                status = Status.NEWTON_NAN
                break
            run.halve()
            continue
        run.cuts = 0
        if run.best is None or dmax < run.best[0]:
            run.best = (dmax, run.X.copy(), run.U.copy(), infeasibility)
        run.history.append(run.best[0])
        run.current.append(dmax)
        status = _stalled(run, dmax, opts)
        if status is not None:
            break
        status = _outer_step(problem, run, fx, dmax, opts)
        if status is not None:
            break
        status = Status.NEWTON_MAX_ITER
    if run.best is None:
        return NewtonResult(False, run.it, status, X, U, np.inf, False, run.maps, run.start_F)
    _, Xb, Ub, viol = run.best
    return NewtonResult(viol <= opts.newton.tol, run.it, status, Xb, Ub, viol, True, run.maps,
                        run.start_F)


@dataclass
class _Run:
    """The state of one Newton run: the iterate, the maps its derivatives are re-centred from,
    the best iterate so far, the best and the exact residual after each outer iteration, the
    last step (model, dY) and its halvings so far, and the first model's maps if expanded
    afresh at the start (``NewtonResult.start_F``)."""

    X: np.ndarray
    U: np.ndarray
    maps: StageMaps | None
    it: int = 0
    best: tuple | None = None
    history: list = field(default_factory=list)
    current: list = field(default_factory=list)
    prev_dmax: float = np.inf
    fresh: bool = True
    last: tuple | None = None
    start_F: object = None
    cuts: int = 0

    def halve(self) -> None:
        self.cuts += 1
        self.last = (self.last[0], 0.5 * self.last[1])
        self.X, self.U = self.last[0].apply(self.last[1])


def _residual(problem: Problem, X, U, active_tol: float) -> tuple:
    """``_float_residual`` at (X, U), with an infinite residual where the flows fail."""
    try:   # (a NaN is handled by the caller: numpy's warning would only be noise)
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            return _float_residual(problem, X, U, active_tol)
    except (DaddyError, ArithmeticError):   # incl. 1 / 0 on Python floats
        return None, np.inf, np.inf


def _stalled(run: _Run, dmax: float, opts: SolverOptions) -> Status | None:
    """Converged, or stalled: Newton converges fast or not at all, so a best residual that did
    not halve over newton_stall_iter iterations, or an exact residual that stays put
    (``_flat``), ends the run."""
    if dmax <= opts.newton.tol:
        return Status.NEWTON_CONVERGED
    if not_halved(run.history, opts.newton.stall_iter) or (
            opts.newton.stall_iter > 0 and _flat(run.current)):
        return Status.NEWTON_STALLED
    return None


def _outer_step(problem: Problem, run: _Run, fx, dmax: float,
                opts: SolverOptions) -> Status | None:
    """One outer iteration of Alg. 11: the constraint model at the iterate, its inner Newton
    steps, and the new iterate (in ``run``); a status when the run ends here."""
    if dmax >= run.prev_dmax and not run.fresh:
        run.maps = None   # the re-centred derivatives did not help: expand afresh
    run.prev_dmax = dmax
    run.fresh = run.maps is None
    X, U = run.X, run.U
    model = ConstraintModel(problem, X, U, opts.newton.active_tol,
                            F=exact_valued_maps(problem, run.maps, X, U, fx, opts.newton.map_reach))
    if run.it == 0 and run.fresh:
        run.start_F = model.F
    sigma = _factorise(model, column_weights(problem, U, opts.newton.control_weight_floor),
                       opts.newton.regularisation)
    if sigma is None:
        return Status.NEWTON_SINGULAR
    dY, inner, model_max = _inner_iterations(model, sigma, dmax, opts)
    run.it += 1
    if inner == 0:
        if not run.fresh:   # re-centred derivatives gave no descent: expand afresh
            run.maps, run.prev_dmax, run.fresh = None, np.inf, True
            return None
        return Status.NEWTON_NO_DESCENT
    if (opts.newton.stall_iter > 0 and run.fresh and dmax > run.best[0]
            and model_max > (1.0 - _FLAT_TOL) * dmax):
        # thrown above its best residual, a fresh model that Newton cannot take down by 1 %
        # has no way back (design notes: no descent on a fresh model)
        return Status.NEWTON_NO_DESCENT
    run.maps = StageMaps.of(model.F, X, U, opts.eps_da)
    run.last = (model, dY)
    run.X, run.U = model.apply(dY)
    return None


def _factorise(model: ConstraintModel, scale: np.ndarray | None,
               reg: float) -> BandedSigma | None:
    """Sigma's factor, with a larger regularisation if it is not positive definite; None when
    it is singular even then."""
    for r in (reg, max(1e-8, 1e3 * reg)):
        try:
            return BandedSigma(model.D, r, scale)
        except (np.linalg.LinAlgError, ValueError):
            continue
    return None


def _inner_iterations(model: ConstraintModel, sigma: BandedSigma, dmax: float,
                      opts: SolverOptions):
    """Alg. 11's inner loop: Newton steps on the polynomial model, re-using the factorisation,
    each backtracked until it reduces the model's max residual, while the model converges at a
    rate r = log d*_max / log d_max above eps_CV. Returns (dY, number of steps taken, the
    model's max residual at dY)."""
    d = model.residual()
    dY = np.zeros(model.D.shape[1])
    r = np.inf
    inner = 0
    while (dmax > opts.newton.tol and r > opts.newton.cv_ratio
           and inner < opts.newton.inner_max_iter):
        step, ahead = _corrected(model, sigma, dY, sigma.step(d), dmax)
        found = _backtrack(model, dY, step, d, dmax, opts, ahead)
        if found is None:
            break
        alpha, dstar = found
        dY = dY + alpha * step
        d = dstar
        new_max = float(np.max(np.abs(d)))
        r = np.log(new_max) / np.log(dmax) if 0 < dmax < 1 and new_max > 0 else np.inf
        dmax = new_max
        inner += 1
    return dY, inner, dmax


def _corrected(model: ConstraintModel, sigma: BandedSigma, dY: np.ndarray, step: np.ndarray,
               dmax: float) -> tuple[np.ndarray, np.ndarray]:
    """The Newton step, or its second-order correction when the full step does not reduce
    the model's max residual and the corrected one does: step - W D^T Sigma^-1 d(dY + step),
    on the same factorisation; with the model's residual at dY + the step returned (which
    ``_backtrack`` takes instead of evaluating it again).

    Rationale: the full step's residual is the model's second-order term alone, which a step
    turning a full-thrust control along its thrust sphere makes dominant; the correction removes
    it to first order (Nocedal & Wright, sec. 18.3; design notes: second-order correction)."""
    ahead = model.residual(dY + step)
    if not float(np.max(np.abs(ahead))) >= dmax:   # (the full step will do; or NaN: as before)
        return step, ahead
    fixed = step + sigma.step(ahead)
    there = model.residual(dY + fixed)
    return (fixed, there) if float(np.max(np.abs(there))) < dmax else (step, ahead)


def _backtrack(model: ConstraintModel, dY: np.ndarray, step: np.ndarray, d: np.ndarray,
               dmax: float, opts: SolverOptions, ahead: np.ndarray | None = None):
    """The first of alpha = 1, s, s^2, ... (s = newton_ls_shrink, newton_ls_max_halvings
    trials) at which the model's max residual at dY + alpha step is below dmax, with that
    residual; None if there is none (ahead: the residual at dY + step, if already evaluated).

    The model is a polynomial of degree 2 in Y, so along the step its residual is exactly
    d + alpha r1 + alpha^2 r2 (d: the residual at dY): the trial at alpha = 1 and one at
    alpha = -1 give every trial's value at once (a failed step took up to 25 evaluations of
    the model, 70 % of a stalled restoration's inner loop on Earth-Mars). The trial chosen is
    evaluated directly, and accepted on that value, so round-off in the quadratic can only
    skip a trial that ties with dmax."""
    def below(cand):
        return float(np.max(np.abs(cand))) < dmax   # (False for a NaN)

    if ahead is None:
        ahead = model.residual(dY + step)
    if below(ahead):
        return 1.0, ahead
    alphas = opts.newton.ls_shrink ** np.arange(1, opts.newton.ls_max_halvings)
    back = model.residual(dY - step)
    with np.errstate(invalid="ignore", over="ignore"):   # (a non-finite quadratic: below)
        r1, r2 = 0.5 * (ahead - back), 0.5 * (ahead + back) - d
        line = np.max(np.abs(d + alphas[:, None] * (r1 + alphas[:, None] * r2)), axis=1)
    if not np.all(np.isfinite(r1 + r2)):
        line = np.zeros_like(alphas)   # (no usable quadratic: try every step directly)
    for alpha in alphas[line < dmax]:
        cand = model.residual(dY + alpha * step)
        if below(cand):
            return alpha, cand
    return None
