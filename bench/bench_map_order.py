"""The stage maps' order (``DDPOptions.map_order``, issue 47) side by side: each catalogue case
solved cold at each order, one process per solve, interleaved; CPU seconds, DDP iterations,
the share of stages the Dyn forward pass served by their polynomial, the answer, and each
CPU ratio to the first order's.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python bench/bench_map_order.py
        [--cases double_integrator earth_mars halo_l2_l1] [--orders 2 3 4] [--fuel] [--cap 600]
"""
from __future__ import annotations

import argparse
import platform

from bench_multiplier_update import run


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", nargs="*", default=["double_integrator", "earth_mars",
                                                   "halo_l2_l1", "dro_dro", "lyapunov_l1_l2"])
    ap.add_argument("--orders", nargs="+", type=int, default=[2, 3, 4])
    ap.add_argument("--fuel", action="store_true", help="fuel-optimal (default: energy)")
    ap.add_argument("--cap", type=float, default=600.0)
    args = ap.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, one solve at a time")
    for case in args.cases:
        kind = "fuel" if args.fuel and case != "double_integrator" else "energy"
        runs = [run(case, kind, {"ddp": {"map_order": k}}, args.cap) for k in args.orders]
        base = runs[0]["cpu_s"]
        cells = [f"order {k}: {r['cpu_s']} s ({r['cpu_s'] / base if base else float('nan'):.2f})"
                 f", DDP {r['ddp']}, polynomial {r['share'] or 0:.0%}, "
                 f"{r['mass_kg'] if r['mass_kg'] is not None else r['cost']}, "
                 f"converged {r['converged']}" for k, r in zip(args.orders, runs)]
        print(f"{case:18s} {kind:6s} " + " | ".join(cells), flush=True)


if __name__ == "__main__":
    main()
