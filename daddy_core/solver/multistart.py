"""The global option: one problem solved from many starts in parallel, the best converged
optimum returned with every distinct optimum found.

DDP is a local method: each start falls into its own basin. The halo L2 -> L1 transfer has a
981.4255 kg optimum beside the 973.9447 kg one that every control guess finds (the paper's, zero
thrust, random): it is reached from states blended between the departure and arrival orbits,
which the Newton restoration turns into a trajectory (``WarmStart.X``). The starts:

- structured (``structured_starts``): the cold guess (the case's, else the paper's 1e-6 on
  every control), zero control (the ballistic flight), and the blended states
  (``blend.blended_states``: the departure and arrival orbits joined by a smooth step);
- random (``random_starts``): controls of random directions and magnitudes up to the bound
  (``Problem.u_max``, else 1), from a seeded generator.

Parallel in processes (``jobs``; forked, so a problem of lambdas needs no pickling) or on an
executor of the caller's (``executor``: e.g. a Dask client's ``client.get_executor()``, which
ships the problem by cloudpickle). Optima are distinct when their values differ by more than
``distinct_tol`` max(1, |value|) (relative for masses in kg, absolute for costs near 0, whose
terms may cancel); the value is the final mass (larger is better) for a problem with a
spacecraft and a mass state, else the cost.
"""
from __future__ import annotations

import math
import multiprocessing
import time
from concurrent.futures import Executor, ProcessPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from ..errors import DaddyError
from ..problem import Problem
from .blend import PAPER_GUESS, blended_states
from .options import SolverOptions
from .solution import Solution, WarmStart
from .solve import solve


@dataclass(frozen=True)
class Start:
    """One start of a multi-start solve: its name ("paper", "ballistic", "blend",
    "random 3") and what ``solve`` takes as its guess (controls or a ``WarmStart``)."""

    name: str
    guess: object


@dataclass(frozen=True)
class Run:
    """What one start gave: converged, its value (final mass [kg] or cost), the solution
    (None when the solve raised), CPU [s] and the reason of a failed run."""

    start: str
    converged: bool
    value: float
    cpu_s: float
    reason: str
    solution: Solution | None = None


@dataclass(frozen=True)
class Optimum:
    """A distinct converged optimum: its value, its best solution, and the starts that found
    it."""

    value: float
    solution: Solution
    starts: tuple


@dataclass
class MultiStartResult:
    """``best``: the best converged solution (None when no start converged); ``optima``:
    the distinct converged optima, best first; ``runs``: every start's outcome, in order;
    ``wall_s``: the wall time of the whole search."""

    best: Solution | None
    optima: list = field(default_factory=list)
    runs: list = field(default_factory=list)
    wall_s: float = 0.0

    def summary(self) -> str:
        """A few lines: the optima found and by which starts, the failures counted."""
        lines = [f"{len(self.runs)} starts, {sum(r.converged for r in self.runs)} converged, "
                 f"{len(self.optima)} distinct optima, {self.wall_s:.1f} s wall, "
                 f"{sum(r.cpu_s for r in self.runs):.1f} s CPU"]
        lines += [f"  {o.value:.6f}  from {', '.join(o.starts)}" for o in self.optima]
        return "\n".join(lines)


def structured_starts(problem: Problem, guess: np.ndarray | None = None) -> list:
    """The cold guess (``guess``, else the paper's: 1e-6 on every control), zero control and
    the blended states with the cold guess's controls (module docstring); the blend is left
    out when the arrival orbit does not propagate backwards to finite states."""
    N, nu = problem.N, problem.nu
    cold = np.full((N, nu), PAPER_GUESS) if guess is None else np.asarray(guess, float)
    starts = [Start("cold guess", cold), Start("ballistic", np.zeros((N, nu)))]
    X = blended_states(problem)
    if X is not None:
        starts.append(Start("blend", WarmStart(U=cold, X=X)))
    return starts


def random_starts(problem: Problem, n: int, seed: int = 0) -> list:
    """``n`` random control guesses: unit directions scaled by uniform magnitudes up to the
    bound (``Problem.u_max``, else 1), seeded."""
    rng = np.random.default_rng(seed)
    bound = problem.u_max if problem.u_max else 1.0
    out = []
    for i in range(n):
        d = rng.normal(size=(problem.N, problem.nu))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        out.append(Start(f"random {i}", d * rng.uniform(0.0, 1.0, (problem.N, 1)) * bound))
    return out


