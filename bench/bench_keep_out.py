"""Path constraints with the fuel homotopy from the default guess (issue 50, item 1): the
Clohessy-Wiltshire rendezvous of ``daddy_core.catalogue.rendezvous`` without and with its keep-out
sphere, solved by daddy with default options, beside an independent optimum of the same
discrete problem (``catalogue.rendezvous_reference.slsqp_reference``: scipy's SLSQP, the
keep-out at ``--samples`` points per stage), started from its own free optimum and from
daddy's answer (the same optimum: a local optimum of both; lower: a point SLSQP improves).

    .venv/bin/python bench/bench_keep_out.py [--keep-out-km 1.5] [--z0-km 0.1] [--cap 300]
        [--multiplier-update {first_order,second_order,sweep}]

Prints CPU, propellant (sum |u_k| dt, km per 1/n), converged and the reason, the dense
keep-out margin, and the ratios the issue states: daddy's keep-out CPU over its free CPU, and
its propellant over the oracle's (the lower of its two starts).
"""
from __future__ import annotations

import argparse
import time

from daddy_core.catalogue.rendezvous import cw_rendezvous, propellant
from daddy_core.catalogue.rendezvous_reference import slsqp_reference
from daddy_core.solver import MultiplierUpdate, SolverOptions, solve


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--keep-out-km", type=float, default=1.5)
    ap.add_argument("--z0-km", type=float, default=0.1)
    ap.add_argument("--cap", type=float, default=300.0, help="time budget of one solve [s]")
    ap.add_argument("--samples", type=int, default=8, help="the oracle's keep-out points per stage")
    ap.add_argument("--multiplier-update", choices=[m.value for m in MultiplierUpdate],
                    default=None, help="aul.multiplier_update (default: the solver's default)")
    args = ap.parse_args()
    opts = SolverOptions(run=dict(time_budget_s=args.cap))
    if args.multiplier_update:
        opts = opts.with_(aul=dict(multiplier_update=args.multiplier_update))
    rows = {}
    for label, km in (("free", None), ("keep-out", args.keep_out_km)):
        problem = cw_rendezvous(keep_out_km=km, z0_km=args.z0_km)
        t0 = time.process_time()
        sol = solve(problem, fuel_optimal=True, options=opts)
        cpu = time.process_time() - t0
        fuel = propellant(sol.U, problem.stage_dt)
        rows[label] = (cpu, fuel, sol.U)
        margin = "" if sol.min_path_margin is None else f", margin {sol.min_path_margin:+.2e} km"
        print(f"daddy {label:9s} CPU {cpu:7.2f} s, propellant {fuel:.8f}, converged "
              f"{sol.converged}, exact {sol.exact_fuel}, max violation {sol.max_violation:.1e}"
              f"{margin}: {sol.reason[:160]}", flush=True)
    t0 = time.process_time()
    free_problem = cw_rendezvous(z0_km=args.z0_km)
    f_free, f_kept, _ = slsqp_reference(free_problem, args.keep_out_km, args.samples)
    _, f_daddy, _ = slsqp_reference(free_problem, args.keep_out_km, args.samples,
                                    start=rows["keep-out"][2])
    print(f"SLSQP oracle ({args.samples} keep-out samples per stage, {time.process_time() - t0:.1f} s"
          f" CPU): free {f_free:.8f}, keep-out {f_kept:.8f} (from its free optimum), "
          f"{f_daddy:.8f} (from daddy's answer)")
    f_kept = min(f_kept, f_daddy)
    print(f"ratios: keep-out CPU / free CPU {rows['keep-out'][0] / rows['free'][0]:.1f} "
          f"(target <= 10); propellant / oracle: free {rows['free'][1] / f_free - 1:+.2e}, "
          f"keep-out {rows['keep-out'][1] / f_kept - 1:+.2e} (target |.| <= 1e-4)")


if __name__ == "__main__":
    main()
