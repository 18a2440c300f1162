"""The Solution of a solve: figures of merit, the DOP853 re-propagation check
(``repropagation_miss``), the verdict (feasible to tol_newton and KKT residual to
tol_optimality), timings, and what a warm start needs (``duals``: the KKT multipliers)."""
from __future__ import annotations

import math
import time
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from ..errors import DaddyError
from ..integrators import dop853, dop853_batch
from ..problem import Problem, largest
from ..throttle import ThrottleForm
from .context import SolveContext
from .homotopy import HomotopyResult
from .optimality import Optimality, objective
from .options import Method, SolverOptions
from .solution import Solution
from .stage_maps import StageMaps

if TYPE_CHECKING:   # (the end game builds on this module's duals)
    from .end_game import Game


def _describe(r: dict) -> str:
    """One entry of ``Problem.violation_report`` as the reason of a failed solve names it."""
    label = "" if r.get("label") is None else f" ({r['label']})"
    stage = "" if r["stage"] is None else f" (stage {r['stage']})"
    return f"{r['name']}{label} {r['violation']:.2e}{stage}"


def repropagation_miss(problem: Problem, U: np.ndarray, X: np.ndarray | None = None,
                       maps: StageMaps | None = None) -> float | None:
    """Terminal miss (max terminal-constraint violation) after re-propagating U from x0 with
    DOP853 at rtol = atol = 1e-12, stage by stage (``integrators.dop853``: solve_ivp's scheme and
    step control); inf when the re-propagation fails (NaN or inf dynamics).

    Each stage's first trial step is the whole stage (scipy's initial-step heuristic costs two
    rhs calls and usually picks a shorter step); the error control still accepts only steps
    within the tolerances.

    With the trajectory X (N+1, nx) that U was solved on and its stage maps (``StageMaps``
    whose radius holds (X, U)), every stage is re-propagated at once from its own start X_k
    (``dop853_batch``, the same steps as one at a time) and the stage defects d_k =
    DOP853(X_k, U_k) - X_{k+1} are carried to the end through the maps' state Jacobians: x_N
    = X_N + e_N, e_{k+1} = Phi_k e_k + d_k, e_0 = x0 - X_0 -- the sequential re-propagation
    to first order in e, whose neglected second-order terms are below round-off while every
    |e_k| <= ``_LINEAR_REPROPAGATION`` (else the stages are integrated one after the other
    from x0). A converged many-revolution solution is re-propagated in milliseconds instead
    of ~13 Python rhs calls per stage (4960 LEO stages: 0.5 s of a warm re-plan)."""
    if problem.rhs is None:
        x = problem.rollout(U)[-1]
    else:
        x = _linear_repropagation(problem, U, X, maps)
        if x is None:
            x = problem.x0.copy()
            try:
                for k in range(problem.N):
                    x = dop853(problem.rhs, x, U[k], problem.stage_t0[k], problem.stage_dt[k],
                               rtol=1e-12, atol=1e-12)
            except DaddyError:
                return math.inf
    if problem.terminal_constraints(x)[0] is None:
        return None
    return problem.terminal_violation(x)


# the largest deviation e_k from the solved states that the linearised re-propagation carries
# (its second-order remainder ~ |f_xx| e^2 stays below round-off of the states)
_LINEAR_REPROPAGATION = 1e-7


def _linear_repropagation(problem: Problem, U: np.ndarray, X: np.ndarray | None,
                          maps: StageMaps | None) -> np.ndarray | None:
    """x_N of ``repropagation_miss``'s linearised re-propagation, or None when it does not
    apply (no states or maps, maps expanded farther from (X, U) than their radius, a failed
    stage, or a deviation beyond _LINEAR_REPROPAGATION)."""
    if X is None or maps is None or maps.N != problem.N or not maps.deviation(X, U)[1].all():
        return None
    nx = problem.nx
    try:
        flows = dop853_batch(problem.rhs, X[:-1].T, U.T, problem.stage_t0, problem.stage_dt,
                             rtol=1e-12, atol=1e-12)
    except DaddyError:
        return None
    defects = flows.T - X[1:]                                                # (N, nx)
    # Phi_k[i, j] = d x_{k+1, i} / d x_{k, j}: the maps' linear coefficients (M, nx, N) of the
    # state variables
    phi = np.ascontiguousarray(np.transpose(maps.F.c[1:nx + 1], (2, 1, 0)))  # (N, nx, nx)
    E = np.empty((problem.N + 1, nx))
    E[0] = problem.x0 - X[0]
    for k in range(problem.N):
        np.add(phi[k] @ E[k], defects[k], out=E[k + 1])
    if not np.max(np.abs(E)) <= _LINEAR_REPROPAGATION:   # (or NaN)
        return None
    return X[-1] + E[-1]


