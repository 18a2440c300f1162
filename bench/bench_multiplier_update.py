"""The AUL's multiplier updates side by side (issues 46, 47): eq. 9's first-order one against
the second-order one, or the terminal multipliers swept with the controls (``--updates
first_order sweep``); each catalogue case solved cold with each, one process per solve,
interleaved; AUL and DDP iterations, CPU seconds and the final mass (or cost), and each CPU
ratio to the first update's.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python bench/bench_multiplier_update.py
        [--cases earth_mars halo_l2_l1] [--kinds energy fuel] [--cap 600]
        [--updates first_order second_order]
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys

from daddy_core.solver import MultiplierUpdate

SOLVE = """
import json, sys, time
from daddy_core.catalogue import load_case, problem_from_case
from daddy_core.solver import case_options, solve
case = load_case(sys.argv[1]); fuel = sys.argv[2] == "fuel"
t = time.process_time()
problem = problem_from_case(case)
sol = solve(problem, case.cold_guess(problem.N), fuel_optimal=fuel,
            options=case_options(case, fuel, run=dict(time_budget_s=float(sys.argv[4])),
                                 **json.loads(sys.argv[3])))
print(json.dumps({"cpu_s": round(time.process_time() - t, 2), "converged": sol.converged,
                  "aul": sol.iterations["aul"], "ddp": sol.iterations["ddp"],
                  "share": sol.polynomial_share, "mass_kg": sol.final_mass_kg,
                  "cost": sol.cost}))
"""


def run(case: str, kind: str, changes: dict, cap: float) -> dict:
    """One cold solve of ``case`` (``kind``: energy or fuel) in its own process, with the option
    ``changes`` (``SolverOptions.with_``'s groups as dicts) and a time budget ``cap``."""
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    try:
        out = subprocess.run([sys.executable, "-c", SOLVE, case, kind, json.dumps(changes),
                              str(cap)],
                             env=env, capture_output=True, text=True, timeout=cap * 1.5 + 60)
        return json.loads(out.stdout.strip().splitlines()[-1])
    except (subprocess.TimeoutExpired, IndexError, json.JSONDecodeError):
        return {"cpu_s": cap, "converged": False, "aul": None, "ddp": None, "share": None,
                "mass_kg": None, "cost": None}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", nargs="*", default=["double_integrator", "earth_mars",
                                                   "halo_l2_l1", "dro_dro", "lyapunov_l1_l2"])
    ap.add_argument("--kinds", nargs="*", default=["energy", "fuel"])
    ap.add_argument("--cap", type=float, default=600.0)
    ap.add_argument("--updates", nargs="+", default=["first_order", "second_order"],
                    choices=[m.value for m in MultiplierUpdate])
    args = ap.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, one solve at a time")
    for case in args.cases:
        for kind in args.kinds:
            if kind == "fuel" and case == "double_integrator":
                continue
            runs = [run(case, kind, {"aul": {"multiplier_update": update}}, args.cap)
                    for update in args.updates]
            first = runs[0]
            value = "mass_kg" if first.get("mass_kg") is not None else "cost"
            cells = []
            for update, r in zip(args.updates, runs):
                ratio = r["cpu_s"] / first["cpu_s"] if first["cpu_s"] else float("nan")
                cells.append(f"{update}: AUL {r['aul']}, DDP {r['ddp']}, {r['cpu_s']} s "
                             f"({ratio:.2f}), {value} {r[value]}, converged {r['converged']}")
            print(f"{case:18s} {kind:6s} " + " | ".join(cells), flush=True)


if __name__ == "__main__":
    main()
