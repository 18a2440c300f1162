"""The global option on catalogue cases: every start's outcome, the distinct optima, the best
against the default solve's, and the CPU.

    python bench/bench_multistart.py [--cases halo_l2_l1 leo_leo] [--random 4] [--jobs 2]

The default solve is the case's cold guess alone (what ``daddy solve CASE`` does); the
multi-start adds zero control, the blended states and ``--random`` random guesses
(``daddy_core/solver/multistart.py``). Fuel-optimal; masses in kg.
"""
from __future__ import annotations

import argparse
import os
import platform
import time

from daddy_core.catalogue import load_case, problem_from_case
from daddy_core.solver import case_options
from daddy_core.solver.multistart import multistart, random_starts, structured_starts


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", nargs="+", default=["halo_l2_l1", "leo_leo"])
    ap.add_argument("--random", type=int, default=4, help="random starts beyond the structured")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--cap", type=float, default=900.0, help="time budget of each start [s]")
    args = ap.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores; "
          f"{args.jobs} workers")
    for name in args.cases:
        case = load_case(name)
        problem = problem_from_case(case)
        starts = (structured_starts(problem, case.cold_guess(problem.N))
                  + random_starts(problem, args.random, args.seed))
        t0 = time.perf_counter()
        res = multistart(problem, starts, fuel_optimal=True, jobs=args.jobs,
                         options=case_options(case, True, run=dict(time_budget_s=args.cap)))
        print(f"\n{name}: {time.perf_counter() - t0:.1f} s wall")
        for r in res.runs:
            print(f"  {r.start:12s} {'converged' if r.converged else 'failed   '} "
                  f"{r.value:12.4f} kg {r.cpu_s:8.1f} s CPU  {r.reason[:70]}")
        print(res.summary())
        default = res.runs[0]
        if res.best is not None and default.converged:
            print(f"  best {res.best.final_mass_kg:.4f} kg vs the cold guess's {default.value:.4f}"
                  f" kg (+{res.best.final_mass_kg - default.value:.4f}); CPU "
                  f"{sum(r.cpu_s for r in res.runs) / default.cpu_s:.1f}x the cold solve's")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
