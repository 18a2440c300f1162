"""DADDy (paper Fig. 1) as the pipeline it is:

    context -> exact warm start (a bang-bang plan restored in its form) exact_start.py
            -> start (Alg. 11 restoration and its fallbacks)        solver/context.py, start.py
            -> continuation (eq. 12-14 -> Alg. 4 -> Alg. 3)           homotopy.py, aul.py, ddp.py
            -> end game (Newton / KKT polishing, exact fuel, re-solve) end_game.py
            -> assemble (re-propagation check, verdict, duals)         assemble.py
            -> hold between nodes (path constraints' exchange)         path_exchange.py

Each step lives in its own module; this one only chains them.
"""
from __future__ import annotations

import time
from dataclasses import replace
from typing import Callable

import numpy as np

from ..errors import DaddyError
from ..path_constraints import violated_at_start
from ..phases import phase_report
from ..policy import feedback_policy, fuel_policy
from ..problem import Problem
from . import end_game, infeasibility, path_exchange
from .assemble import repropagation_miss, solution, unsolved, within_thrust_bound
from .blend import PAPER_GUESS, restart_from_blend, worth_restarting
from .context import Clock, SolveContext
from .deadline import CancelFlag
from .exact_start import exact_opening, exact_start_wanted
from .homotopy import homotopy_steps
from .options import Method, SolverOptions, UnrestoredStates
from .solution import Solution, WarmStart
from .start import start


def solve(problem: Problem, u_guess: np.ndarray | Solution | WarmStart | None = None,
          method: Method | str = Method.DYN, fuel_optimal: bool | None = None,
          polish: bool = True, options: SolverOptions | None = None,
          case_name: str | None = None, progress: Callable[[str], None] | None = None,
          cancel: CancelFlag | None = None) -> Solution:
    """Solve ``problem`` with DADDy.

    Args:
        problem: a ``Problem``.
        u_guess: (N, nu) initial controls, a ``Solution`` to warm-start from, or a
            ``WarmStart`` (controls, duals, rho, stage maps); None: 1e-6 everywhere.
        method: a ``Method`` or its name: std, hess, q, dyn, hessdyn, qdyn (paper Table 1).
        fuel_optimal: run the whole homotopy of ``options.homotopy`` (True; the default
            ``fuel.FUEL_HOMOTOPY`` when the options name only the energy step, and a DaddyError
            when the stage cost ignores ``hom``) or only its first, energy-optimal step
            (False). None: the whole homotopy when it has more than one step.
        polish: finish with the Newton polishing (Alg. 11) and the KKT end game.
        options: ``SolverOptions``.
        progress: callable receiving progress lines (or None; ``options.run.verbose``: print).
        cancel: a flag with ``is_set()`` (a ``threading.Event``): once set, the solve stops
            within one iteration and returns its best point so far, ``converged=False`` with
            the reason 'cancelled by the caller'.
    Returns:
        a ``Solution``. A solve that fails returns ``converged=False`` with the reason and the
        best feasible-so-far iterate (never NaN).
    """
    layout = problem.parameters
    if layout is not None:   # static parameters (``static_parameters``): the user's guess padded
        u_guess = _padded_guess(layout, u_guess)
    sol = _solve(problem, u_guess, method, fuel_optimal, polish, options, case_name, progress,
                 cancel)
    order = (options or SolverOptions()).policy.order
    if layout is None:
        if order:   # an exact fuel optimum has its form's laws (``policy``)
            _attach_policy(problem, sol, order,
                           fuel_policy if sol.exact_fuel else feedback_policy)
        return sol
    if order:
        sol.policy_error = "feedback laws are not built for static-parameter problems yet"
    sol.parameters = layout.values(sol.X)
    if layout.base is None:   # phases: the augmented trajectory, and each phase in the user's view
        sol.phases = phase_report(problem, sol.X, sol.U, sol.duals)
        return sol
    X, U, dt = layout.user_view(sol.X, sol.U, sol.stage_dt)
    a, b = sol.gains_a, sol.gains_b
    return replace(sol, X=X, U=U, stage_dt=dt, stage_maps=None,
                   gains_a=a[:, :layout.nu] if a.ndim == 2 else a,
                   gains_b=b[:, :layout.nu, :layout.nx] if b.ndim == 3 else b)


def _attach_policy(problem: Problem, sol: Solution, order: int, build) -> None:
    """``sol.policy``: the feedback laws ``build`` makes of a converged solve
    (``daddy_core.policy``), or in ``sol.policy_error`` why there are none; the solution itself
    is kept either way."""
    if not sol.converged:
        sol.policy_error = "the solve did not converge: no feedback laws"
        return
    try:
        sol.policy = build(problem, sol, order)
    except DaddyError as exc:
        sol.policy_error = str(exc)


