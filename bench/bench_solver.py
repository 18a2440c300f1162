"""Solver benchmark: wall and CPU time per acceptance case, iterations, the time split of the DDP
(forward pass / expansion / backward sweep / Newton / KKT polishing), the final KKT residual and
the share of stages served by polynomial evaluation, next to the C++ reference's CPU time
measured on this machine type (issue #3).

    .venv/bin/python bench/bench_solver.py [--all] [--method dyn] [--repeat 3]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from daddy_core.catalogue import load_case, problem_from_case
from daddy_core.solver import case_options, solve

# (case, fuel-optimal, C++ reference CPU seconds, CasADi+IPOPT seconds) from issue #3
# (None: not measured here)
CASES = [("earth_mars", False, 1.5, 0.43), ("earth_mars", True, 3.8, 1.1),
         ("halo_l2_l1", True, 16.0, 11.1), ("dro_dro", True, 5.7, 2.3),
         ("lyapunov_l1_l2", True, None, None), ("dro_dro_2rev", True, None, None)]


def run(name, fuel, method):
    case = load_case(name)
    prob = problem_from_case(case)
    u0 = case.cold_guess(prob.N)
    w0, c0 = time.perf_counter(), time.process_time()
    sol = solve(prob, u0, method=method, fuel_optimal=fuel, options=case_options(case, fuel))
    return sol, time.perf_counter() - w0, time.process_time() - c0


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--all", action="store_true", help="include the CR3BP cases (minutes)")
    ap.add_argument("--case", action="append", help="only this case (repeatable)")
    ap.add_argument("--method", default="dyn")
    ap.add_argument("--repeat", type=int, default=1,
                    help="solves per case; the row shows the median-CPU one and the spread (this "
                         "shared VM's timings drift by +-15 %% over an hour)")
    args = ap.parse_args()
    if args.repeat < 1:
        ap.error("--repeat must be >= 1")
    from bench_da import machine
    print(f"machine: {machine()}")
    hdr = (f"{'case':22s} {'conv':>4s} {'m_f kg':>9s} {'viol':>8s} {'wall s':>7s} {'cpu s':>7s} "
           f"{'C++ s':>6s} {'ratio':>6s} {'DDP it':>6s} {'ms/it fwd/exp/bwd':>20s} {'newton s':>8s} "
           f"{'kkt s':>6s} {'KKT res':>8s} {'poly':>5s}")
    print(hdr)
    for name, fuel, cpp, _ in CASES:
        if (args.case and name not in args.case) or (
                not args.case and name != "earth_mars" and not args.all):
            continue
        runs = sorted((run(name, fuel, args.method) for _ in range(args.repeat)),
                      key=lambda r: r[2])
        sol, wall, cpu = runs[len(runs) // 2]
        it = max(sol.iterations["ddp"], 1)
        rt = sol.runtime_s
        split = "/".join(f"{1e3 * rt[k] / it:.0f}" for k in ("forward", "expansion", "backward"))
        label = f"{name} {'fuel' if fuel else 'energy'}"
        print(f"{label:22s} {str(sol.converged)[0]:>4s} {sol.final_mass_kg:9.3f} "
              f"{sol.max_violation:8.1e} {wall:7.2f} {cpu:7.2f} "
              + (f"{cpp:6.1f} {cpu / cpp:6.2f} " if cpp else f"{'-':>6s} {'-':>6s} ") +
              f"{it:6d} {split:>20s} {rt['newton']:8.2f} {rt['kkt']:6.2f} "
              f"{sol.kkt_residual:8.1e} {sol.polynomial_share:5.0%}"
              + (f"  (cpu {runs[0][2]:.2f}-{runs[-1][2]:.2f} s over {len(runs)})"
                 if len(runs) > 1 else ""), flush=True)
    print("ratio = our CPU time / the C++ reference's CPU time (target <= 1, stretch <= 0.5)")


if __name__ == "__main__":
    main()
