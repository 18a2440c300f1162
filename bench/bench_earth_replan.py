"""Warm re-plan of the remaining LEO->LEO transfer (issue 20's target: <= 2 s) after 5 % of its
flight from a 1 km / 1 m/s perturbation, through the guidance planner as the node runs it
(``GuidancePlanner.replan``: Cartesian estimate -> elements on the plan's grid of true
longitude -> the node's warm options, the plan's controls, duals and stage maps -> assessment).
The energy-optimal plan is the planner's own cold solve from the departure state (or a
solution read from --plan and adopted, its stage maps expanded then, as the node does); the
spacecraft flies it in Cartesian coordinates in time (``self_trigger.propagate``) to 40 % into
the stage at 5 % of the stages, where the estimate is moved by 1 km and 1 m/s in random
directions.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python bench/bench_earth_replan.py [--trials 3] [--plan FILE]
"""
from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np

from daddy_ros.planner import GuidancePlanner
from daddy_ros.self_trigger import propagate

CASE = "leo_leo"
TARGET_S = 2.0
T0_S = 1000.0


def fly(planner, plan, fraction: float):
    """(time s, Cartesian state SI (7,)) after flying ``plan`` from the departure in Cartesian
    coordinates to 40 % into the stage at ``fraction`` of its stages."""
    case = planner.case
    k = int(fraction * len(plan.stage_dt_s))
    x, t = case.cartesian_x0(), plan.epoch_s
    for j in range(k):
        x = propagate(case, x, plan.thrust_n[j], plan.stage_dt_s[j])
        t += plan.stage_dt_s[j]
    dt = 0.4 * plan.stage_dt_s[k]
    return t + dt, planner.units.cartesian_si(propagate(case, x, plan.thrust_n[k], dt))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=3)
    ap.add_argument("--plan", help="an energy-optimal leo_leo solution (JSON); default: solve it")
    args = ap.parse_args()
    pl = GuidancePlanner(CASE, thrust_margin=0.0, fuel_optimal=False, time_budget_s=3600.0)
    t = time.perf_counter()
    if args.plan:
        pl.load_plan(args.plan, T0_S)
        print(f"adopted {args.plan} (its stage maps expanded): {time.perf_counter() - t:.1f} s")
    else:
        x = pl.units.cartesian_si(pl.case.cartesian_x0())
        out = pl.replan(x[:3], x[3:6], x[6], T0_S)
        print(f"cold energy-optimal plan: {out.solve_time_s:.1f} s, {out.reason}, "
              f"{out.plan.states_si[-1, 6]:.3f} kg")
    plan = pl.plan
    t_s, x = fly(pl, plan, 0.05)
    walls = []
    for trial in range(args.trials):
        rng = np.random.default_rng(trial)
        dr, dv = (d / np.linalg.norm(d) for d in rng.normal(size=(2, 3)))
        pl.set_plan(plan)
        out = pl.replan(x[:3] + 1000.0 * dr, x[3:6] + dv, x[6], t_s)
        walls.append(out.solve_time_s)
        sol = pl.plan.solution
        print(f"trial {trial}: {out.solve_time_s:.2f} s, {out.level} {out.reason}, warm "
              f"{out.warm_start}, {len(pl.plan.stage_dt_s)} stages, converged {sol.converged}, "
              f"{pl.plan.states_si[-1, 6]:.3f} kg, violation {sol.max_violation:.1e}, "
              f"{out.iterations}")
    print(f"machine: {os.cpu_count()} cores; warm re-plan median {statistics.median(walls):.2f} s "
          f"(target {TARGET_S} s)")


if __name__ == "__main__":
    main()