def within_thrust_bound(problem: Problem, X: np.ndarray, U: np.ndarray,
                        tol: float) -> tuple[np.ndarray, np.ndarray, bool]:
    """(X, U) of an answer, with every control whose norm exceeds the thrust bound
    ``Problem.u_max`` by more than ``tol`` (relative) scaled onto it and the states flown
    again from x0, and whether that was needed. A solve cut off by its time budget, or one
    whose augmented Lagrangian never raised the penalty enough, ends at an iterate that can
    break the bound many times over (Lyapunov from a random guess: 41 times, at 120 s); no
    engine can fly that, so the answer is the nearest thrust that can be flown -- its
    constraints' violations, reported with it, are then those of a flyable trajectory. Left
    as it is when the flown states would not be finite, and for problems whose control is
    not a thrust vector alone (no bound, or static parameters among the controls)."""
    if not problem.u_max or problem.parameters is not None:
        return X, U, False
    norm = np.linalg.norm(U, axis=1)
    over = norm > problem.u_max * (1.0 + tol)
    if not np.any(over):
        return X, U, False
    V = U.copy()
    V[over] *= (problem.u_max / norm[over])[:, None]
    with np.errstate(all="ignore"):
        Y = problem.rollout(V)
    if not (np.all(np.isfinite(Y)) and np.all(np.isfinite(V))):
        return X, U, False
    return Y, V, True


def solution(ctx: SolveContext, game: Game, case_name: str | None) -> Solution:
    """The Solution of the game's final end: its violations, the re-propagation check, the
    verdict and reason, timings, iterations, gains and the duals a warm start takes. An end
    that breaks the thrust bound is answered within it (``within_thrust_bound``)."""
    problem, opts, end, hres = ctx.problem, ctx.opts, game.end, game.hres
    X, U, bounded = within_thrust_bound(problem, end.X, end.U, opts.newton.tol)
    if bounded:
        game = replace(game, end=replace(end, X=X, U=U, maps=None, optimality=None, cost=None,
                                         converged=False, reason=(
            f"{end.reason}; the controls above the thrust bound were scaled onto it and the "
            "trajectory flown again from x0")))
        end = game.end
    violations = problem.violation_report(X, U)   # one evaluation of the constraints
    gmax = largest(0.0, *(r["violation"] for r in violations))
    with ctx.clock.phase("repropagation"):
        miss = repropagation_miss(problem, U, X, end.maps)
    converged, reason = _verdict(ctx, game, gmax, miss, violations)
    opt, gains, stats, t = end.optimality, hres.gains, ctx.stats, ctx.clock.times
    N, nu, nx = problem.N, problem.nu, problem.nx
    return Solution(
        **_described(problem, X, U, ctx.steps, ctx.method, case_name, end.cost),
        converged=converged, reason=reason,
        gains_a=gains.a if gains else np.zeros((N, nu)),
        gains_b=gains.b if gains else np.zeros((N, nu, nx)), max_violation=gmax,
        kkt_residual=None if opt is None else opt.kkt_residual, repropagation_miss=miss,
        iterations={"restore": ctx.work.restore, "homotopy": len(hres.history),
                    "aul": hres.aul_iterations, "ddp": stats.iterations,
                    "newton": ctx.work.newton, "kkt": ctx.work.kkt},
        runtime_s={"total": time.perf_counter() - ctx.clock.start,
                   **{k: t.get(k, 0.0) for k in ("rollout", "restore", "ddp", "newton")},
                   "forward": stats.forward_s, "expansion": stats.expansion_s,
                   "backward": stats.backward_s,
                   **{k: t.get(k, 0.0) for k in ("repropagation", "optimality", "kkt")}},
        history=hres.history, polynomial_share=stats.polynomial_share, violations=violations,
        duals=duals(problem, X, U, opt, hres, opts, end.form), rho=float(hres.rho),
        stage_maps=end.maps, exact_fuel=end.form is not None)


