"""Warm re-plan of the remaining LEO->LEO transfer (issue 20's target: <= 2 s) after 5 % of its
stages from a 1 km / 1 m/s perturbation, in the core (the guidance node does not fly
Earth-centred scenarios yet): the energy-optimal plan is solved cold first (or read from
--plan), its stage maps expanded once (what the node does when it adopts a plan), then the
remaining stages -- from the perturbed state's own true longitude to the same stage ends --
are re-solved with the node's warm re-plan options (``ReplanPolicy.warm``: the last homotopy
step, the plan's controls, duals of the remaining stages and their maps, Newton restoration
first, one AUL iteration at WARM_TOL_AUL).

    OPENBLAS_NUM_THREADS=1 .venv/bin/python bench/bench_earth_replan.py [--trials 3] [--plan FILE]
"""
from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np

from daddy_core.catalogue import load_case, problem_from_case
from daddy_core.dynamics import models
from daddy_core.solver import Solution, WarmStart, case_options, solve
from daddy_core.solver.stage_maps import StageMaps, expand_dynamics
from daddy_ros.config import PlannerConfig
from daddy_ros.replan_policy import ReplanPolicy

CASE = "leo_leo"
TARGET_S = 2.0


def remaining_problem(problem, units, sol: Solution, k0: int, rng, dr_m: float, dv_m_s: float):
    """The stages k0.. from the plan's node k0 moved by dr_m and dv_m_s in random directions
    (Cartesian), re-expressed in elements; the first stage starts at the moved state's true
    longitude and ends where the plan's did."""
    x, L = sol.X[k0], problem.stage_t0[k0]
    rv = models.mee_to_cartesian(x[:5], L, units.gm)
    d = rng.normal(size=6)
    rv[:3] += units.length(dr_m) * d[:3] / np.linalg.norm(d[:3])
    rv[3:] += units.speed(dv_m_s) * d[3:] / np.linalg.norm(d[3:])
    mee, L_new = models.cartesian_to_mee(rv, units.gm)
    L_new = L + ((L_new - L + np.pi) % (2 * np.pi) - np.pi)
    dts = problem.stage_dt[k0:].copy()
    dts[0] -= L_new - L
    return problem.with_x0(np.concatenate([mee, x[5:]]), dts, L_new)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=3)
    ap.add_argument("--plan", help="an energy-optimal leo_leo solution (JSON); default: solve it")
    args = ap.parse_args()
    case = load_case(CASE)
    problem = problem_from_case(case)
    if args.plan:
        sol = Solution.from_json(args.plan)
    else:
        t = time.process_time()
        sol = solve(problem, np.full((problem.N, 3), float(case.units.thrust(1e-6))),
                    fuel_optimal=False, options=case_options(case, False))
        print(f"cold energy-optimal plan: {time.process_time() - t:.1f} s CPU, "
              f"{sol.final_mass_kg:.3f} kg, violation {sol.max_violation:.1e}")
    warm = ReplanPolicy.of(case, PlannerConfig(scenario=CASE, fuel_optimal=False)).warm
    t = time.perf_counter()
    maps = StageMaps.of(expand_dynamics(problem, sol.X[:-1], sol.U), sol.X, sol.U, warm.eps_da)
    print(f"stage maps of the plan ({problem.N} stages): {time.perf_counter() - t:.2f} s")
    k0 = int(0.05 * problem.N)
    lam = np.asarray(sol.duals["lam"])[:, k0:].tolist()
    walls = []
    for trial in range(args.trials):
        rest = remaining_problem(problem, case.units, sol, k0, np.random.default_rng(trial),
                                 1000.0, 1.0)
        start = WarmStart(U=sol.U[k0:], duals={"lam": lam, "lam_t": sol.duals["lam_t"]},
                          maps=maps.tail(k0, False))
        t = time.perf_counter()
        s = solve(rest, start, fuel_optimal=False, options=warm)
        walls.append(time.perf_counter() - t)
        print(f"trial {trial}: {walls[-1]:.2f} s, converged {s.converged}, "
              f"{s.final_mass_kg:.3f} kg, violation {s.max_violation:.1e}, {s.iterations}")
    print(f"machine: {os.cpu_count()} cores; warm re-plan median {statistics.median(walls):.2f} s "
          f"(target {TARGET_S} s)")


if __name__ == "__main__":
    main()
