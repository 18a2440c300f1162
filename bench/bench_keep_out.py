"""Path constraints with the fuel homotopy from the default guess (issue 50, item 1): the
Clohessy-Wiltshire rendezvous of ``daddy_core.catalogue.rendezvous`` without and with its keep-out
sphere, solved by daddy with default options, beside an independent optimum of the same
discrete problem (``catalogue.rendezvous_reference.slsqp_reference``: scipy's SLSQP, the
keep-out at ``--samples`` points per stage), started from its own free optimum.

    .venv/bin/python bench/bench_keep_out.py [--keep-out-km 1.5] [--z0-km 0.1] [--cap 300]

Prints CPU, propellant (sum |u_k| dt, km per 1/n), converged and the reason, the dense
keep-out margin, and the ratios the issue states: daddy's keep-out CPU over its free CPU, and
its propellant over the oracle's.
"""
from __future__ import annotations

import argparse
import time

from daddy_core.catalogue.rendezvous import cw_rendezvous, propellant
from daddy_core.catalogue.rendezvous_reference import slsqp_reference
from daddy_core.solver import SolverOptions, solve


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--keep-out-km", type=float, default=1.5)
    ap.add_argument("--z0-km", type=float, default=0.1)
    ap.add_argument("--cap", type=float, default=300.0, help="time budget of one solve [s]")
    ap.add_argument("--samples", type=int, default=8, help="the oracle's keep-out points per stage")
    args = ap.parse_args()
    opts = SolverOptions(run=dict(time_budget_s=args.cap))
    rows = {}
    for label, km in (("free", None), ("keep-out", args.keep_out_km)):
        problem = cw_rendezvous(keep_out_km=km, z0_km=args.z0_km)
        t0 = time.process_time()
        sol = solve(problem, fuel_optimal=True, options=opts)
        cpu = time.process_time() - t0
        fuel = propellant(sol.U, problem.stage_dt)
        rows[label] = (cpu, fuel)
        margin = "" if sol.min_path_margin is None else f", margin {sol.min_path_margin:+.2e} km"
        print(f"daddy {label:9s} CPU {cpu:7.2f} s, propellant {fuel:.8f}, converged "
              f"{sol.converged}, exact {sol.exact_fuel}, max violation {sol.max_violation:.1e}"
              f"{margin}: {sol.reason[:160]}", flush=True)
    t0 = time.process_time()
    f_free, f_kept, _ = slsqp_reference(cw_rendezvous(z0_km=args.z0_km), args.keep_out_km,
                                        args.samples)
    print(f"SLSQP oracle ({args.samples} keep-out samples per stage, {time.process_time() - t0:.1f} s"
          f" CPU): free {f_free:.8f}, keep-out {f_kept:.8f}")
    print(f"ratios: keep-out CPU / free CPU {rows['keep-out'][0] / rows['free'][0]:.1f} "
          f"(target <= 10); propellant / oracle: free {rows['free'][1] / f_free - 1:+.2e}, "
          f"keep-out {rows['keep-out'][1] / f_kept - 1:+.2e} (target |.| <= 1e-4)")


if __name__ == "__main__":
    main()
