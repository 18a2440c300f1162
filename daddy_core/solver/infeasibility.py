"""Certified infeasibility (issue 50): a solve that ends with terminal conditions it could not
meet asks whether any trajectory could -- the least-violation problem:

    min_U  1/2 |psi(x_N)|^2      subject to every stage constraint (g_ineq, g_path, g_eq)

the problem's own dynamics, start and stage grid, its terminal equalities psi (``g_teq``)
moved into the cost and everything else held (the thrust bound among them). Its solution
decides the verdict (``Verdict``):

- INFEASIBLE: it holds the stage constraints and still misses psi by more than
  ``INFEASIBLE_MARGIN`` x tol_aul. The solve returns that point -- the least miss found, never
  breaking the bounds -- with the reason "infeasible: ...". The least-violation solve is local:
  where that problem is convex (linear dynamics, convex constraints) its minimum is the global
  one and the verdict a certificate; where it is not (a keep-out zone, nonlinear dynamics) it
  says that no point near this solve's end meets the constraints, and the reason says so;
- FEASIBLE: it meets every constraint: the problem is feasible and the failure is the
  solver's; the solve returns it (feasible, not optimal: ``converged=False``) and says so;
- UNDECIDED: the least-violation solve itself did not settle; the solve's own answer stands.

It runs only after a solve that ended unconverged on its constraints (not on its time budget
or a cancel), within what is left of the budget, and never on the least-violation problem
itself (it has no terminal equalities).
"""
from __future__ import annotations

import enum
import time
from dataclasses import replace

import numpy as np

from ..da import functions as dm
from ..problem import Problem
from .options import Method, SolverOptions
from .solution import Solution

# a least-violation point that misses psi by more than this x tol_aul certifies infeasibility
# (between 1x and this: too close to the tolerance to call either way -- undecided)
INFEASIBLE_MARGIN = 10.0


class Verdict(enum.Enum):
    INFEASIBLE = "infeasible"
    FEASIBLE = "feasible"
    UNDECIDED = "undecided"


def least_violation_problem(problem: Problem) -> Problem | None:
    """The least-violation problem of the module docstring, or None for a problem without
    terminal equalities (nothing to relax: its stage constraints are what failed)."""
    if problem.g_teq is None:
        return None
    g_teq, n = problem.g_teq, problem.nu

    def miss(x, x_target):
        psi = g_teq(x, x_target)
        return 0.5 * dm.dot(psi, psi)

    def no_cost(x, u, dt, hom=(0.0, 1.0)):
        return 0.0 * sum(u[i] for i in range(n)) * dt

    return replace(problem, name=f"{problem.name} (least violation)", stage_cost=no_cost,
                   terminal_cost=miss, g_teq=None)


def unmet(sol: Solution, opts: SolverOptions, out_of_time: bool) -> bool:
    """``sol`` ended unconverged with constraints above tol_aul, not on its budget or a
    cancel."""
    return not sol.converged and not out_of_time and not sol.max_violation <= opts.aul.tol


def wanted(sol: Solution, opts: SolverOptions, out_of_time: bool) -> bool:
    """Certify ``sol``: it ended unmet (``unmet``) and the options ask for the verdict."""
    return unmet(sol, opts, out_of_time) and opts.end_game.certify_infeasibility


def certify(problem: Problem, sol: Solution, opts: SolverOptions, solve_again,
            remaining_s: float | None) -> Solution:
    """``sol`` judged by the least-violation problem (module docstring). ``solve_again(p, U0,
    options)``: a solve of p from the controls U0 (the caller's ``solve`` with its method and
    cancel flag); ``remaining_s``: what is left of the time budget (None: unbounded)."""
    lv = least_violation_problem(problem)
    if lv is None or (remaining_s is not None and remaining_s <= 0.0):
        return sol
    t0 = time.perf_counter()
    o = opts.with_(run=dict(time_budget_s=remaining_s), policy=dict(order=0))
    best = solve_again(lv, np.asarray(sol.U, float), o)
    verdict, miss = judge(problem, best, opts)
    if verdict is Verdict.UNDECIDED:
        return replace(sol, reason=f"{sol.reason}; the least-violation solve did not settle "
                                   f"({best.reason})")
    from .assemble import unsolved   # (assemble imports the solve's modules)
    point = unsolved(problem, best.U, "", (sol.fuel_step or (0.0, 1.0),),
                     Method.parse(sol.method), sol.case)
    if verdict is Verdict.INFEASIBLE:
        worst = point.violations[0]
        reason = (f"infeasible: the least-violation point, every stage constraint held, still "
                  f"misses the terminal conditions by {miss:.3e} (largest: {worst['name']}"
                  + (f", {worst['label']}" if worst["label"] else "") + "; the least miss found "
                  "from this solve's end: a local minimum where the problem is not convex); the "
                  f"solve had ended: {sol.reason}")
    else:
        reason = (f"{sol.reason}; the problem is feasible: the least-violation solve met every "
                  "constraint, and its point (not optimal) is returned")
    runtime = dict(sol.runtime_s, total=sol.runtime_s.get("total", 0.0)
                   + time.perf_counter() - t0)
    return replace(point, reason=reason, iterations=sol.iterations, runtime_s=runtime,
                   history=sol.history, fuel_optimal=sol.fuel_optimal,
                   min_path_margin=best.min_path_margin,
                   infeasible=verdict is Verdict.INFEASIBLE)


def judge(problem: Problem, best: Solution, opts: SolverOptions) -> tuple[Verdict, float]:
    """(the verdict, the least-violation point's terminal miss max |psi|)."""
    X = best.X
    if not (np.all(np.isfinite(X)) and best.max_violation <= opts.aul.tol):
        return Verdict.UNDECIDED, float("nan")
    psi = np.asarray(problem.g_teq(X[-1], problem.x_target), float)
    miss = float(np.max(np.abs(psi), initial=0.0))
    if miss > INFEASIBLE_MARGIN * opts.aul.tol:
        return Verdict.INFEASIBLE, miss
    if miss <= opts.aul.tol:
        return Verdict.FEASIBLE, miss
    return Verdict.UNDECIDED, miss
