"""The exchange step of path constraints (``path_constraints``): after a solve, check g_path
along the re-propagated trajectory, tighten the samples of every stage where it rises above
zero between them, and solve the last homotopy step again from there, until it holds
everywhere."""
from __future__ import annotations

import time
from dataclasses import replace

from ..path_constraints import dense_margin, tightened
from ..problem import Problem
from .homotopy import homotopy_steps
from .options import SolverOptions
from .solution import Solution, WarmStart


def _merged(first: Solution, later: list[Solution]) -> Solution:
    """The last of ``later`` with the work of every solve counted: iterations and run times
    summed, histories concatenated (each exchange round's entries marked ``path_round``)."""
    last = later[-1]
    iterations, runtime = dict(first.iterations), dict(first.runtime_s)
    history = list(first.history)
    for r, sol in enumerate(later, start=1):
        for k, v in sol.iterations.items():
            iterations[k] = iterations.get(k, 0) + v
        for k, v in sol.runtime_s.items():
            runtime[k] = runtime.get(k, 0.0) + v
        history += [dict(h, path_round=r) for h in sol.history]
    return replace(last, iterations=iterations, runtime_s=runtime, history=history)


def _last_step(problem: Problem, sol: Solution, opts: SolverOptions) -> tuple:
    """The homotopy step an exchange round solves again: the last pseudo-Huber step of a
    fuel-optimal solve (the options' last, when its exact end game ran from the energy step
    before any), else the step solved last."""
    if sol.fuel_optimal:
        return sol.fuel_step or homotopy_steps(problem, sol.U, opts, True)[-1]
    return (sol.history[-1]["h"], sol.history[-1]["delta"]) if sol.history else opts.homotopy[0]


def hold(problem: Problem, sol: Solution, resolve, opts: SolverOptions, progress) -> Solution:
    """``sol`` of ``problem`` with g_path held between the nodes: up to
    ``opts.end_game.path_exchange_rounds`` rounds of (dense check, tighten the offending
    stages' samples, ``resolve(problem, warm start, options)`` the last homotopy step from
    ``sol``). Returns the
    last solve's Solution with ``min_path_margin`` (the dense check's) and every round's work
    counted; ``converged`` is False, and the reason names the stage, when the constraint is
    still violated between the nodes by more than tol_newton."""
    start, first, later = time.perf_counter(), sol, []
    pm = dense_margin(problem, sol.X, sol.U)
    while len(later) < opts.end_game.path_exchange_rounds and sol.max_violation <= opts.aul.tol:
        offset = tightened(problem.path_offset, pm, opts.newton.tol)
        if offset is None:
            break
        options = opts.with_(homotopy=(_last_step(problem, sol, opts),))
        if opts.run.time_budget_s is not None:   # the first solve's time and every round's since
            left = opts.run.time_budget_s - first.runtime_s.get("total", 0.0) \
                - (time.perf_counter() - start)
            if left <= 0:
                break
            options = options.with_(run=dict(time_budget_s=left))
        if progress is not None:
            progress(f"path exchange {len(later) + 1}: g_path rises {-pm.margin:.2e} above its "
                     f"bound between the samples (stage {pm.stage}, tau {pm.tau:.3f}): the "
                     "offending stages' samples tightened, the last homotopy step solved again")
        problem = replace(problem, path_offset=offset)
        sol = resolve(problem, WarmStart(U=sol.U, duals=sol.duals), options)
        later.append(sol)
        pm = dense_margin(problem, sol.X, sol.U)
    out = replace(_merged(first, later) if later else sol, min_path_margin=pm.margin)
    if out.converged and not pm.margin >= -opts.newton.tol:
        out = replace(out, converged=False,
                      reason=f"g_path holds at its samples but not between them: "
                             f"{-pm.margin:.2e} above its bound at stage {pm.stage} "
                             f"(tau {pm.tau:.3f}) after {len(later)} exchange rounds")
    return out
