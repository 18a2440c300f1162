"""The AUL's second-order multiplier update against eq. 9's first-order one (issue 46): each
catalogue case solved cold with both, one process per solve, interleaved; AUL and DDP
iterations, CPU seconds and the final mass (or cost) side by side.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python bench/bench_multiplier_update.py
        [--cases earth_mars halo_l2_l1] [--kinds energy fuel] [--cap 600]
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
                                 aul=dict(multiplier_update=sys.argv[3])))
print(json.dumps({"cpu_s": round(time.process_time() - t, 2), "converged": sol.converged,
                  "aul": sol.iterations["aul"], "ddp": sol.iterations["ddp"],
                  "mass_kg": sol.final_mass_kg, "cost": sol.cost}))
"""


def run(case: str, kind: str, update: str, cap: float) -> dict:
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    try:
        out = subprocess.run([sys.executable, "-c", SOLVE, case, kind, update, str(cap)],
                             env=env, capture_output=True, text=True, timeout=cap * 1.5 + 60)
        return json.loads(out.stdout.strip().splitlines()[-1])
    except (subprocess.TimeoutExpired, IndexError, json.JSONDecodeError):
        return {"cpu_s": cap, "converged": False, "aul": None, "ddp": None, "mass_kg": None,
                "cost": None}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", nargs="*", default=["double_integrator", "earth_mars",
                                                   "halo_l2_l1", "dro_dro", "lyapunov_l1_l2"])
    ap.add_argument("--kinds", nargs="*", default=["energy", "fuel"])
    ap.add_argument("--cap", type=float, default=600.0)
    args = ap.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, one solve at a time")
    for case in args.cases:
        for kind in args.kinds:
            if kind == "fuel" and case == "double_integrator":
                continue
            first = run(case, kind, "first_order", args.cap)
            second = run(case, kind, "second_order", args.cap)
            value = "mass_kg" if first.get("mass_kg") is not None else "cost"
            ratio = second["cpu_s"] / first["cpu_s"] if first["cpu_s"] else float("nan")
            print(f"{case:18s} {kind:6s} first: AUL {first['aul']}, DDP {first['ddp']}, "
                  f"{first['cpu_s']} s, {value} {first[value]}, converged {first['converged']} | "
                  f"second: AUL {second['aul']}, DDP {second['ddp']}, {second['cpu_s']} s, "
                  f"{value} {second[value]}, converged {second['converged']} | CPU ratio "
                  f"{ratio:.2f}", flush=True)


if __name__ == "__main__":
    main()
