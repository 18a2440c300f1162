"""The free arrival of an Earth-centred transfer: a search over its total angle.

An Earth-centred case arrives anywhere on the target orbit at t = ToF, so the number of
revolutions the transfer makes is free; a solve fixes it (its stages are equal arcs of true
longitude over ``Case.revolutions``), and this outer 1-D search varies it: a golden-section
search for the heaviest final mass over [r0 - span/2, r0 + span/2] around the case's own
revolutions r0, each solve warm-started from the nearest one solved before (its controls
re-sampled by the fraction of the transfer, stage by stage), down to a bracket of ``tol``
revolutions. Why outside the solve: with the angle a variable inside it, the NLP solvers of the
independent transcription crawled and stayed at the revolution count of their guess (issue 20),
and a solve at a fixed angle is what the rest of the solver does well. A solve that ends
infeasible counts as no mass at all (a feasible one whose KKT residual stayed above
tol_optimality counts with its mass, flagged not converged); the search assumes one maximum in
the bracket (golden section), which neighbouring revolution counts of a smooth transfer give.
The span matters: the arrival time fixes the mean motion the transfer must average, so a
1-day LEO raise of 15.5 revolutions turned infeasible 0.12 revolutions away, while the
oracle's MEO transfers differ by ~1 kg between 71.1 and 74.9 revolutions.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..solver import Solution, case_options, solve
from .cases import Case
from .paper_problems import problem_from_case

_GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0
FEASIBLE = 10.0   # a solve within this many tol_newton of every constraint counts as feasible


@dataclass(frozen=True)
class RevolutionTrial:
    """One solve of the search: its revolutions, stage count, final mass [kg] (None when it
    ended infeasible), whether it converged, and its CPU time [s]."""

    revolutions: float
    stages: int
    final_mass_kg: float | None
    converged: bool
    cpu_s: float


@dataclass
class RevolutionSearch:
    """The heaviest feasible solve (None if none was), its revolutions, every trial in the
    order solved."""

    best: Solution | None
    revolutions: float | None
    trials: list = field(default_factory=list)


def resample(U: np.ndarray, stages: int) -> np.ndarray:
    """(stages, nu) controls flying U (N, nu) stage by stage at the same fraction of the
    transfer (the stage whose span holds each new stage's midpoint)."""
    idx = np.minimum(((np.arange(stages) + 0.5) * len(U) / stages).astype(int), len(U) - 1)
    return np.asarray(U)[idx].copy()


def search_revolutions(case: Case, fuel_optimal: bool = False, span: float = 2.0,
                       tol: float = 0.1, method: str = "dyn",
                       progress: Callable[[str], None] | None = None) -> RevolutionSearch:
    """The module docstring's search around ``case.revolutions`` (span and tol in
    revolutions; the case's own solve comes first, from its cold guess)."""
    solved: dict[float, Solution | None] = {}   # None: infeasible
    trials: list[RevolutionTrial] = []

    def mass(revs: float) -> float:
        if revs in solved:
            sol = solved[revs]
            return sol.final_mass_kg if sol is not None else -math.inf
        variant = case.with_revolutions(revs)
        problem = problem_from_case(variant)
        feasible = [r for r, s in solved.items() if s is not None]
        if feasible:
            u0 = resample(solved[min(feasible, key=lambda r: abs(r - revs))].U, problem.N)
        else:
            u0 = case.cold_guess(problem.N)
        opts = case_options(case, fuel_optimal)
        t = time.process_time()
        sol = solve(problem, u0, method=method, fuel_optimal=fuel_optimal, options=opts,
                    case_name=case.name)
        ok = sol.max_violation <= FEASIBLE * opts.newton.tol
        solved[revs] = sol if ok else None
        trials.append(RevolutionTrial(revs, problem.N, sol.final_mass_kg if ok else None,
                                      sol.converged, time.process_time() - t))
        if progress is not None:
            state = ("" if sol.converged else f" (not converged: {sol.reason})") if ok \
                else f"infeasible ({sol.reason})"
            progress(f"  {revs:.4f} revolutions ({problem.N} stages): "
                     + (f"{sol.final_mass_kg:.3f} kg" if ok else "") + state
                     + f", {trials[-1].cpu_s:.1f} s")
        return sol.final_mass_kg if ok else -math.inf

    r0 = case.revolutions
    mass(r0)
    a, b = r0 - 0.5 * span, r0 + 0.5 * span
    c, d = b - _GOLDEN * (b - a), a + _GOLDEN * (b - a)
    fc, fd = mass(c), mass(d)
    while b - a > tol:
        if fc >= fd:                    # the maximum lies in [a, d]
            b, d, fd = d, c, fc
            c = b - _GOLDEN * (b - a)
            fc = mass(c)
        else:                           # in [c, b]
            a, c, fc = c, d, fd
            d = a + _GOLDEN * (b - a)
            fd = mass(d)
    good = {r: s for r, s in solved.items() if s is not None}
    if not good:
        return RevolutionSearch(None, None, trials)
    best = max(good, key=lambda r: good[r].final_mass_kg)
    return RevolutionSearch(good[best], best, trials)