def _verdict(ctx: SolveContext, game: Game, gmax: float, miss: float | None,
             violations: list) -> tuple[bool, str]:
    """Converged and why not: the end's own verdict, then the constraints (unpolished solves:
    to tol_aul), the re-propagation, the KKT residual (polished solves: to tol_optimality)."""
    opts, end = ctx.opts, game.end
    converged, reason = end.converged, end.reason
    if not ctx.polish and not gmax <= opts.aul.tol:   # (NaN: not converged)
        converged = False
    if miss is not None and not math.isfinite(miss):
        converged, reason = False, "the DOP853 re-propagation of the final controls failed"
    if not converged:   # say which constraints the returned iterate does not meet
        worst = [r for r in violations[:3] if r["violation"] > opts.newton.tol]
        if worst:
            reason += "; largest violations: " + ", ".join(_describe(r) for r in worst)
    opt = end.optimality
    if ctx.polish and converged and math.isfinite(opts.kkt.tol) and (
            opt is None or opt.kkt_residual > opts.kkt.tol):
        converged = False
        reason = ("the KKT residual could not be evaluated" if opt is None else
                  f"KKT residual {opt.kkt_residual:.2e} above tol_optimality "
                  f"{opts.kkt.tol:g} after {ctx.work.kkt} KKT iterations "
                  f"({end.kkt_reason})")
    return converged, reason


def _described(problem: Problem, X: np.ndarray, U: np.ndarray, steps: tuple, method: Method,
               case_name: str | None, cost: float | None = None) -> dict:
    """The Solution fields that describe (X, U) of ``problem`` whatever the solve did: what
    was solved, the trajectory, its cost (``cost``, the objective solved, or at the last
    homotopy step) and its mass figures."""
    m, units = problem.mass_index, problem.units
    return dict(
        case=case_name or problem.name, method=method.value,
        fuel_optimal=len(steps) > 1 or (steps[0][0] > 0), X=X, U=U,
        stage_dt=problem.stage_dt.copy(), t_start=problem.t_start,
        time_index=problem.time_index,
        cost=objective(problem, X, U, steps[-1]) if cost is None else cost,
        final_mass_kg=float(X[-1, m] * units.mu_kg) if m is not None else None,
        propellant_kg=float((X[0, m] - X[-1, m]) * units.mu_kg) if m is not None else None,
        units=units.as_dict())


def unsolved(problem: Problem, U0: np.ndarray, reason: str, steps: tuple, method: Method,
              case_name: str | None) -> Solution:
    """The Solution of a problem refused before any iteration (``converged=False``, the reason):
    the guess's own rollout (finite: ``start.start`` checks it the same way)."""
    X = problem.rollout(U0)
    if not np.all(np.isfinite(X)):
        raise DaddyError("the initial guess propagates to a non-finite state")
    violations = problem.violation_report(X, U0)
    N, nu, nx = problem.N, problem.nu, problem.nx
    return Solution(
        **_described(problem, X, U0, steps, method, case_name), converged=False, reason=reason,
        gains_a=np.zeros((N, nu)), gains_b=np.zeros((N, nu, nx)),
        max_violation=largest(0.0, *(r["violation"] for r in violations)),
        repropagation_miss=None, violations=violations,
        iterations={"restore": 0, "homotopy": 0, "aul": 0, "ddp": 0, "newton": 0, "kkt": 0},
        runtime_s={"total": 0.0})


def duals(problem: Problem, X, U, opt: Optimality | None, hres: HomotopyResult,
           opts: SolverOptions, form: ThrottleForm | None = None) -> dict:
    """The multipliers a warm start from this solution takes: the least-squares KKT
    multipliers of (X, U) (``optimality``) when evaluated, 0 for an inequality inactive there
    (below -newton_active_tol), else those the last AUL solve ran with. Rationale: an AUL's own
    multipliers lag the optimum's by mu g, and a warm start re-learns them (design notes)."""
    if opt is None:
        return hres.mult.as_duals()
    if form is not None:   # opt is the exact fuel form's: its rows, less the throttle bound's
        problem, U = form.problem, form.controls(U)
    g, ni, gt, nti = problem.constraint_values(X, U)
    nc, nt = (0 if g is None else g.shape[0]), (0 if gt is None else gt.shape[0])
    split = opt.constraint_multipliers(problem.N, problem.nx, nc, nt)
    if split is None or not np.all(np.isfinite(opt.multipliers)):
        return hres.mult.as_duals()
    lam, lam_t = split
    if nc:
        lam[:ni][g[:ni] < -opts.newton.active_tol] = 0.0
    if nt:
        lam_t[:nti][gt[:nti] < -opts.newton.active_tol] = 0.0
    if form is not None:
        lam = form.stage_duals(lam)
    return {"lam": lam.tolist(), "lam_t": lam_t.tolist()}
