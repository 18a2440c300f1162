"""The fuel-optimal continuation of paper eq. 12-14: one augmented-Lagrangian solve per
(h, delta) step of the pseudo-Huber stage cost, each warm-started from the previous one.

h = 0 is the energy-optimal problem; raising h and shrinking delta moves the stage cost towards
|u| (fuel). Controls and duals carry over between steps, the penalties restart from mu_init.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import DaddyError
from ..fuel import FUEL_HOMOTOPY
from ..problem import Problem
from .aul import aul, update_multipliers
from .ddp import DDPStats
from .deadline import Deadline
from .sweeps import Gains, Stages
from .lagrangian import Multipliers
from .options import Method, SolverOptions
from .progress import ProgressLine
from .results import Status


@dataclass
class HomotopyResult:
    """The last finite iterate (X, U) and how the continuation ended.

    Attributes:
        X: (N+1, nx), U: (N, nu): the last iterate whose states and controls are all finite.
        stages: the last AUL solve's expanded nominal (its maps serve warm starts); None when
            no continuation ran (``exact_start``).
        mult: the multipliers at the end; gains: the last backward sweep's (or None).
        rho: Quu regularisation at the end of the last DDP solve.
        aul_iterations: summed over the steps; history: one summary dict per step.
        converged: the last step run met tol_aul or stalled (``Status.AUL_STALLED``: the
            polishing decides) -- an earlier step's failure is superseded when the steps
            after it converged from its end; reason: the last step that did neither, and why.
        stalled: the first step whose AUL stalled, and at what (empty if none).
        diverged: a step's first DDP solve diverged (``Status.AUL_DIVERGED``): X, U are that
            step's start, where DDP could not converge (no polishing follows: the solve
            reports the divergence).
    """

    X: np.ndarray
    U: np.ndarray
    stages: Stages | None
    mult: Multipliers
    gains: Gains | None
    rho: float
    aul_iterations: int = 0
    history: list = field(default_factory=list)
    converged: bool = True
    reason: str = "converged"
    stalled: str = ""
    diverged: bool = False


def homotopy_steps(problem: Problem, U0: np.ndarray, opts: SolverOptions,
                   fuel_optimal: bool | None) -> tuple:
    """The (h, delta) steps to run.

    fuel_optimal None: all of ``opts.homotopy`` when it has more than one step, else its
    first; False: its first (energy-optimal) step only; True: all of it, or
    ``fuel.FUEL_HOMOTOPY`` when the options name only the energy step -- never silently the
    energy problem: a stage cost that ignores ``hom`` (same value at the guess with the first
    and the last step's (h, delta)) is a DaddyError saying what is missing.
    """
    hom = opts.homotopy
    if fuel_optimal is None:
        return hom if len(hom) > 1 else hom[:1]
    if not fuel_optimal:
        return hom[:1]
    steps = hom if (len(hom) > 1 or hom[0][0] > 0) else FUEL_HOMOTOPY
    x, u, dt, _ = problem.probe_point(U0)
    u = u + 1.0     # any non-zero thrust: the fuel term differs there
    first, last = (np.asarray(problem.stage_cost(x, u, dt, step), float)
                   for step in ((0.0, steps[0][1]), steps[-1]))
    if np.array_equal(first, last):
        raise DaddyError("fuel_optimal=True, but problem stage_cost ignores its hom = (h, delta) "
                         "argument (same value for h = 0 and h = "
                         f"{steps[-1][0]:g}): blend the fuel term by h, e.g. "
                         "daddy_core.fuel.pseudo_huber_stage_cost, or solve with "
                         "fuel_optimal=False")
    return steps


def continuation(problem: Problem, X, U, steps: tuple, method: Method, opts: SolverOptions,
                 stats: DDPStats, deadline: Deadline | None = None, progress=None,
                 rho: float | None = None, duals: dict | None = None, F=None,
                 numbering: tuple[int, int] | None = None) -> HomotopyResult:
    """Run the AUL (Alg. 4) on each homotopy step from (X, U) (F: their stage maps, if known;
    duals: warm-start multipliers; rho: the Quu regularisation each step starts from). Stops
    after a step that ran out of time. ``numbering``: (steps before these, all steps) for the
    progress lines, when these are part of a longer homotopy.

    Each step after the first starts from the previous step's solution with the penalty back
    at mu_init and the multipliers of eq. 9's update there (lam + mu g: the first-order
    estimate at that solution), not those its last DDP solve ran with: an AUL that met tol_aul
    as mu grew ends with multipliers that lag by mu g, and with mu reset the next step's first
    DDP solve traded the constraints away on them (`docs/design-notes.md`)."""
    mult = Multipliers.initial(problem, opts.aul.mu_init)
    mult.take_duals(duals)
    best, gains, history, aul_iterations = (X, U), None, [], 0
    converged, reason, stalled = True, "converged", ""
    res = None
    for i, hom in enumerate(steps):
        if progress:
            before, total = numbering or (0, len(steps))
            progress(ProgressLine(f"homotopy {before + i + 1}/{total}: h = {hom[0]}, "
                                  f"delta = {hom[1]}", homotopy_step=before + i + 1,
                                  homotopy_steps=total))
        mult.mu[...] = opts.aul.mu_init
        mult.mu_t[...] = opts.aul.mu_init
        st = (Stages(problem, X, U, mult, hom, opts.eps_da, F=F, order=opts.ddp.map_order)
              if res is None
              else res.stages.with_costs(mult, hom))
        res = aul(st, method, opts, stats, deadline, progress, rho0=rho)
        gains = res.gains or gains
        aul_iterations += res.iterations
        mult = res.mult
        X, U = res.stages.X, res.stages.U
        if i + 1 < len(steps):   # (mu is reset above: only the multipliers carry over)
            mult = _next_multipliers(problem, X, U, mult, opts)
        if np.all(np.isfinite(X)) and np.all(np.isfinite(U)):
            best = (X, U)
        history.append({"h": hom[0], "delta": hom[1], "aul_iterations": res.iterations,
                        "max_violation": res.max_violation, "cost": res.stages.cost,
                        "converged": res.converged, "reason": res.reason})
        if res.status in (Status.AUL_STALLED, Status.AUL_UNMOVED):
            # the penalty can do no more: the next step goes on from here, and Newton's
            # polishing finally meets the constraints or reports that they cannot be met
            stalled = stalled or (f"homotopy step {i + 1}: {res.reason} (max violation "
                                  f"{res.max_violation:.2e})")
        elif not res.converged:
            converged, reason = False, f"homotopy step {i + 1}: {res.reason}"
            if res.status in (Status.TIME_BUDGET, Status.CANCELLED, Status.AUL_DIVERGED):
                break
        else:   # (a step that converged from a failed one's end: the verdict is the last's)
            converged, reason = True, "converged"
    return HomotopyResult(best[0], best[1], res.stages, mult, gains, res.rho, aul_iterations,
                          history, converged, reason, stalled,
                          res.status is Status.AUL_DIVERGED)


def _next_multipliers(problem: Problem, X, U, mult: Multipliers,
                      opts: SolverOptions) -> Multipliers:
    """The multipliers the next homotopy step starts from: eq. 9's update at the solution
    (X, U) of a step (``continuation``: why), or ``mult`` where it is not finite."""
    g, _, gt, _ = problem.constraint_values(X, U)
    est = update_multipliers(mult, g, gt, opts)
    if np.all(np.isfinite(est.lam)) and np.all(np.isfinite(est.lam_t)):
        return est
    return mult


def resume_duals(problem: Problem, done: HomotopyResult, opts: SolverOptions) -> dict:
    """The multipliers a continuation of further steps starts from after ``done``: eq. 9's
    update at its solution (``_next_multipliers``), as if one continuation ran them all."""
    return _next_multipliers(problem, done.X, done.U, done.mult, opts).as_duals()


def joined(done: HomotopyResult, more: HomotopyResult) -> HomotopyResult:
    """One continuation's result from two that ran one after the other: the later one's end,
    the iterations and the history summed, and the later one's verdict -- a continuation is
    judged by its last step, as ``continuation`` judges its own (design notes: the last
    step's verdict): the first step's failure is superseded when the rest converged from its
    end, whose answer Newton and the KKT test then judge."""
    return replace(more, gains=more.gains or done.gains,
                   aul_iterations=done.aul_iterations + more.aul_iterations,
                   history=done.history + more.history,
                   stalled=done.stalled or more.stalled)
