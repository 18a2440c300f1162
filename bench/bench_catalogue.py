"""Run times of the catalogue: every case solved as `daddy solve CASE --energy` and `--fuel`
(method dyn, cold guess, defaults; a solar-sail case as `daddy solve CASE`, recorded as its
"energy" solve), one process per solve, CPU seconds, with a cap; written to
``daddy_core/catalogue/run_times.json`` with ``--write``, which ``daddy list`` shows as each
case's expected run time (with the machine and date of the measurement).

    OPENBLAS_NUM_THREADS=1 .venv/bin/python bench/bench_catalogue.py [--cap 600] [--jobs 2]
        [--cases leo_leo meo_meo] [--write]

Solves run ``--jobs`` at a time (each on one core); a solve that reaches the cap is recorded
as not converged within it.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from datetime import date
from pathlib import Path

from daddy_core.catalogue import list_cases, load_case
from daddy_core.catalogue.run_times import RUN_TIMES_FILE, read_run_times

SOLVE = """
import json, sys, time
from daddy_core.catalogue import load_case, problem_from_case
from daddy_core.catalogue.sail_cases import SailCase, sail_options, solve_sail
from daddy_core.solver import case_options, solve
case = load_case(sys.argv[1]); fuel = sys.argv[2] == "fuel"
t = time.process_time()
if isinstance(case, SailCase):   # `daddy solve` of a sail case: from the steering law
    sol = solve_sail(case, options=sail_options(run=dict(time_budget_s=float(sys.argv[3])))).solution
else:
    problem = problem_from_case(case)
    u0 = case.cold_guess(problem.N)
    sol = solve(problem, u0, fuel_optimal=fuel, options=case_options(case, fuel,
                run=dict(time_budget_s=float(sys.argv[3]))))
print(json.dumps({"cpu_s": round(time.process_time() - t, 1), "converged": sol.converged,
                  "final_mass_kg": None if sol.final_mass_kg is None else round(sol.final_mass_kg, 3),
                  "reason": sol.reason[:120]}))
"""


def run(case: str, kind: str, cap: float) -> dict:
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    try:
        out = subprocess.run([sys.executable, "-c", SOLVE, case, kind, str(cap)], env=env,
                             capture_output=True, text=True, timeout=cap * 1.5 + 60)
        return json.loads(out.stdout.strip().splitlines()[-1])
    except (subprocess.TimeoutExpired, IndexError, json.JSONDecodeError):
        return {"cpu_s": cap, "converged": False, "final_mass_kg": None,
                "reason": "no result within the cap"}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cap", type=float, default=600.0, help="wall-clock budget per solve [s]")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--cases", nargs="*", default=list_cases())
    ap.add_argument("--write", action="store_true", help=f"update {RUN_TIMES_FILE}")
    args = ap.parse_args()
    work = [(c, kind) for c in args.cases for kind in ("energy", "fuel")
            if not (kind == "fuel" and getattr(load_case(c), "spacecraft", None) is None)]
    t = time.perf_counter()
    with ThreadPoolExecutor(args.jobs) as pool:
        results = list(pool.map(lambda w: (w, run(*w, args.cap)), work))
    table = read_run_times()
    for (case, kind), r in results:
        print(f"{case:16s} {kind:6s} {r['cpu_s']:7.1f} s  converged {r['converged']!s:5s} "
              f"{r['final_mass_kg']}  {'' if r['converged'] else r['reason']}")
        table.setdefault("cases", {}).setdefault(case, {})[kind] = r
    machine = (f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
               f"{args.jobs} solves at a time")
    print(f"machine: {machine}; {time.perf_counter() - t:.0f} s in all")
    if args.write:
        # every run carries its date; the table's machine and date are those of a full run
        for (case, kind), r in results:
            table["cases"][case][kind]["date"] = date.today().isoformat()
        if set(args.cases) == set(list_cases()):
            table.update(machine=machine, date=date.today().isoformat(), cap_s=args.cap)
        RUN_TIMES_FILE.write_text(json.dumps(table, indent=1, sort_keys=True) + "\n")
        print(f"wrote {RUN_TIMES_FILE}")


if __name__ == "__main__":
    main()
