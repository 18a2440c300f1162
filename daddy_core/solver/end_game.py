"""The end game of a solve: from the homotopy's end to the answer, as an ordered tuple of named
attempts (``Attempt``), each run on the ``Game`` so far; the first that ends it ``final`` wins.

- Newton polishing (Alg. 11) follows every continuation (``polished``);
- ``EXACT_FROM_ENERGY_STEP``: a fuel-optimal solve KKT-polishes the exact fuel form
  (``throttle``: thrust as throttle and direction) from the energy step's solution;
- ``RESUME_HOMOTOPY``: else the rest of the homotopy (eq. 12-14) from there;
- ``EXACT_FROM_HOMOTOPY_END``: the exact fuel form again, from the homotopy's end;
- ``PSEUDO_HUBER_KKT``: the KKT polishing of the last step's own (pseudo-Huber) cost;
- ``RESOLVE``: a KKT polishing stalled above tol_optimality hands the last step back to DDP.

Success is one test (``meets_tol``); the work of every attempt, kept or not, is counted in
``SolveContext.work``.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ..problem import Problem
from ..throttle import ThrottleForm, has_throttle_form, throttle_form
from . import newton
from .assemble import duals
from .context import SolveContext
from .homotopy import HomotopyResult, continuation, joined, resume_duals
from .kkt_polish import kkt_polish
from .optimality import Optimality, objective, optimality
from .start import Start
from .stage_maps import StageMaps, expand_dynamics

# the stage cost's (h, delta) argument for the exact fuel form, whose cost ignores it
EXACT = (1.0, 0.0)


@dataclass
class End:
    """A candidate answer: the iterate, its maps, whether it is feasible and why not, its
    optimality, and (an exact fuel end) the form whose optimality and cost it reports."""

    X: np.ndarray
    U: np.ndarray
    maps: StageMaps | None
    converged: bool
    reason: str
    optimality: Optimality | None = None
    kkt_reason: str = ""
    form: ThrottleForm | None = None
    cost: float | None = None   # the objective solved, when not the last homotopy step's


@dataclass
class Game:
    """The state of the end game: the homotopy run so far, its start (None: an exact warm
    start, ``exact_start``, ran no continuation), the current end, and whether an attempt
    ended the game."""

    hres: HomotopyResult
    start: Start | None
    end: End
    final: bool = False


@dataclass(frozen=True)
class Attempt:
    """A named end-game attempt: ``run(ctx, game)`` when ``applies(ctx, game)``."""

    name: str
    applies: Callable[[SolveContext, Game], bool]
    run: Callable[[SolveContext, Game], Game]


def meets_tol(end: End, ctx: SolveContext) -> bool:
    """A feasible end whose KKT residual is at most tol_optimality."""
    return (end.converged and end.optimality is not None
            and end.optimality.kkt_residual <= ctx.opts.kkt.tol)


def _polishable(end: End, ctx: SolveContext) -> bool:
    """A polished solve's feasible end whose evaluated KKT residual is above tol_optimality."""
    return (ctx.polish and end.converged and end.optimality is not None
            and end.optimality.kkt_residual > ctx.opts.kkt.tol)


def homotopy(ctx: SolveContext, X, U, steps: tuple, **kw) -> HomotopyResult:
    """The one entry to the continuation (AUL -> DDP on each step), timed as "ddp"."""
    with ctx.clock.phase("ddp"):
        return continuation(ctx.problem, X, U, steps, ctx.method, ctx.opts, ctx.stats,
                            ctx.clock.deadline, ctx.progress, **kw)


def polished_fuel_with_form(ctx: SolveContext) -> bool:
    """A polished fuel-optimal solve of a problem with an exact fuel form (``throttle``)."""
    return ctx.polish and ctx.steps[-1][0] > 0 and has_throttle_form(ctx.problem)


def exact_wanted(ctx: SolveContext) -> bool:
    """A polished fuel-optimal solve of a problem with an exact fuel form whose options ask for
    it (``SolverOptions.end_game.exact_fuel``) and for a KKT residual."""
    opts = ctx.opts
    return (opts.end_game.exact_fuel and math.isfinite(opts.kkt.tol)
            and polished_fuel_with_form(ctx))


def opening(ctx: SolveContext, start: Start, duals: dict | None) -> Game:
    """The continuation from the start -- its first step only when the exact fuel attempts
    follow, else every step -- and Newton's polishing of its end."""
    steps = ctx.steps[:1] if exact_wanted(ctx) else ctx.steps
    hres = homotopy(ctx, start.X, start.U, steps, rho=ctx.rho0, duals=duals, F=start.F,
                    numbering=(0, len(ctx.steps)))
    return Game(hres, start, polished(ctx, hres, start))


def play(ctx: SolveContext, game: Game) -> Game:
    """Run the end game's attempts in order until one ends it (none after a final opening)."""
    if game.final:
        return game
    for attempt in (EXACT_END_GAME if exact_wanted(ctx) else PSEUDO_HUBER_END_GAME):
        if attempt.applies(ctx, game):
            game = attempt.run(ctx, game)
            if game.final:
                break
    return game


