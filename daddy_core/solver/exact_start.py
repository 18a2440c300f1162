"""The exact warm start: a warm re-plan of a bang-bang plan solved in the exact fuel form from
the start, before any DDP (``SolverOptions.end_game.exact_start``).

Rationale: a re-plan starts next to a plan that was the exact fuel optimum (``throttle``: thrust
as throttle s and direction), for a state a little off that plan. Written in the form, the
plan's switching structure is its working set: every stage at full thrust (s = 1) or coasting
(s = 0) sits on a bound, within ``newton.active_tol``. Newton's restoration (Alg. 11) in the
form holds those bounds as equalities and corrects the directions and the few intermediate
throttles by the minimum-norm step that meets the dynamics and the terminal constraints: the
neighbouring bang-bang plan. Its propellant differs from the re-optimised one's at second
order in the correction (measured: the same to 1e-7 of the mass on the halo and Earth-Mars
re-plans, docs/design-notes.md: exact warm start), for a fraction of a continuation's cost;
with a finite ``kkt.tol`` the KKT polishing of the form (``kkt_polish``) then takes it to a KKT
point as far as the time budget allows. The DDP of the last pseudo-Huber step (the warm
pipeline before) re-shaped a bang-bang plan into a smooth one with more propellant.

A restoration that does not converge within ``end_game.exact_start_iter`` Newton iterations
(one or two where the structure fits; quadratic convergence or none) says the state is too far
off the plan for its switching structure, or the thrust bound cannot reach the target from it:
the solve then goes on as without this option (restoration, continuation, end game).
"""
from __future__ import annotations

import math

import numpy as np

from ..problem import Problem
from ..throttle import throttle_form
from . import newton
from .context import SolveContext
from .end_game import EXACT, End, Game, count_kkt_work, polished_fuel_with_form
from .homotopy import HomotopyResult
from .kkt_polish import kkt_polish
from .lagrangian import Multipliers
from .optimality import objective, optimality
from .solution import WarmStart


def exact_start_wanted(ctx: SolveContext) -> bool:
    """A polished fuel-optimal solve of a problem with an exact fuel form whose options ask
    for the exact warm start."""
    return ctx.opts.end_game.exact_start and polished_fuel_with_form(ctx)


def exact_opening(ctx: SolveContext, U0: np.ndarray, warm: WarmStart) -> Game | None:
    """The final game of an exact warm start from the controls U0 (N, 3) (module docstring),
    or None when Newton cannot restore them in the exact form."""
    problem, opts = ctx.problem, ctx.opts
    form = throttle_form(problem, U0)
    fuel = form.problem
    V = form.controls(U0)
    with ctx.clock.phase("rollout"):
        X = _start_states(fuel, V, warm)
    if not np.all(np.isfinite(X)):
        return None
    with ctx.clock.phase("restore"):
        res = newton.polish(fuel, X, V, opts.with_(
            newton=dict(max_iter=min(opts.newton.max_iter, opts.end_game.exact_start_iter))),
            ctx.clock.deadline)
    ctx.work.restore += res.iterations
    ctx.say(f"exact warm start: Newton in the exact fuel form, {res.iterations} iterations, "
            f"max violation {res.max_violation:.2e} ({res.reason})")
    if not res.converged:
        return None
    X, V, opt, kkt_reason = res.X, res.U, None, ""
    if math.isfinite(opts.kkt.tol):
        with ctx.clock.phase("optimality"):
            opt = optimality(fuel, X, V, EXACT)
        if opt is not None and opt.kkt_residual > opts.kkt.tol:
            with ctx.clock.phase("kkt"):
                kkt = kkt_polish(fuel, X, V, EXACT, opts, opt, ctx.clock.deadline)
            count_kkt_work(ctx, kkt)
            X, V, opt, kkt_reason = kkt.X, kkt.U, kkt.optimality, kkt.reason
    mult = Multipliers.initial(problem, opts.aul.mu_init)
    mult.take_duals(warm.duals)
    U = form.thrust(V)
    end = End(X, U, None, True, "converged", opt, kkt_reason, form,
              objective(fuel, X, V, EXACT))
    hres = HomotopyResult(X, U, None, mult, None, 0.0 if ctx.rho0 is None else ctx.rho0)
    return Game(hres, None, end, final=True)


def _start_states(fuel: Problem, V: np.ndarray, warm: WarmStart) -> np.ndarray:
    """Where the restoration starts: the warm start's states with the problem's x0 (no
    integration: Newton's residuals are exact), else the rollout of V."""
    if warm.X is not None and warm.X.shape == (fuel.N + 1, fuel.nx):
        X = np.array(warm.X, float)
        X[0] = fuel.x0
        return X
    return fuel.rollout(V)
