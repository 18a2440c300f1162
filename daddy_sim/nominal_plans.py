"""Regenerate the bundled nominal plans (``daddy_ros/plans/CASE_fuel.json``): each case's
cold solve at the simulation's start, by the guidance planner itself (its cold options: the
whole homotopy and the exact fuel end game, at the derated thrust bound the node plans at).

    python -m daddy_sim.nominal_plans [--cases halo_l2_l1 earth_mars] [--out DIR]
"""
from __future__ import annotations

import argparse
from pathlib import Path

from daddy_core.throttle import intermediate_stages
from daddy_ros.config import PLANS_DIR
from daddy_ros.planner import GuidancePlanner

from .sim import T0_S, TruthSim

CASES = ("earth_mars", "halo_l2_l1")


def nominal_plan(case: str, out: Path) -> str:
    """Solve ``case``'s nominal cold at T0 and write it to ``out/CASE_fuel.json``; a summary
    line."""
    planner = GuidancePlanner(case, time_budget_s=3600.0)
    p, v, m = TruthSim(case, t0_s=T0_S).truth_si()
    outcome = planner.replan(p, v, m, T0_S, "nominal", cold=True)
    if not outcome.ok:
        raise SystemExit(f"{case}: the nominal solve failed: {outcome.reason}")
    sol = outcome.plan.solution
    path = out / f"{case}_fuel.json"
    sol.to_json(path)
    u_max = planner.rated_problems[0].u_max
    return (f"{case}: {path} final mass {sol.final_mass_kg:.4f} kg, propellant "
            f"{sol.propellant_kg:.4f} kg, KKT residual {sol.kkt_residual:.1e}, "
            f"{intermediate_stages(sol.U, u_max)} of {sol.N} stages at intermediate thrust, "
            f"{outcome.solve_time_s:.1f} s")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", nargs="*", default=list(CASES), choices=list(CASES))
    ap.add_argument("--out", type=Path, default=PLANS_DIR)
    args = ap.parse_args(argv)
    for case in args.cases:
        print(nominal_plan(case, args.out), flush=True)


if __name__ == "__main__":
    main()