def value_of(sol: Solution) -> float:
    """What ranks a solution: its final mass [kg] when it has one, else its cost."""
    return float(sol.final_mass_kg if sol.final_mass_kg is not None else sol.cost)


# the problem a forked worker solves: set before the pool forks (no pickling of the problem)
_WORKER: dict = {}


def _solve_start(start: Start, problem: Problem | None = None, kwargs: dict | None = None) -> Run:
    """Solve one start (in a worker: the forked problem and arguments, unless given)."""
    problem = problem if problem is not None else _WORKER["problem"]
    kwargs = kwargs if kwargs is not None else _WORKER["kwargs"]
    t0 = time.process_time()
    try:
        sol = solve(problem, start.guess, **kwargs)
    except DaddyError as exc:   # a start the problem refuses (its guess out of the domain)
        return Run(start.name, False, math.nan, time.process_time() - t0, str(exc))
    value = value_of(sol)
    return Run(start.name, bool(sol.converged), value, time.process_time() - t0,
               "" if sol.converged else sol.reason, sol)


def multistart(problem: Problem, starts: list | None = None, *, random: int = 8, seed: int = 0,
               method: str = "dyn", fuel_optimal: bool | None = None, polish: bool = True,
               options: SolverOptions | None = None, case_name: str | None = None,
               jobs: int = 1, executor: Executor | None = None,
               distinct_tol: float = 1e-6) -> MultiStartResult:
    """Solve ``problem`` from every start and return the best converged optimum.

    Args:
        problem: the ``Problem``.
        starts: ``Start`` list; None: ``structured_starts`` then ``random`` random ones
            (``random_starts`` with ``seed``).
        random: random starts after the structured ones (with ``starts`` None).
        seed: the random starts' seed.
        method: as ``solve`` (every start alike).
        fuel_optimal: as ``solve``.
        polish: as ``solve``.
        options: as ``solve``; a time budget in them bounds each start.
        case_name: as ``solve``.
        jobs: worker processes (forked) when no ``executor``; 1: in this process.
        executor: a ``concurrent.futures.Executor`` to run the starts on instead (a Dask
            client's ``get_executor()``); the problem and solutions must pickle there.
        distinct_tol: two converged values closer than this times max(1, |value|) are one
            optimum.
    Returns:
        a ``MultiStartResult``.
    """
    if starts is None:
        starts = structured_starts(problem) + random_starts(problem, random, seed)
    if not starts:
        raise DaddyError("multistart needs at least one start")
    if not (isinstance(jobs, int) and jobs >= 1):
        raise DaddyError(f"multistart jobs must be an integer >= 1, got {jobs!r}")
    kwargs = dict(method=method, fuel_optimal=fuel_optimal, polish=polish, options=options,
                  case_name=case_name)
    t0 = time.perf_counter()
    if executor is not None:
        runs = [f.result() for f in [executor.submit(_solve_start, s, problem, kwargs)
                                     for s in starts]]
    elif jobs == 1 or len(starts) == 1:
        runs = [_solve_start(s, problem, kwargs) for s in starts]
    else:
        _WORKER.update(problem=problem, kwargs=kwargs)
        try:
            with ProcessPoolExecutor(min(jobs, len(starts)),
                                     mp_context=multiprocessing.get_context("fork")) as pool:
                runs = list(pool.map(_solve_start, starts))
        finally:
            _WORKER.clear()
    return _ranked(list(runs), problem, distinct_tol, time.perf_counter() - t0)


def _ranked(runs: list, problem: Problem, tol: float, wall_s: float) -> MultiStartResult:
    """The converged runs grouped into distinct optima, best first."""
    by_mass = problem.spacecraft is not None and problem.mass_index is not None
    groups: list = []   # [value, best run, [start names]]
    done = sorted((r for r in runs if r.converged and math.isfinite(r.value)),
                  key=lambda r: -r.value if by_mass else r.value)
    for r in done:
        for g in groups:
            if abs(r.value - g[0]) <= tol * max(abs(g[0]), 1.0):
                g[2].append(r.start)
                break
        else:
            groups.append([r.value, r, [r.start]])
    optima = [Optimum(v, best.solution, tuple(names)) for v, best, names in groups]
    return MultiStartResult(optima[0].solution if optima else None, optima, runs, wall_s)
