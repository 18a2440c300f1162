"""The solar-sail cases (issue 45): each solved from the steering law and from the Sun-facing
guess, one process per solve, with its CPU time and peak memory, beside the steering law held
per stage and the issue's independent references.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python bench/bench_sail.py [--cases geo_sail_3rev ...]
        [--guesses steering_law sun_facing] [--continuous-law]

The 500-revolution case (``--cases geo_sail_500rev --guesses steering_law``) is the issue's
target of <= 10 minutes CPU on one core and <= 4 GiB.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys

REFERENCES_KM = {   # issue 45's table (CasADi + IPOPT, or the paper where that is all there is)
    "geo_sail_2d_3rev": 205.7018, "geo_sail_3rev": 208.8721, "acs3_3rev": 0.46816,
    "acs3_3rev_j2": 0.46618, "acs3_3rev_j2j4": 0.385446, "acs3_3rev_all": 0.385513,
    "geo_sail_500rev": 3793.1,
}

SOLVE = """
import json, resource, sys, time
from daddy_core.catalogue import load_case
from daddy_core.catalogue.sail_cases import SailGuess, continuous_law, solve_sail
case = load_case(sys.argv[1])
t = time.process_time()
r = solve_sail(case, SailGuess(sys.argv[2]))
cpu = time.process_time() - t
out = {"cpu_s": round(cpu, 1), "converged": r.solution.converged, "reason": r.solution.reason,
       "delta_a_km": r.delta_a_km, "law_delta_a_km": r.law_delta_a_km,
       "peak_rss_mib": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024),
       "iterations": r.solution.iterations}
if sys.argv[3] == "1":
    xf = continuous_law(case)
    a = lambda s: s[0] / (1 - s[1] ** 2 - s[2] ** 2)
    out["continuous_law_km"] = (a(xf) - a(case.x0)) * case.units.lu_km
print(json.dumps(out))
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", nargs="*", default=[c for c in REFERENCES_KM if "500" not in c])
    ap.add_argument("--guesses", nargs="*", default=["steering_law", "sun_facing"])
    ap.add_argument("--continuous-law", action="store_true",
                    help="also fly the steering law continuously (DOP853)")
    args = ap.parse_args()
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores; "
          "one solve at a time")
    for case in args.cases:
        for guess in args.guesses:
            run = subprocess.run([sys.executable, "-c", SOLVE, case, guess,
                                  "1" if args.continuous_law else "0"],
                                 env=env, capture_output=True, text=True)
            if run.returncode:
                print(f"{case:18s} {guess:13s} failed: {run.stderr.strip().splitlines()[-1:]}")
                continue
            r = json.loads(run.stdout.strip().splitlines()[-1])
            d, law = r["delta_a_km"], r["law_delta_a_km"]["osculating"]
            extra = "".join(f", {k} {v:.5f} km" for k, v in d.items() if k != "osculating")
            cont = (f", continuous law {r['continuous_law_km']:.4f} km"
                    if "continuous_law_km" in r else "")
            print(f"{case:18s} {guess:13s} da {d['osculating']:.5f} km{extra}; law per stage "
                  f"{law:.5f} km{cont}; reference {REFERENCES_KM[case]} km "
                  f"(ratio {d['osculating'] / REFERENCES_KM[case]:.4f}); {r['cpu_s']} s CPU, "
                  f"{r['peak_rss_mib']} MiB, converged {r['converged']}, DDP "
                  f"{r['iterations'].get('ddp')} it")


if __name__ == "__main__":
    main()
