"""KKT polishing: Newton steps on the first-order optimality conditions of a feasible iterate
(SQP on a working set), each followed by Newton's feasibility restoration (Alg. 11).

Rationale: DDP stops on a relative cost decrease below tol_ddp, which on an ill-conditioned
problem happens far from a stationary point (docs/design-notes.md: KKT polishing). Newton on
the KKT conditions uses what the solver already has -- order-2
expansions of the dynamics, costs and constraints, and the least-squares multipliers of
``optimality`` -- and converges quadratically near a KKT point.

One iteration, over Y = [u_0, x_1, ..., u_{N-1}, x_N] (Newton's layout), every stage
expanded afresh at the iterate (re-centred maps carry derivative errors that turned the
convergence linear):
  - the working set W: every equality (stage defects h_k = x_{k+1} - f(x_k, u_k), path and
    terminal equalities) and the inequalities within ``newton_active_tol`` of their bound;
  - the Lagrangian Hessian H, block-diagonal in z_k = [x_k, u_k]: the stage cost's Hessian
    plus mu_g . d2 g_k minus lam_k . d2 f_k (the defect's sign), and the terminal block, with
    the multipliers of the previous QP (the first: ``optimality``'s least-squares ones);
  - the equality-constrained QP step from the KKT system (sparse LU)
        [H + delta I   A_W^T] [dY]   [-c  ]
        [A_W           0    ] [mu] = [-g_W],
    an inequality of W whose new multiplier is negative leaves W (it wants to leave its
    bound) and the system is solved again (bounded passes);
  - Levenberg-Marquardt-like shifts delta (``_SHIFTS``, relative to H's largest diagonal
    entry): from the level the last iteration ended on, a shift is refused when the KKT
    system is singular, the model predicts no decrease, or the cost at Y + dY misses its own
    quadratic model by more than ``kkt_cost_slack`` predicted decreases (the step left the region
    where the cost is quadratic, e.g. a coasting control across the kink of the fuel cost) or
    its point cannot be flown (``_trial``);
    else the step is restored to feasibility (``_restore``) and kept when the cost fell by at
    least a tenth of the prediction. A step that delivered three quarters of it lowers the
    next iteration's level by one. No shift kept: the polishing stops.
Every iterate it returns is feasible to tol_newton and no more costly than the one it got.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import da
from ..errors import DaddyError
from ..problem import Problem, largest, max_violation
from .deadline import Deadline, passed
from .newton import (BandedSigma, ConstraintModel, NewtonResult, column_weights, polish,
                     stage_columns)
from .optimality import Optimality, every_constraint, objective, optimality
from .options import SolverOptions
from .results import Status, StepResult, not_halved
from .stage_maps import StageMaps

# Hessian shifts (relative to its largest diagonal entry): Levenberg-Marquardt-like levels
_SHIFTS = (0.0,) + tuple(10.0 ** k for k in range(-10, 3))
_MAX_DROPS = 5                     # passes that drop inequalities with negative multipliers
_SOLVE_TOL = 1e-8                  # largest relative residual of a KKT solve taken as solved


@dataclass
class KKTResult(StepResult):
    X: np.ndarray
    U: np.ndarray
    optimality: Optimality | None
    maps: StageMaps | None        # fresh expansions at (X, U)
    newton_iterations: int


def kkt_polish(problem: Problem, X, U, hom, opts: SolverOptions, optimality0: Optimality,
               deadline: Deadline | None = None, stall_iter: int = 0) -> KKTResult:
    """From a feasible (X, U) whose first-order optimality is ``optimality0``, Newton on the
    KKT conditions (module docstring) until the KKT residual is at most opts.kkt.tol,
    for at most opts.kkt.max_iter iterations, or (``stall_iter`` > 0) until the lowest residual
    so far has not halved over ``stall_iter`` iterations (``Status.KKT_STALLED``: the residual
    is not monotone -- a step that changes the working set can raise it). Every iterate's
    stage maps are expanded afresh:
    re-centred maps carry derivative errors that the Hessian and Jacobian of a Newton step on
    the KKT conditions cannot afford (its convergence turned linear with them)."""
    opt, f = optimality0, objective(problem, X, U, hom)
    mu = opt.multipliers   # the Lagrangian's: then each QP's own (Newton on (Y, mu))
    level = 0              # index into _SHIFTS, carried between iterations
    it = newton_its = 0
    status = Status.KKT_MAX_ITER
    lowest = [opt.kkt_residual]     # the lowest residual after each iteration
    try:
        model = every_constraint(problem, X, U)
    except (DaddyError, ArithmeticError, ValueError):
        return KKTResult(False, 0, Status.KKT_NO_DESCENT, X, U, opt, None, 0)
    while it < opts.kkt.max_iter:
        if opt.kkt_residual <= opts.kkt.tol:
            status = Status.KKT_CONVERGED
            break
        if passed(deadline):
            status = deadline.status
            break
        if not_halved(lowest, stall_iter):
            status = Status.KKT_STALLED
            break
        it += 1
        try:
            step = _iteration(problem, X, U, hom, f, model, mu, opt.gradient, level, opts,
                              deadline)
            if step is not None:
                model = every_constraint(problem, step[0], step[1])
                new = optimality(problem, step[0], step[1], hom, model=model)
        except (DaddyError, ArithmeticError, np.linalg.LinAlgError, ValueError,
                RuntimeError):
            step = None
        if step is None or new is None:
            status = Status.KKT_NO_DESCENT
            break
        X, U, f, n_its, mu, level = step
        newton_its += n_its
        opt = new
        lowest.append(min(lowest[-1], opt.kkt_residual))
    return KKTResult(opt.kkt_residual <= opts.kkt.tol, it, status, X, U, opt,
                     StageMaps.of(model.F, X, U, opts.eps_da), newton_its)


def _iteration(problem: Problem, X, U, hom, f: float, model: ConstraintModel,
               mu: np.ndarray, c: np.ndarray, level: int, opts: SolverOptions, deadline):
    """One KKT step (module docstring) from the Hessian shift ``level``, raised until the
    restored step lowers the cost by at least a tenth of the quadratic model's prediction:
    (X, U, cost, Newton iterations, the QP's multipliers, the next level), or None when no
    shift does. c: the cost gradient at (X, U)."""
    Hf, H = hessians(problem, X, U, hom, model, mu)
    g = model.residual()
    ineq = model.inequality_rows()
    work = ~ineq | (g > -opts.newton.active_tol)
    scale = max(float(np.max(np.abs(H.diagonal()), initial=0.0)), 1e-12)
    maps = StageMaps.of(model.F, X, U, opts.eps_da)
    restore_opts = opts.with_(newton=dict(max_iter=opts.kkt.restore_iter,
                                          stall_iter=opts.kkt.restore_stall_iter))
    newton_its = 0
    for lv in range(level, len(_SHIFTS)):
        shift = _SHIFTS[lv] * scale
        dY, mu_new = kkt_step(H, shift, model.D, c, g, ineq, work)
        if dY is None:
            continue
        predicted = -(c @ dY + 0.5 * (dY @ (H @ dY)))
        if not predicted > 0:
            continue   # no descent on the model (negative curvature along the step): shift more
        Xt, Ut = model.apply(dY)
        cost_model = c @ dY + 0.5 * (dY @ (Hf @ dY))
        res = _trial(problem, model, Xt, Ut, hom, f + cost_model, opts.kkt.cost_slack * predicted,
                     opts.kkt.trial_violation * float(np.max(np.abs(dY))), restore_opts,
                     deadline, maps)
        if res is None:
            continue
        newton_its += res.iterations
        if not res.converged:
            continue
        fa = objective(problem, res.X, res.U, hom)
        if f - fa >= 0.1 * predicted:
            good = f - fa >= 0.75 * predicted
            return res.X, res.U, fa, newton_its, mu_new, max(lv - 1, 0) if good else lv
        if passed(deadline):
            break
    return None


def _trial(problem: Problem, model: ConstraintModel, X, U, hom, cost_model: float,
           slack: float, step: float, opts: SolverOptions, deadline,
           maps: StageMaps) -> NewtonResult | None:
    """The restoration (``_restore``) of the KKT step's point (X, U), or None when the step is
    refused: its cost misses ``cost_model`` (the cost's own quadratic model there) by more than
    ``slack`` -- the step left the region where the cost is quadratic (e.g. a coasting control
    across the kink of the fuel cost), refused before the costly restoration -- or its
    constraints, whose linearisation the step meets, are violated by more than ``step``
    (``kkt_trial_violation`` times max |dY|): the remainder is second order in the step, and
    one that large means the step left the region where the model holds (a cost linear in the
    controls, as the exact fuel form's, cannot tell: its first unshifted steps took the
    Earth-Mars throttle to 1e7, and their Newton restorations cost 2.6 s of a 4.6 s solve) --
    or the point cannot be flown. The smallest shifts' long steps can leave the elements'
    domain (NaN from a square root in the dynamics on a small LEO raise, KKT residual 1.35:
    the stage integration raised, and the whole polishing stopped with "no KKT step lowered
    the cost" before any larger shift was tried); a larger shift then takes a shorter step.
    numpy's warnings on such a point would only be noise."""
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        try:
            if not abs(objective(problem, X, U, hom) - cost_model) <= slack:
                return None
            return _restore(problem, model, X, U, opts, deadline, maps, step)
        except (DaddyError, ArithmeticError, ValueError, np.linalg.LinAlgError):
            return None


def _restore(problem: Problem, model: ConstraintModel, X, U, opts: SolverOptions, deadline,
             maps: StageMaps, refuse_above: float = np.inf) -> NewtonResult | None:
    """Feasibility after a KKT step. The step met the constraints' linearisation, so what is
    left is second order: chord iterations -- minimum-norm corrections on the step's own
    Jacobian (``model``'s D, factorised once) with exact float residuals -- usually take it
    below tol_newton at the cost of one float integration each. When they do not, Newton
    (Alg. 11) with at most ``opts.newton.max_iter`` iterations (``kkt.restore_iter``), stopped
    as soon as its residual has not halved over ``newton.stall_iter`` of them
    (``kkt.restore_stall_iter``): Newton converges fast or not at all, and a step whose
    restoration does not left the region where the linearisation holds -- a larger shift is
    cheaper (design notes: restoration stall). None (refused) when (X, U) violates the
    constraints by more than ``refuse_above``."""
    ineq = model.inequality_rows()
    rows, sigma, last = None, None, np.inf
    Xc, Uc = X, U
    for it in range(opts.kkt.chord_iter):
        values, violation = _exact_values(problem, Xc, Uc)
        if it == 0 and not violation <= refuse_above:   # (or NaN)
            return None
        if not violation < 0.5 * last:   # (or NaN) chords that do not converge fast stop
            break
        if violation <= opts.newton.tol:
            return NewtonResult(True, it, Status.NEWTON_CONVERGED, Xc, Uc, violation, True, None)
        if rows is None:   # the equalities and the inequalities at or past their bound
            rows = ~ineq | (values > -opts.newton.active_tol)
            sigma = BandedSigma(model.D[rows], opts.newton.regularisation, column_weights(
                problem, U, opts.newton.control_weight_floor))   # Newton's weighted steps
        Xc, Uc = model.apply(sigma.step(values[rows]), Xc, Uc)
        last = violation
    return polish(problem, X, U, opts, deadline, maps=maps)   # from the step, not the chords'


def _exact_values(problem: Problem, X, U):
    """Every constraint's value at (X, U) in the rows of ``every_constraint``'s model (stage
    defects from one batched float integration) and the max violation."""
    fx = problem.stage_flows(X, U)                                          # (nx, N)
    g, ni, gt, nti = problem.constraint_values(X, U)
    h = X[1:].T - fx
    stages = h if g is None else np.vstack([np.asarray(g, float), h])
    values = np.concatenate([stages.T.ravel(), np.zeros(0) if gt is None else
                             np.asarray(gt, float)])
    violation = largest(float(np.max(np.abs(h))), max_violation(g, ni), max_violation(gt, nti))
    return values, violation


def kkt_step(H: sp.csr_matrix, shift: float, D: sp.csr_matrix, c: np.ndarray, g: np.ndarray,
          ineq: np.ndarray, work: np.ndarray):
    """The working-set QP step dY and its multipliers (in D's rows, zero off the working set)
    (module docstring); (None, None) if the KKT matrix is singular."""
    import scipy.sparse as sp   # (lazy, as in newton: import time)
    from scipy.sparse.linalg import splu
    n = H.shape[0]
    work = work.copy()
    Hs = (H + shift * sp.identity(n, format="csr")) if shift else H
    for _ in range(_MAX_DROPS):
        A = D[work]
        m = A.shape[0]
        K = sp.bmat([[Hs, A.T], [A, -1e-14 * sp.identity(m)]], format="csc")
        rhs = np.concatenate([-c, -g[work]])
        lu = splu(K)
        sol = lu.solve(rhs)
        if not (np.all(np.isfinite(sol))
                and np.max(np.abs(K @ sol - rhs)) <= _SOLVE_TOL * np.max(np.abs(rhs))):
            return None, None   # (nearly) singular: H is singular on A's null space
        mu = np.zeros(work.shape)
        mu[work] = sol[n:]
        leaving = ineq & work & (mu < 0)
        if not leaving.any():
            break
        work &= ~leaving
    return sol[:n], mu


def hessians(problem: Problem, X, U, hom, model: ConstraintModel, mu: np.ndarray):
    """The cost's and the Lagrangian's Hessians over Y (N w x N w each, w = nx + nu), from the
    order-2 expansions of the costs and of the model (every constraint in its rows,
    ``every_constraint``) with the multipliers mu in those rows."""
    p = problem
    nx, nu, N = p.nx, p.nu, p.N
    w = nx + nu
    nc = model.g_active.shape[0]
    per_stage = mu[:N * (nc + nx)].reshape(N, nc + nx)
    mu_t = mu[N * (nc + nx):]
    z = da.variables(np.concatenate([X[:-1].T, U.T]), order=2)
    l = p.stage_cost(z[:nx], z[nx:], p.stage_dt, hom)
    lzz = l.hessian() if isinstance(l, da.DA) else np.zeros((N, w, w))     # (N, n, n)
    phi = p.terminal_cost(da.variables(X[-1], order=2), p.x_target)
    phixx = phi.hessian() if isinstance(phi, da.DA) else np.zeros((nx, nx))
    Hk = lzz - np.einsum("kj,jkab->kab", per_stage[:, nc:], model.F.hessian())
    if model.G is not None:
        Hk = Hk + np.einsum("kc,ckab->kab", per_stage[:, :nc], model.G.hessian())
    Ht = phixx if model.Gt is None else \
        phixx + np.einsum("t,tab->ab", mu_t, model.Gt.hessian())
    return _over_y(lzz, phixx, nx, nu), _over_y(Hk, Ht, nx, nu)


def _over_y(Hk: np.ndarray, Ht: np.ndarray, nx: int, nu: int) -> sp.csr_matrix:
    """Stage blocks Hk (N, n, n) in z_k = [x_k, u_k] and the terminal block Ht (nx, nx) on x_N
    as one sparse matrix over Y (x_0 is fixed: its rows and columns are left out)."""
    N, w = Hk.shape[0], nx + nu
    cols = stage_columns(np.arange(N), nx, nu)                              # (N, n)
    keep = (cols[:, :, None] >= 0) & (cols[:, None, :] >= 0)
    rows = np.broadcast_to(cols[:, :, None], Hk.shape)[keep]
    cc = np.broadcast_to(cols[:, None, :], Hk.shape)[keep]
    xn = (N - 1) * w + nu + np.arange(nx)
    rows = np.concatenate([rows, np.repeat(xn, nx)])
    cc = np.concatenate([cc, np.tile(xn, nx)])
    vals = np.concatenate([Hk[keep], Ht.ravel()])
    import scipy.sparse as sp
    return sp.csr_matrix((vals, (rows, cc)), shape=(N * w, N * w))
