"""The AUL's second-order multiplier update (``AULOptions.multiplier_update``): after a DDP
solve, the multipliers are those of the KKT system of the Lagrangian's quadratic model at the
solve's trajectory. This is the λ-block of the Newton step on (Y, λ), with the same working
set, Hessian and sparse solve as one KKT polishing step (``kkt_polish.kkt_step``):

    [H  A^T] [dY]   [-c]
    [A  0  ] [λ ] = [-g]

HDDP, the DA-HDDP paper and PDDP all update their multipliers this way. On a problem with
linear dynamics and constraints and a quadratic cost the model is exact, so one update gives
the optimal multipliers, and the next DDP solve ends feasible.
"""
from __future__ import annotations

import numpy as np

from ..errors import DaddyError
from .kkt_polish import hessians, kkt_step
from .lagrangian import Multipliers
from .optimality import every_constraint, optimality
from .options import SolverOptions
from .sweeps import Stages


def second_order(st: Stages, mult: Multipliers, opts: SolverOptions) -> Multipliers | None:
    """The multipliers of the KKT system at ``st``'s trajectory (module docstring), in the
    AUL's layout: path (n_c, N) and terminal (n_t,); inequality multipliers held >= 0, every
    one within lambda_max, penalties grown as eq. 9 does. None when the system cannot be
    formed or solved (a singular model): the caller falls back to eq. 9."""
    p, X, U = st.problem, st.X, st.U
    try:
        model = every_constraint(p, X, U)
        opt = optimality(p, X, U, st.hom, model=model)
        if opt is None:
            return None
        _, H = hessians(p, X, U, st.hom, model, opt.multipliers)
        g = model.residual()
        ineq = model.inequality_rows()
        work = ~ineq | (g > -opts.newton.active_tol)
        _, mu = kkt_step(H, 0.0, model.D, opt.gradient, g, ineq, work)
    except (DaddyError, ArithmeticError, np.linalg.LinAlgError, ValueError, RuntimeError):
        return None
    nc, nt, N = mult.lam.shape[0], mult.lam_t.size, p.N
    rows = N * (nc + p.nx)
    if mu is None or mu.size != rows + nt or not np.all(np.isfinite(mu)):
        return None
    lam = mu[:rows].reshape(N, nc + p.nx)[:, :nc].T.copy()
    lam_t = mu[rows:].copy()
    lam[:mult.n_ineq] = np.maximum(lam[:mult.n_ineq], 0.0)
    lam_t[:mult.n_tineq] = np.maximum(lam_t[:mult.n_tineq], 0.0)
    clip = opts.aul.lambda_max
    return Multipliers(np.clip(lam, -clip, clip),
                       np.minimum(mult.mu * opts.aul.mu_growth, opts.aul.mu_max),
                       np.clip(lam_t, -clip, clip),
                       np.minimum(mult.mu_t * opts.aul.mu_growth, opts.aul.mu_max),
                       mult.n_ineq, mult.n_tineq)