def polished(ctx: SolveContext, hres: HomotopyResult, start: Start) -> End:
    """The homotopy's last finite iterate -- or the restored start when the homotopy failed
    after a restoration -- after Newton's polishing (Alg. 11, when ``ctx.polish``), with its
    KKT residual."""
    X, U, st = hres.X, hres.U, hres.stages
    maps = start.restored.maps if start.restored is not None else None
    if np.array_equal(st.X, X):
        maps = StageMaps.of(st.F, st.X, st.U, ctx.opts.eps_da)
    end = End(X, U, maps, hres.converged, hres.reason)
    fallback = start.restored is not None and not hres.converged
    if fallback:   # DDP did not finish: return the feasible, Newton-restored start
        end.X, end.U = start.restored.X, start.restored.U
        end.reason += "; returned the Newton-restored start"
    if ctx.polish and not fallback and not hres.diverged:
        _newton_polish(ctx, end, hres)
    elif hres.stalled and end.converged:   # nothing else can meet the constraints
        end.converged, end.reason = False, hres.stalled
    with ctx.clock.phase("optimality"):
        if end.converged and math.isfinite(ctx.opts.kkt.tol):   # (feasible only)
            end.optimality = optimality(ctx.problem, end.X, end.U, hres.stages.hom, end.maps)
    return end


def _newton_polish(ctx: SolveContext, end: End, hres: HomotopyResult) -> None:
    """Alg. 11 on ``end`` in place (fresh expansions unless ``polish_from_ddp_maps``)."""
    opts = ctx.opts
    with ctx.clock.phase("newton"):
        res = newton.polish(ctx.problem, end.X, end.U, opts, ctx.clock.deadline,
                            maps=end.maps if opts.newton.polish_from_ddp_maps else None)
    ctx.work.newton += res.iterations
    ctx.say(f"newton: {res.iterations} iterations, max violation {res.max_violation:.2e} "
            f"({res.reason})")
    if res.improved:
        end.X, end.U = res.X, res.U
        end.maps = res.maps or end.maps
    if not res.converged:   # (after a stalled AUL: the constraints cannot be met here)
        end.converged, end.reason = False, "; ".join(
            filter(None, (hres.stalled, f"newton polishing: {res.reason}")))


def _kkt(ctx: SolveContext, end: End, hom: tuple) -> End:
    """The KKT polishing (``kkt_polish``) of ``end`` at the homotopy point ``hom``, in place."""
    opt = end.optimality
    with ctx.clock.phase("kkt"):
        res = kkt_polish(ctx.problem, end.X, end.U, hom, ctx.opts, opt, ctx.clock.deadline)
    ctx.say(f"KKT polishing: {res.iterations} iterations, KKT residual {opt.kkt_residual:.2e} "
            f"-> {res.optimality.kkt_residual:.2e} ({res.reason})")
    end.X, end.U, end.optimality, end.maps = res.X, res.U, res.optimality, res.maps or end.maps
    count_kkt_work(ctx, res)
    end.kkt_reason = res.reason
    return end


def count_kkt_work(ctx: SolveContext, res) -> None:
    """A KKT polishing's work (``KKTResult``): its iterations and its restorations' Newton."""
    ctx.work.newton += res.newton_iterations
    ctx.work.kkt += res.iterations


def _exact_fuel(ctx: SolveContext, end: End, stall_iter: int) -> End | None:
    """A copy of the feasible, polished ``end`` KKT-polished in the exact fuel form
    (``throttle``), with the form's optimality, fresh stage maps and the exact propellant cost;
    None when the form's KKT residual cannot be evaluated there."""
    problem, opts = ctx.problem, ctx.opts
    with ctx.clock.phase("kkt"):
        form = throttle_form(problem, end.U)
        fuel = form.problem
        V = form.controls(end.U)
        opt = optimality(fuel, end.X, V, EXACT)
        if opt is None:
            return None
        res = kkt_polish(fuel, end.X, V, EXACT,
                         opts.with_(kkt=dict(max_iter=opts.end_game.exact_fuel_max_iter)),
                         opt, ctx.clock.deadline, stall_iter)
        count_kkt_work(ctx, res)
        ctx.say(f"exact fuel (throttle and direction): {res.iterations} KKT iterations, "
                f"residual {opt.kkt_residual:.2e} -> {res.optimality.kkt_residual:.2e} "
                f"({res.reason})")
        U = form.thrust(res.U)
        return replace(
            end, X=res.X, U=U, optimality=res.optimality,
            maps=StageMaps.of(expand_dynamics(problem, res.X[:-1], U), res.X, U, opts.eps_da),
            kkt_reason=res.reason, form=form, cost=objective(fuel, res.X, res.U, EXACT))


