"""Where DDP starts: the initial rollout (through a warm start's stage maps where they reach)
and, with ``SolverOptions.start.restore``, Newton's restoration of feasibility (paper Alg. 11 on the
guess) with its named fallbacks: the ballistic trajectory for a cold guess Newton cannot
restore, and the problem without ``g_path`` for a start that meets everything else.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..errors import DaddyError
from ..problem import Problem
from . import newton
from .context import SolveContext
from .options import UnrestoredStates
from .solution import WarmStart


@dataclass
class Start:
    """The iterate the homotopy starts from (after the restoration, if any).

    X: (N+1, nx), U: (N, nu); restored: a converged restoration of the problem itself (a
    feasible iterate to fall back on); F: DA stage maps at (X, U), if known; states_lost: a
    state guess was given and not restored (X is the rollout of U instead)."""

    X: np.ndarray
    U: np.ndarray
    restored: newton.NewtonResult | None = None
    F: object = None
    states_lost: bool = False


def start(ctx: SolveContext, U0: np.ndarray, warm: WarmStart) -> Start:
    """The initial rollout of U0 (N, nu) and, with ``opts.start.restore``, its restoration --
    from the warm start's states when it gives them without maps (a state guess: a blend of
    the departure and arrival orbits, another solver's trajectory), else from the rollout."""
    problem, opts = ctx.problem, ctx.opts
    maps = warm.maps
    if maps is not None and maps.N != problem.N:
        raise DaddyError(f"maps cover {maps.N} stages, the problem has {problem.N}")
    # a start for the Newton restoration only needs to be near (its residuals are exact): the
    # maps then serve stages up to map_reach radii
    reach = opts.newton.map_reach if opts.start.restore else 1.0
    with ctx.clock.phase("rollout"):
        X = problem.rollout(U0) if maps is None else maps.rollout(problem, U0, reach)[0]
    if not np.all(np.isfinite(X)):
        raise DaddyError("the initial guess propagates to a non-finite state")
    if not opts.start.restore:
        return Start(X, U0)
    states = None if maps is not None else guess_states(problem, warm.X)
    # (a state guess that is the only start to try gets no ballistic fallback either)
    only_states = states is not None and opts.start.unrestored_states is UnrestoredStates.STOP
    with ctx.clock.phase("restore"):
        return _restored(ctx, X, U0, maps,
                         cold=maps is None and warm.duals is None and not only_states,
                         reach=reach, states=states)


def guess_states(problem: Problem, X) -> np.ndarray | None:
    """A state guess (N+1, nx) checked, with the problem's x0 in row 0; None for None."""
    if X is None:
        return None
    X = np.array(X, dtype=float)
    shape = (problem.N + 1, problem.nx)
    if X.shape != shape:
        raise DaddyError(f"WarmStart.X must be {shape} states at the stage ends, got shape "
                         f"{X.shape}")
    bad = np.flatnonzero(~np.all(np.isfinite(X), axis=1))
    if bad.size:
        raise DaddyError(f"WarmStart.X has non-finite states at stage ends {bad[:5].tolist()}")
    X[0] = problem.x0
    return X


def _restored(ctx: SolveContext, X, U0, maps, cold: bool, reach: float,
              states: np.ndarray | None = None) -> Start:
    """The start after Newton's restoration of (X, U0) -- or of (``states``, U0), whose
    failure starts from (X, U0) -- and its fallbacks."""
    problem = ctx.problem
    first = X if states is None else states
    res = _restore(ctx, problem, first, U0, maps, cold)
    relaxed = False
    if not res.converged and problem.g_path is not None:
        # the restoration without the path constraint: the AUL takes a start that meets the
        # rest from there (design notes: restore without g_path)
        alt = _restore(ctx, replace(problem, g_path=None), first, U0, maps, cold)
        if alt.converged:
            res, relaxed = alt, True
    st = Start(X, U0)
    if res.converged:
        st.X, st.U = res.X, res.U
        if not relaxed:
            st.restored = res
        if res.maps is not None:
            # DDP starts from the Newton model's maps, re-centred as Newton re-centres them,
            # with the restored flows as their values
            st.F = newton.exact_valued_maps(problem, res.maps, res.X, res.U, res.X[1:].T,
                                            ctx.opts.newton.map_reach)
    elif maps is not None and reach > 1:
        st.X = maps.rollout(problem, U0)[0]   # DDP starts from a consistent trajectory
    elif states is None:   # DDP starts from the guess, where Newton's first model expanded it
        st.F = res.start_F
    else:
        st.states_lost = True
    ctx.say(f"start {'restored' if res.converged else 'not restored'} by Newton"
            f"{' (without g_path)' if relaxed else ''}: {res.iterations} iterations, max "
            f"violation {res.max_violation:.2e} ({res.reason})")
    return st


def _restore(ctx: SolveContext, problem: Problem, X, U0, maps,
             cold: bool) -> newton.NewtonResult:
    """Newton's restoration of (X, U0) and, for a cold start it cannot restore, of the
    ballistic trajectory (``_restore_ballistic``); the iterations counted in ``ctx.work``."""
    res = newton.polish(problem, X, U0, ctx.opts, ctx.clock.deadline, maps=maps)
    ctx.work.restore += res.iterations
    if not res.converged and cold:
        ballistic = _restore_ballistic(ctx, problem, X, U0, res)
        if ballistic is not None:
            ctx.work.restore += ballistic.iterations
            res = ballistic if ballistic.converged else res
    return res


# a ballistic trajectory within this fraction of the state's size (max |x|, normalised units)
# of the guess's is the guess itself as far as the restoration can tell
_SAME_START_RTOL = 1e-2


def same_start(problem: Problem, X: np.ndarray, Y: np.ndarray) -> bool:
    """Two trajectories (N+1, nx) of ``problem`` within ``_SAME_START_RTOL`` of the states'
    size (the largest |x| of X and of the target) of each other: the same start as far as
    the restoration can tell."""
    size = max(float(np.max(np.abs(X))), float(np.max(np.abs(problem.x_target))))
    return bool(np.max(np.abs(Y - X)) <= _SAME_START_RTOL * size)


def _restore_ballistic(ctx: SolveContext, problem: Problem, X, U0,
                       stalled: newton.NewtonResult) -> newton.NewtonResult | None:
    """Newton's restoration of the ballistic trajectory (zero control) for a cold guess (X, U0)
    it could not restore; None when the guess flies it already. Rationale: the ballistic flight
    stays near the departure orbit where a thrusting guess left the model poor (design notes)."""
    Ub = np.zeros_like(U0)
    Xb = problem.rollout(Ub)
    if not np.all(np.isfinite(Xb)) or same_start(problem, X, Xb):
        return None
    res = newton.polish(problem, Xb, Ub, ctx.opts, ctx.clock.deadline)
    ctx.say(f"guess not restored ({stalled.reason}); ballistic start: {res.iterations} "
            f"iterations, max violation {res.max_violation:.2e} ({res.reason})")
    return res
