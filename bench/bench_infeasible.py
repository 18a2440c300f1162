"""Infeasible problems called infeasible, and how quickly (issue 50, item 3): the double
integrator of ``daddy_core.catalogue.infeasible`` (20 stages, 6 states, 3 controls) feasible,
and made infeasible the three ways the issue names, each solved from zero controls with
default options, interleaved over ``--rounds`` rounds (the median CPU of each).

    .venv/bin/python bench/bench_infeasible.py [--rounds 5]

Prints each kind's median CPU, its ratio to the feasible solve's (the issue's target: <= 2)
and to a feasible solve whose thrust bound is active (|u| <= 1.05; the energy optimum's peak
is 1.5), the verdict and the reason's start, and whether the answer keeps the thrust bound.
"""
from __future__ import annotations

import argparse
import os
import platform
import statistics
import time

import numpy as np

from daddy_core.catalogue.infeasible import INFEASIBLE, double_integrator
from daddy_core.da import functions as dm
from daddy_core.solver import solve


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=5)
    args = ap.parse_args()
    active = dict(g_ineq=lambda x, u, dt: dm.stack([dm.dot(u, u) - 1.05 ** 2]), u_max=1.05)
    kinds = {"feasible": {}, "feasible, thrust bound active": active,
             **{k: changes for k, (changes, _) in INFEASIBLE.items()}}
    problems = {k: double_integrator(**changes) for k, changes in kinds.items()}
    solve(problems["feasible"], np.zeros((20, 3)))        # (the DA tables built once, untimed)
    cpu = {k: [] for k in kinds}
    last = {}
    for _ in range(args.rounds):
        for k, prob in problems.items():
            t0 = time.process_time()
            last[k] = solve(prob, np.zeros((20, 3)))
            cpu[k].append(time.process_time() - t0)
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"Python {platform.python_version()}; {args.rounds} interleaved rounds, median CPU")
    base = statistics.median(cpu["feasible"])
    base_active = statistics.median(cpu["feasible, thrust bound active"])
    print(f"{'':34s} {'CPU':>9s}  {'x feasible':>10s} {'x active':>8s}")
    for k, prob in problems.items():
        sol, t = last[k], statistics.median(cpu[k])
        bounded = np.max(np.linalg.norm(sol.U, axis=1)) <= prob.u_max * (1 + 1e-9)
        print(f"{k:34s} {t:7.3f} s  x{t / base:9.2f} x{t / base_active:7.2f}  "
              f"infeasible={sol.infeasible!s:5s} within the bound={bounded!s:5s} "
              f"{sol.reason[:70]}")


if __name__ == "__main__":
    main()