def _exact_attempt(stall_option: str) -> Callable[[SolveContext, Game], Game]:
    """The exact fuel form polished from the game's end, stopped after the option
    ``stall_option``'s iterations without halving; the game ends when it meets tol."""
    def run(ctx: SolveContext, game: Game) -> Game:
        tried = _exact_fuel(ctx, game.end, getattr(ctx.opts.end_game, stall_option))
        if tried is not None and meets_tol(tried, ctx):
            return replace(game, end=tried, final=True)
        return game
    return run


def _resume(ctx: SolveContext, game: Game) -> Game:
    """The rest of the homotopy from the first step's solution, then Newton's polishing."""
    ctx.say("the rest of the homotopy from the first step's solution")
    done, before = game.hres, len(game.hres.history)
    more = homotopy(ctx, done.X, done.U, ctx.steps[1:], rho=ctx.rho0,
                    duals=resume_duals(ctx.problem, done, ctx.opts),
                    numbering=(before, before + len(ctx.steps) - 1))
    hres = joined(done, more)
    return replace(game, hres=hres, end=polished(ctx, hres, game.start))


def _pseudo_huber_kkt(ctx: SolveContext, game: Game) -> Game:
    """The KKT polishing of the last homotopy step's own cost."""
    return replace(game, end=_kkt(ctx, game.end, game.hres.stages.hom))


def _resolve(ctx: SolveContext, game: Game) -> Game:
    """The last homotopy step solved again (AUL + DDP, Newton, KKT polishing) from the polished
    end with its KKT multipliers, at most ``end_game.resolves`` times while the polishing stalls;
    a new end is kept when it improves on the old (``improves``). Rationale: DDP is the
    globalised method, and the KKT multipliers start it where its last solve stopped."""
    for _ in range(ctx.opts.end_game.resolves):
        if not (_polishable(game.end, ctx) and not ctx.clock.out_of_time()):
            break
        game = _resolve_once(ctx, game)
    return game


def _resolve_once(ctx: SolveContext, game: Game) -> Game:
    hres, end, hom = game.hres, game.end, ctx.steps[-1]
    ctx.say(f"KKT polishing stalled at {end.optimality.kkt_residual:.2e}: the last homotopy "
            "step again from the polished iterate with its KKT multipliers")
    again = homotopy(ctx, end.X, end.U, (hom,),
                     duals=duals(ctx.problem, end.X, end.U, end.optimality, hres, ctx.opts))
    new = polished(ctx, again, Start(end.X, end.U))
    if _polishable(new, ctx):
        new = _kkt(ctx, new, hom)
    counted = dict(aul_iterations=hres.aul_iterations + again.aul_iterations,
                   history=hres.history + [dict(h, resolve=True) for h in again.history])
    if not improves(ctx.problem, hom, new, end):
        return replace(game, hres=replace(hres, **counted))
    return replace(game, end=new, hres=replace(
        again, gains=again.gains or hres.gains, converged=hres.converged, reason=hres.reason,
        stalled=hres.stalled, **counted))


def improves(problem: Problem, hom: tuple, new: End, old: End) -> bool:
    """A re-solved end replaces the polished one when it is feasible with a smaller KKT
    residual at no higher cost (the objective at ``hom``): far from a KKT point the residual
    alone is not enough (design notes: a re-solve is kept only if no costlier)."""
    return (new.converged and new.optimality is not None
            and new.optimality.kkt_residual < old.optimality.kkt_residual
            and objective(problem, new.X, new.U, hom) <= objective(problem, old.X, old.U, hom))


def _always(ctx: SolveContext, game: Game) -> bool:
    return True


def _converged(ctx: SolveContext, game: Game) -> bool:
    return game.end.converged


def _more_steps(ctx: SolveContext, game: Game) -> bool:
    return len(ctx.steps) > 1


EXACT_FROM_ENERGY_STEP = Attempt(
    "exact fuel from the energy step",
    lambda ctx, game: _more_steps(ctx, game) and _converged(ctx, game),
    _exact_attempt("exact_fuel_stall_iter"))
RESUME_HOMOTOPY = Attempt("the rest of the homotopy", _more_steps, _resume)
EXACT_FROM_HOMOTOPY_END = Attempt("exact fuel from the homotopy's end", _converged,
                                  _exact_attempt("exact_fuel_end_stall_iter"))
PSEUDO_HUBER_KKT = Attempt("pseudo-Huber KKT polishing",
                           lambda ctx, game: _polishable(game.end, ctx), _pseudo_huber_kkt)
RESOLVE = Attempt("re-solve of the last step", _always, _resolve)

EXACT_END_GAME = (EXACT_FROM_ENERGY_STEP, RESUME_HOMOTOPY, EXACT_FROM_HOMOTOPY_END,
                  PSEUDO_HUBER_KKT, RESOLVE)
PSEUDO_HUBER_END_GAME = (PSEUDO_HUBER_KKT, RESOLVE)
