"""Augmented Lagrangian outer loop (paper Alg. 4, eq. 8-9), ALTRO-style."""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .ddp import DDPStats, ddp
from .expansion import Multipliers, Stages, constraint_values, max_violation


@dataclass
class AULResult:
    stages: Stages
    mult: Multipliers
    max_violation: float
    converged: bool
    iterations: int
    reason: str
    rho: float = 0.0
    gains: object = None  # Gains of the last backward sweep (None if no DDP iteration ran)


def update_multipliers(mult: Multipliers, g, gt, opts) -> Multipliers:
    """Eq. 9: lam <- max(0, lam + mu g) for inequalities, lam + mu g for equalities; mu <- gamma mu."""
    lam, lam_t = mult.lam.copy(), mult.lam_t.copy()
    if g is not None:
        lam = lam + mult.mu * g
        lam[:mult.n_ineq] = np.maximum(lam[:mult.n_ineq], 0.0)
    if gt is not None:
        lam_t = lam_t + mult.mu_t * gt
        lam_t[:mult.n_tineq] = np.maximum(lam_t[:mult.n_tineq], 0.0)
    clip = opts.lambda_max
    return Multipliers(np.clip(lam, -clip, clip), np.minimum(mult.mu * opts.mu_growth, opts.mu_max),
                       np.clip(lam_t, -clip, clip),
                       np.minimum(mult.mu_t * opts.mu_growth, opts.mu_max),
                       mult.n_ineq, mult.n_tineq)


def aul(problem, X, U, mult: Multipliers, hom, sweep: str, dyn: bool, opts, stats: DDPStats,
        deadline: float | None = None, progress=None, rho0: float | None = None,
        F=None) -> AULResult:
    """Alg. 4: DDP on the augmented cost, multiplier and penalty updates, until the maximum
    constraint violation is below tol_aul. rho0: Quu regularisation to start from (None:
    opts.rho_init); with opts.carry_rho each DDP solve resumes from the previous one's.
    F: stage maps at (X, U) if already known (else expanded here)."""
    st = Stages(problem, X, U, mult, hom, opts.eps_da, F=F)
    gains = None
    reason = "aul_max_iter reached"
    gmax = np.inf
    rho, rho_last = rho0, opts.rho_init if rho0 is None else rho0
    for it in range(1, opts.aul_max_iter + 1):
        res = ddp(st, sweep, dyn, opts, stats, deadline, rho0=rho)
        rho_last = res.rho
        gains = res.gains or gains
        rho = res.rho if opts.carry_rho else rho0
        st = res.stages
        g, ni, gt, nti = constraint_values(problem, st.X, st.U)
        gmax = max(max_violation(g, ni), max_violation(gt, nti))
        if progress is not None:
            progress(f"  AUL {it:2d}: DDP {res.iterations:3d} it ({res.reason}), "
                     f"cost {st.cost:.6e}, max violation {gmax:.2e}")
        if deadline is not None and time.perf_counter() > deadline:
            return AULResult(st, mult, gmax, False, it, "time budget exceeded", rho_last, gains)
        if gmax <= opts.tol_aul:
            return AULResult(st, mult, gmax, True, it, "max violation below tol_aul", rho_last, gains)
        mult = update_multipliers(mult, g, gt, opts)
        st = Stages(problem, st.X, st.U, mult, hom, opts.eps_da, F=st.F)
    return AULResult(st, mult, gmax, False, opts.aul_max_iter, reason, rho_last, gains)
