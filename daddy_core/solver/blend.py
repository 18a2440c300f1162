"""The blended-state start and the restart that falls back on it (a named strategy).

DDP is local, and a start can leave it at a local minimum of the constraint violation: the
Lyapunov L1 -> L2 transfer from random guesses stalled at one point, 0.205 from the target
with the penalty at its cap, where the least-violation solve can only say "no point near
here meets the constraints". The same transfer from the blended states -- the departure orbit
and the arrival orbit joined by a smooth step, handed to the Newton restoration as a state
guess -- converges to the paper's optimum (997.487 kg, 21 s).

``restart_from_blend`` (``EndGameOptions.blend_restart``, on by default, off in the guidance
node's warm re-plans): a solve that ended unconverged, not on its budget or a cancel
(``worth_restarting``) -- on its constraints (what would go to the infeasibility verdict), or
feasible at a point its KKT polishing could not take to a stationary one (Lyapunov from random
guesses: a homotopy that ended 0.3-5.8 kg below the optimum with a KKT residual of 1.4-1.7) --
is solved once more from the blended states; its answer is kept when it converged, else the
first solve's answer and verdict stand. Never for a solve that started from a state guess (it
would start where it failed).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..errors import DaddyError
from ..problem import Problem
from .infeasibility import unmet
from .options import SolverOptions, UnrestoredStates
from .solution import Solution, WarmStart
from .start import same_start

PAPER_GUESS = 1e-6   # the paper's cold guess on every control component (``solve``'s default)
# A feasible end with a KKT residual (relative to the largest cost-gradient component) above
# this is not near a stationary point: worth a restart (100x the default tol_optimality; the
# polishing stalls of tight tolerances, 1e-7-1e-5, are round-off near one, where a restart
# from elsewhere would only cost time).
FAR_FROM_STATIONARY = 1e-2


def blended_states(problem: Problem) -> np.ndarray | None:
    """(N+1, nx) the departure orbit (the ballistic rollout from x_0) and the arrival orbit
    (x_target propagated backwards; the components the target does not give taken from the
    departure) joined by the smooth step s = 3t^2 - 2t^3 of the normalised independent
    variable t; None where either does not propagate to finite states (a flow that raises
    included: PDDP's costate flow from its target, whose mass entry is a placeholder 0,
    divides by the mass; an integration through a singularity exceeds its steps)."""
    p = problem
    zero = np.zeros(p.nu)
    try:
        with np.errstate(all="ignore"):
            departure = p.rollout(np.zeros((p.N, p.nu)))
            arrival = np.empty_like(departure)
            target = np.asarray(p.x_target, float)
            arrival[-1] = departure[-1]
            arrival[-1, :target.size] = target[:p.nx]
            for k in range(p.N - 1, -1, -1):
                arrival[k] = np.asarray(p.step(arrival[k + 1], zero, -p.stage_dt[k]), float)
    except (DaddyError, ArithmeticError):   # (an integration that cannot go on, 1 / 0)
        return None
    if not (np.all(np.isfinite(departure)) and np.all(np.isfinite(arrival))):
        return None
    arrival[:, target.size:] = departure[:, target.size:]
    t = np.concatenate([[0.0], np.cumsum(p.stage_dt)]) / float(np.sum(p.stage_dt))
    s = (t * t * (3.0 - 2.0 * t))[:, None]
    return (1.0 - s) * departure + s * arrival


def worth_restarting(sol: Solution, opts: SolverOptions, out_of_time: bool) -> bool:
    """``sol`` ended unconverged, not on its budget or a cancel, either on its constraints
    (max violation above tol_aul) or feasible with a KKT residual above FAR_FROM_STATIONARY
    (module docstring). Never without ``StartOptions.restore``: the blended states are a guess
    for the restoration, and without it the restart would solve the paper's cold controls
    (PDDP's costate stages: a zero primer vector)."""
    if sol.converged or out_of_time or not opts.start.restore:
        return False
    return unmet(sol, opts, out_of_time) or (sol.kkt_residual is not None
                                             and sol.kkt_residual > FAR_FROM_STATIONARY)


def restart_from_blend(problem: Problem, sol: Solution, opts: SolverOptions, solve_again,
                       remaining_s: float | None,
                       first: np.ndarray | None = None) -> Solution | None:
    """The solve from the blended states (module docstring) when it converged, else None.
    ``solve_again(p, guess, options)``: the caller's solve; ``remaining_s``: what is left of
    the time budget (None: unbounded); ``first``: (N, nu) the controls the solve that ended
    unconverged started from, if known. Where the blend is not restored the restart would go
    on from the rollout of the paper's cold guess; when that is where the first solve started
    (``start.same_start``) it stops there instead (``UnrestoredStates.STOP``): it would repeat
    that solve."""
    if remaining_s is not None and remaining_s <= 0.0:
        return None
    X = blended_states(problem)
    if X is None:
        return None
    cold = np.full((problem.N, problem.nu), PAPER_GUESS)
    repeat = first is not None and same_start(problem, problem.rollout(first),
                                                 problem.rollout(cold))
    o = opts.with_(run=dict(time_budget_s=remaining_s),
                   end_game=dict(blend_restart=False, certify_infeasibility=False),
                   start=dict(unrestored_states=UnrestoredStates.STOP if repeat
                              else opts.start.unrestored_states))
    again = solve_again(problem, WarmStart(U=cold, X=X), o)
    if not again.converged:
        return None
    return replace(again, reason=f"{again.reason} (restarted from the blended states: the "
                                 f"solve from the guess had ended unconverged, max violation "
                                 f"{sol.max_violation:.2e}: {sol.reason})")
