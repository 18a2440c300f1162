"""Where a fuel-optimal solve spends its time: each phase of the solve (``Solution.runtime_s``:
rollout, restoration, DDP's forward passes, expansions and sweeps, Newton, optimality, KKT,
re-propagation) and, under cProfile, the calls beneath them that polishing is made of (stage
expansions, the KKT step's sparse factorisations, Newton's banded ones, the float flows, the
KKT residual), with their counts and the time per call.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python bench/profile_fuel.py [--cases earth_mars ...]

One process per case (a fresh interpreter, as a user's solve runs); CPU seconds of the process.
cProfile adds overhead to every Python call: compare the phases' shares, not the absolute
times, with ``bench_compare.py``'s.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys

CASES = ("earth_mars", "halo_l2_l1", "dro_dro", "dro_dro_2rev")

# run in a child process: prints one JSON object on its last line
_PROFILE = r"""
import cProfile, json, pstats, sys, time
import numpy as np
import scipy.linalg, scipy.sparse.linalg  # noqa: E401,F401  (imported before the clock starts)
from daddy_core.catalogue import load_case, problem_from_case
from daddy_core.solver import case_options, solve
name = sys.argv[1]
case = load_case(name); prob = problem_from_case(case)
u0 = case.cold_guess(prob.N)
prof = cProfile.Profile()
c0 = time.process_time()
prof.enable()
sol = solve(prob, u0, fuel_optimal=True, options=case_options(case, True))
prof.disable()
cpu = time.process_time() - c0
# (module suffix, function name) -> label: the calls polishing is made of
WATCH = {
    ("solver/stage_maps.py", "expand_dynamics"): "stage expansions (DA)",
    ("solver/stage_maps.py", "maps_at"): "maps re-centred (DA)",
    ("solver/kkt_polish.py", "_step"): "KKT step: sparse LU solves",
    ("solver/kkt_polish.py", "_hessians"): "KKT: Lagrangian Hessians",
    ("solver/kkt_polish.py", "_restore"): "KKT: step restorations",
    ("solver/kkt_polish.py", "_trial"): "KKT: trial evaluations",
    ("solver/newton.py", "polish"): "Newton runs (incl. restorations)",
    ("solver/newton.py", "__init__"): "constraint models / banded factors",
    ("solver/optimality.py", "optimality"): "KKT residual evaluations",
    ("daddy_core/problem.py", "stage_flow"): "float stage flows",
    ("daddy_core/integrators.py", "rk78"): "RK78 calls",
}
stats = pstats.Stats(prof).stats
calls = {}
for (path, _, func), (cc, nc, tt, ct, callers) in stats.items():
    for (suffix, fname), label in WATCH.items():
        if func == fname and path.replace("\\", "/").endswith(suffix):
            n, t = calls.get(label, (0, 0.0))
            calls[label] = (n + nc, t + ct)
print(json.dumps({"case": name, "cpu_s": cpu, "converged": sol.converged,
                  "final_mass_kg": sol.final_mass_kg, "iterations": sol.iterations,
                  "runtime_s": sol.runtime_s, "calls": calls}))
"""


def profile(case: str) -> dict:
    out = subprocess.run([sys.executable, "-c", _PROFILE, case], capture_output=True, text=True,
                         env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})
    if out.returncode != 0:
        raise SystemExit(f"{case}: {out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def report(r: dict) -> None:
    t, it = r["runtime_s"], r["iterations"]
    total = t["total"]
    polish = t.get("newton", 0.0) + t.get("kkt", 0.0) + t.get("restore", 0.0) \
        + t.get("optimality", 0.0)
    print(f"\n{r['case']}: {r['final_mass_kg']:.4f} kg, converged {r['converged']}, "
          f"{total:.2f} s wall under cProfile; iterations {it}")
    print(f"  restoration + Newton + KKT + optimality: {polish:.2f} s = "
          f"{100 * polish / total:.0f} % of the solve")
    # (Newton's iterations inside the KKT restorations are counted in "kkt"'s time, in
    # ``iterations["newton"]`` too)
    for key in ("rollout", "restore", "ddp", "forward", "expansion", "backward", "newton",
                "optimality", "kkt", "repropagation"):
        per = ""
        if key in ("ddp", "forward", "expansion", "backward") and it["ddp"]:
            per = f"  ({1e3 * t[key] / it['ddp']:.1f} ms per DDP iteration)"
        elif key == "kkt" and it["kkt"]:
            per = f"  ({1e3 * t[key] / it['kkt']:.1f} ms per KKT iteration)"
        print(f"  {key:14s} {t.get(key, 0.0):8.3f} s {100 * t.get(key, 0.0) / total:5.1f} %{per}")
    print("  beneath them (cumulative, calls overlap):")
    for label, (n, s) in sorted(r["calls"].items(), key=lambda kv: -kv[1][1]):
        print(f"    {label:36s} {n:7d} calls {s:8.3f} s  {1e3 * s / max(n, 1):8.3f} ms/call")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", nargs="*", default=list(CASES))
    args = ap.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, python "
          f"{platform.python_version()}; one process per case, OPENBLAS_NUM_THREADS=1")
    for case in args.cases:
        report(profile(case))


if __name__ == "__main__":
    main()
