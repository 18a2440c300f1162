"""Side-by-side benchmark of two source trees (a clone of an earlier commit and this one): each
workload runs in a fresh process per tree, alternating tree by tree for ``--rounds`` rounds
(interleaved, so this shared machine's drift hits both alike), and the table shows the median
CPU time of each and their ratio, with the masses and iteration counts that show whether the
two computed the same thing.

    git clone -q . /tmp/base && git -C /tmp/base checkout <commit>
    .venv/bin/python bench/bench_compare.py --base /tmp/base [--rounds 3] [--all]

Workloads: the solver's bench cases (CPU per solve and per DDP iteration), batched stage
expansions (CR3BP, RK78, order 2, 10 variables) at B = 1, 10, 110 stages (us per stage), single
and batched map evaluation, warm re-plans (``bench_replan``'s perturbed states, wall time of the solve) and
``import daddy_core.cli``. One core per process
(OPENBLAS_NUM_THREADS=1).
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent

# run in a child process: prints one JSON object {label: [value, info]} on its last line
_SOLVE = """
import json, sys, time
import numpy as np
from daddy_core.catalogue import load_case, problem_from_case
from daddy_core.solver import case_options, solve
import scipy.linalg, scipy.sparse.linalg  # noqa: E401,F401  imported before the clock starts, in
# both trees (the solver imports them at its first Newton step; start-up is its own row)
name, fuel = sys.argv[1], sys.argv[2] == "fuel"
case = load_case(name); prob = problem_from_case(case)
u0 = np.full((prob.N, 3), float(case.units.thrust(case.solver.get("u_guess_n", 1e-6))))
c0 = time.process_time()
sol = solve(prob, u0, method="dyn", fuel_optimal=fuel, options=case_options(case, fuel))
cpu = time.process_time() - c0
it = sol.iterations["ddp"]
info = f"{sol.final_mass_kg:.10f} kg, {it} DDP it"
print(json.dumps({f"{name} {sys.argv[2]} s": [cpu, info],
                  f"{name} {sys.argv[2]} ms/DDP it": [1e3 * cpu / max(it, 1), info]}))
"""

_EXPAND = """
import json, time
import numpy as np
from daddy_core import da
from daddy_core.integrators import rk78
from daddy_core.catalogue import load_case
case = load_case("halo_l2_l1"); rhs = case.rhs()
dt = 20 * 86400 / case.units.tu_s / 110
z0 = np.concatenate([case.x0, [0.05, -0.1, 0.12]])
def per_call(fn, seconds=0.5):
    fn(); n, t0 = 0, time.process_time()
    while True:
        fn(); n += 1
        el = time.process_time() - t0
        if el > seconds and n >= 3:
            return el / n
out = {}
for B in (1, 10, 110):
    x = da.variables(np.tile(z0[:, None], (1, B)), order=2)
    out[f"expansion B={B} us/stage"] = [
        1e6 * per_call(lambda: rk78(rhs, x[:7], x[7:], 0.0, dt, tol=1e-13)) / B, ""]
m1 = rk78(rhs, da.variables(z0, 2)[:7], da.variables(z0, 2)[7:], 0.0, dt)
out["map evaluation single us"] = [1e6 * per_call(lambda: da.evaluate(m1, np.full(10, 1e-4))), ""]
xb = da.variables(np.tile(z0[:, None], (1, 110)), 2)
mb = rk78(rhs, xb[:7], xb[7:], 0.0, dt)
dvb = np.full((10, 110), 1e-4)
out["map evaluation B=110 us/stage"] = [1e6 * per_call(lambda: da.evaluate(mb, dvb)) / 110, ""]
print(json.dumps(out))
"""

_IMPORT = """
import json, time
c0 = time.process_time()
import daddy_core.cli  # noqa: F401
print(json.dumps({"import daddy_core.cli s (after interpreter start)": [time.process_time() - c0, ""]}))
"""

_REPLAN = """
import json, os, statistics, sys
sys.path.insert(0, os.path.join(os.environ["PYTHONPATH"], "bench"))
import numpy as np
from bench_replan import PERTURB, perturbed_state
from daddy_sim.closed_loop import nominal_planner
out = {}
for case in ("earth_mars", "halo_l2_l1"):
    times = []
    for i in range(5):
        planner, _ = nominal_planner(case, 600.0)
        p, v, m, t = perturbed_state(case, planner, np.random.default_rng(i), *PERTURB[case])
        o = planner.replan(p, v, m, t, f"w{i}", now_s=t)
        times.append(o.solve_time_s * 1e3)
    out[f"warm re-plan {case} ms (median of 5)"] = [
        statistics.median(times), f"{o.plan.solution.final_mass_kg:.6f} kg, {o.iterations}"]
print(json.dumps(out))
"""

QUICK_CASES = [("earth_mars", "energy"), ("earth_mars", "fuel")]
ALL_CASES = QUICK_CASES + [("halo_l2_l1", "fuel"), ("dro_dro", "fuel")]


def run(tree: str, code: str, args: list[str]) -> dict:
    env = dict(os.environ, PYTHONPATH=tree, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    out = subprocess.run([sys.executable, "-c", code, *args], env=env, cwd="/tmp",
                         capture_output=True, text=True, check=False)
    if out.returncode:
        raise SystemExit(f"workload failed under {tree}:\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", required=True, help="source tree of the earlier commit")
    ap.add_argument("--new", default=str(REPO), help="source tree to compare (default: this one)")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--all", action="store_true", help="add the halo and DRO solves (minutes)")
    args = ap.parse_args()
    sys.path.insert(0, str(HERE))
    from bench_da import machine
    print(f"machine: {machine()}; {args.rounds} interleaved rounds, one process per run")
    print(f"base {args.base}\nnew  {args.new}")
    jobs = [(_IMPORT, []), (_EXPAND, []), (_REPLAN, [])] + [
        (_SOLVE, [c, f]) for c, f in (ALL_CASES if args.all else QUICK_CASES)]
    samples: dict[str, dict[str, list]] = {}
    for r in range(args.rounds):
        for code, a in jobs:
            for which, tree in (("base", args.base), ("new", args.new)):
                for label, (value, info) in run(tree, code, a).items():
                    samples.setdefault(label, {"base": [], "new": []})[which].append((value, info))
        print(f"round {r + 1} done", file=sys.stderr, flush=True)
    print(f"{'workload':44s} {'base':>10s} {'new':>10s} {'new/base':>8s}  what each computed")
    for label, s in samples.items():
        b = statistics.median(v for v, _ in s["base"])
        n = statistics.median(v for v, _ in s["new"])
        infos = (f"base {s['base'][0][1]}; new {s['new'][0][1]}"
                 if s["base"][0][1] else "")
        print(f"{label:44s} {b:10.4g} {n:10.4g} {n / b:8.2f}  {infos}")


if __name__ == "__main__":
    main()
