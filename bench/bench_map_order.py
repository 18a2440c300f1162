"""The stage maps' order (``DDPOptions.map_order``, issue 47) side by side: each catalogue case
solved cold at each order, one process per solve, interleaved; CPU seconds, DDP iterations,
the share of stages the Dyn forward pass served by their polynomial, the answer, and each
CPU ratio to the first order's.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python bench/bench_map_order.py
        [--cases double_integrator earth_mars halo_l2_l1] [--orders 2 3 4] [--fuel] [--cap 600]
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys

SOLVE = """
import json, sys, time
from daddy_core.catalogue import load_case, problem_from_case
from daddy_core.solver import case_options, solve
case = load_case(sys.argv[1]); fuel = sys.argv[2] == "fuel"
t = time.process_time()
problem = problem_from_case(case)
sol = solve(problem, case.cold_guess(problem.N), fuel_optimal=fuel,
            options=case_options(case, fuel, run=dict(time_budget_s=float(sys.argv[4])),
                                 ddp=dict(map_order=int(sys.argv[3]))))
print(json.dumps({"cpu_s": round(time.process_time() - t, 2), "converged": sol.converged,
                  "ddp": sol.iterations["ddp"], "share": sol.polynomial_share,
                  "value": sol.final_mass_kg if sol.final_mass_kg is not None else sol.cost}))
"""


def run(case: str, fuel: bool, order: int, cap: float) -> dict:
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    try:
        out = subprocess.run([sys.executable, "-c", SOLVE, case, "fuel" if fuel else "energy",
                              str(order), str(cap)],
                             env=env, capture_output=True, text=True, timeout=cap * 1.5 + 60)
        return json.loads(out.stdout.strip().splitlines()[-1])
    except (subprocess.TimeoutExpired, IndexError, json.JSONDecodeError):
        return {"cpu_s": cap, "converged": False, "ddp": None, "share": None, "value": None}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", nargs="*", default=["double_integrator", "earth_mars",
                                                   "halo_l2_l1", "dro_dro", "lyapunov_l1_l2"])
    ap.add_argument("--orders", nargs="+", type=int, default=[2, 3, 4])
    ap.add_argument("--fuel", action="store_true", help="fuel-optimal (default: energy)")
    ap.add_argument("--cap", type=float, default=600.0)
    args = ap.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, one solve at a time")
    for case in args.cases:
        fuel = args.fuel and case != "double_integrator"
        runs = [run(case, fuel, k, args.cap) for k in args.orders]
        base = runs[0]["cpu_s"]
        cells = [f"order {k}: {r['cpu_s']} s ({r['cpu_s'] / base if base else float('nan'):.2f})"
                 f", DDP {r['ddp']}, polynomial {r['share'] or 0:.0%}, {r['value']}, "
                 f"converged {r['converged']}" for k, r in zip(args.orders, runs)]
        print(f"{case:18s} {'fuel' if fuel else 'energy':6s} " + " | ".join(cells), flush=True)


if __name__ == "__main__":
    main()