def _padded_guess(layout, guess):
    """A guess for a static-parameter problem: a user's controls padded with idle increments;
    a solution in the user's view padded with the increments that set its parameters (its
    stage maps are the augmented problem's no more)."""
    if guess is None or isinstance(guess, WarmStart):
        return guess
    if isinstance(guess, Solution):
        if guess.U.ndim == 2 and guess.U.shape[1] == layout.nu:
            return replace(guess, U=layout.padded(guess.U, guess.parameters), stage_maps=None)
        return guess
    return layout.padded(guess)


def _solve(problem: Problem, u_guess, method, fuel_optimal, polish, options, case_name,
           progress, cancel) -> Solution:
    """``solve`` (its arguments) once the guess has the problem's shape."""
    opts = options or SolverOptions()
    method = Method.parse(method)
    if progress is None and opts.run.verbose:
        progress = print

    def once(p: Problem, guess, fuel: bool | None, o: SolverOptions) -> Solution:
        warm = WarmStart.of(guess, p.stage_dt, o.ddp.carry_rho, p.t_start)
        U0 = p.check_guess(np.full((p.N, p.nu), PAPER_GUESS) if warm.U is None else warm.U)
        ctx = SolveContext(p, method, o, homotopy_steps(p, U0, o, fuel), polish,
                           Clock(o.run.time_budget_s, cancel=cancel), progress=progress,
                           rho0=warm.rho)
        why = None if p.g_path is None else violated_at_start(p, U0[0], o.newton.tol)
        if why is None and o.end_game.certify_infeasibility:
            end = infeasibility.contradicted_end(p, o)
            why = None if end is None else end.reason()
        if why is not None:   # infeasible before any iteration: the guess, within the bound
            _, U0, _ = within_thrust_bound(p, None, U0, o.newton.tol)
            return replace(unsolved(p, U0, why, ctx.steps, method, case_name), infeasible=True)
        game = exact_opening(ctx, U0, warm) if exact_start_wanted(ctx) else None
        if game is None:
            st = start(ctx, U0, warm)
            if st.states_lost and o.start.unrestored_states is UnrestoredStates.STOP:
                return unsolved(p, U0, "the state guess was not restored, and the options "
                                "stop there (start.unrestored_states)", ctx.steps, method,
                                case_name)
            game = end_game.opening(ctx, st, warm.duals)
        return solution(ctx, end_game.play(ctx, game), case_name)

    clock = Clock(opts.run.time_budget_s, cancel=cancel)
    sol = once(problem, u_guess, fuel_optimal, opts)
    if problem.g_path is not None:   # (an infeasible end's guess gets its margin measured)
        sol = path_exchange.hold(problem, sol, lambda p, warm, o: once(p, warm, None, o), opts,
                                 progress)
    if sol.infeasible:   # known before any iteration (x0 or the end contradicts the rows)
        return sol
    def remaining():
        return (None if opts.run.time_budget_s is None
                else opts.run.time_budget_s - (time.perf_counter() - clock.start))

    if (opts.end_game.blend_restart and not _state_guess(u_guess)
            and worth_restarting(sol, opts, clock.out_of_time())):
        if progress is not None:
            progress(f"  unconverged (max violation {sol.max_violation:.2e}): solved again "
                     "from the blended states")
        again = restart_from_blend(problem, sol, opts, lambda p, guess, o: _solve(
            p, guess, method, fuel_optimal, polish, o, case_name, progress, cancel), remaining(),
            _start_controls(problem, u_guess))
        if again is not None:
            return again
    if not infeasibility.wanted(sol, opts, clock.out_of_time()):
        return sol
    if progress is not None:
        progress(f"  unmet constraints ({sol.max_violation:.2e}): a least-violation solve "
                 "asks whether any trajectory meets them")
    return infeasibility.certify(problem, sol, opts, lambda p, U0, o: _solve(
        p, U0, method, False, polish, o, case_name, progress, cancel), remaining())


def _start_controls(problem: Problem, guess) -> np.ndarray:
    """(N, nu) the controls a solve of ``problem`` from ``guess`` starts from (the paper's
    cold guess for None)."""
    U = WarmStart.of(guess, problem.stage_dt, False, problem.t_start).U
    return np.full((problem.N, problem.nu), PAPER_GUESS) if U is None else np.asarray(U, float)


def _state_guess(guess) -> bool:
    """The guess gives states (a ``WarmStart`` with X): a restart from the blend is another
    state guess, not a fallback for it."""
    return isinstance(guess, WarmStart) and guess.X is not None


__all__ = ["repropagation_miss", "solve"]
