"""Augmented Lagrangian outer loop (paper Alg. 4) and its multiplier/penalty update (eq. 9),
ALTRO-style: DDP on the augmented cost of ``lagrangian`` until the constraints are met. The
safeguards beyond the paper are named hooks in ``aul_safeguards``."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..problem import largest, max_violation
from . import aul_safeguards as safe
from . import multiplier_update
from .deadline import Deadline, passed
from .ddp import DDPResult, DDPStats, ddp
from .lagrangian import Multipliers
from .options import Method, MultiplierUpdate, SolverOptions
from .progress import ProgressLine
from .results import Status, StepResult
from .sweeps import Gains, Stages


@dataclass
class AULResult(StepResult):
    stages: Stages
    mult: Multipliers
    max_violation: float
    rho: float
    gains: Gains | None   # of the last backward sweep (None if no DDP iteration ran)


def update_multipliers(mult: Multipliers, g, gt, opts: SolverOptions) -> Multipliers:
    """Eq. 9: lam <- max(0, lam + mu g) for inequalities, lam + mu g for equalities; mu <- gamma mu."""
    lam, lam_t = mult.lam.copy(), mult.lam_t.copy()
    if g is not None:
        lam = lam + mult.mu * g
        lam[:mult.n_ineq] = np.maximum(lam[:mult.n_ineq], 0.0)
    if gt is not None:
        lam_t = lam_t + mult.mu_t * gt
        lam_t[:mult.n_tineq] = np.maximum(lam_t[:mult.n_tineq], 0.0)
    clip = opts.aul.lambda_max
    return Multipliers(np.clip(lam, -clip, clip),
                       np.minimum(mult.mu * opts.aul.mu_growth, opts.aul.mu_max),
                       np.clip(lam_t, -clip, clip),
                       np.minimum(mult.mu_t * opts.aul.mu_growth, opts.aul.mu_max),
                       mult.n_ineq, mult.n_tineq)


def _next_multipliers(st: Stages, mult: Multipliers, g, gt, opts: SolverOptions) -> Multipliers:
    """The multipliers of the next DDP solve: eq. 9, or the second-order update where the
    options ask for it and its KKT system can be solved (``multiplier_update``)."""
    if opts.aul.multiplier_update is MultiplierUpdate.SECOND_ORDER:
        new = multiplier_update.second_order(st, mult, opts)
        if new is not None:
            return new
    return update_multipliers(mult, g, gt, opts)


def aul(st: Stages, method: Method, opts: SolverOptions, stats: DDPStats,
        deadline: Deadline | None = None, progress=None, rho0: float | None = None) -> AULResult:
    """Alg. 4 from the expanded nominal ``st`` (its multipliers and homotopy point): DDP on the
    augmented cost, multiplier and penalty updates (eq. 9), until the maximum constraint
    violation is below tol_aul. rho0: Quu regularisation to start from (None: opts.ddp.rho_init);
    with opts.ddp.carry_rho each DDP solve resumes from the previous one's (the trust-region radius
    always does). Stops early when the penalty can do no more (``safe.stalled``) or when its
    first DDP solve diverged (``safe.diverged``: the loop then returns its start)."""
    problem, mult, hom, start = st.problem, st.mult, st.hom, st
    gains, gmax = None, np.inf
    rho, rho_last, radius = rho0, opts.ddp.rho_init if rho0 is None else rho0, math.inf
    history, capped = [], 0   # max violation after each DDP solve; solves at mu_max in a row
    dominated = []            # after each DDP solve: the penalty outweighed the cost
    cut_off = False           # the last DDP solve ran into ddp_max_iter at a feasible point
    for it in range(1, opts.aul.max_iter + 1):
        res, both_cut_off, opts = _ddp_solve(st, method, opts, stats, deadline, rho, radius,
                                             progress, it)
        radius, rho_last, gains = res.radius, res.rho, res.gains or gains
        rho = res.rho if opts.ddp.carry_rho else rho0
        st = safe.without_drift(res.stages, opts, deadline) if method.dyn else res.stages
        mult = st.mult   # (moved by the solve where the terminal multipliers are swept)
        g, ni, gt, nti = problem.constraint_values(st.X, st.U)
        gmax = largest(max_violation(g, ni), max_violation(gt, nti))
        if progress is not None:
            progress(ProgressLine(f"  AUL {it:2d}: DDP {res.iterations:3d} it ({res.reason}), "
                                  f"cost {st.cost:.6e}, max violation {gmax:.2e}",
                                  aul_iteration=it, ddp_iterations=res.iterations,
                                  cost=float(st.cost), max_violation=float(gmax)))
        status = None
        if passed(deadline):
            status = deadline.status
        elif it == 1 and both_cut_off and safe.diverged(
                gmax, gmax_start := problem.violation(start.X, start.U), both_cut_off, opts):
            # (the start, the less violating point, is what the loop returns)
            st, gmax, status = start, gmax_start, Status.AUL_DIVERGED
        elif safe.ends_feasible(res, gmax, cut_off, opts):
            status = Status.AUL_CONVERGED
        else:
            cut_off = gmax <= opts.aul.tol   # (feasible and not ended: DDP hit its bound)
            history.append(gmax)
            dominated.append(safe.penalty_dominates(st))
            capped = capped + 1 if safe.at_cap(mult, opts) else 0   # this solve's penalty
            if safe.stalled(history, capped, opts):
                status = Status.AUL_STALLED
            elif safe.unmoved(history, dominated, opts):
                status = Status.AUL_UNMOVED
        if status is not None:
            return AULResult(status is Status.AUL_CONVERGED, it, status, st, mult, gmax,
                             rho_last, gains)
        mult = _next_multipliers(st, mult, g, gt, opts)
        st = st.with_costs(mult, hom)
    return AULResult(False, opts.aul.max_iter, Status.AUL_MAX_ITER, st, mult, gmax, rho_last,
                     gains)


def _ddp_solve(st: Stages, method: Method, opts: SolverOptions, stats: DDPStats,
               deadline: Deadline | None, rho, radius: float, progress,
               it: int) -> tuple[DDPResult, bool, SolverOptions]:
    """One DDP solve of the loop, and its trust-region retry (``safe.fallback_options``):
    the result, whether both were cut off, and the options the loop goes on with."""
    res = ddp(st, method, opts, stats, deadline, rho0=rho, radius0=radius)
    retry = safe.fallback_options(res, opts)
    if retry is None:
        return res, False, opts
    if progress is not None:
        progress(f"  AUL {it:2d}: DDP {res.iterations:3d} it ({res.reason}) with the line "
                 "search: again from its start with the trust region")
    res = ddp(st, method, retry, stats, deadline, rho0=rho, radius0=radius, retry=True)
    return res, res.status in safe.CUT_OFF, retry
