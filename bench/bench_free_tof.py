"""Earth-Mars with the time of flight free in [300, 400] days (issue 46), fuel-optimal: daddy's
free-ToF solve against its fixed-ToF solve (CPU medians of interleaved runs, ratio), at the
default tol_optimality and at 1e-9, and against a CasADi + IPOPT transcription with the same
free time (``casadi_peer.solve_peer_free_tof``; casadi is benchmark-only,
requirements/optional.txt), its controls re-flown in daddy's model.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python bench/bench_free_tof.py [--rounds 3] [--no-peer]
"""
from __future__ import annotations

import argparse
import math
import platform
import time

import numpy as np

from daddy_core.catalogue import load_case, problem_from_case
from daddy_core.problem import max_violation
from daddy_core.solver import case_options, solve

WINDOW_DAYS = (300.0, 400.0)


def cpu(fn):
    t = time.process_time()
    out = fn()
    return time.process_time() - t, out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--no-peer", action="store_true")
    args = ap.parse_args()
    case = load_case("earth_mars")
    day = 86400.0 / case.units.tu_s   # one day, normalised
    fixed = problem_from_case(case)
    free = problem_from_case(case, tof_window=list(WINDOW_DAYS))
    runs = {"fixed": (fixed, {}), "free": (free, {}),
            "free, tol_optimality 1e-9": (free, dict(kkt=dict(tol=1e-9)))}
    times = {k: [] for k in runs}
    sols = {}
    for _ in range(args.rounds):   # interleaved
        for name, (p, change) in runs.items():
            t, sols[name] = cpu(lambda: solve(p, case.cold_guess(p.N), fuel_optimal=True,
                                              options=case_options(case, True, **change)))
            times[name].append(t)
    print(f"machine: {platform.machine()} {platform.processor() or ''}, {args.rounds} rounds, "
          "cold starts")
    base = float(np.median(times["fixed"]))
    for name, sol in sols.items():
        tof = sol.parameters["tof"] / day if sol.parameters else case.tof / day
        med = float(np.median(times[name]))
        print(f"{name:28s} converged={sol.converged} mass {sol.final_mass_kg:.6f} kg, ToF "
              f"{tof:.4f} d, KKT {sol.kkt_residual:.1e}, CPU {med:.2f} s ({med / base:.2f}x "
              f"fixed), iterations {sol.iterations}")
    if args.no_peer:
        return
    from casadi_peer import solve_peer_free_tof
    for label, U0 in (("daddy's fixed-ToF optimum", sols["fixed"].U),
                      ("the case's cold guess", case.cold_guess(fixed.N))):
        window = tuple(case.units.time(d * 86400.0) for d in WINDOW_DAYS)
        mass, T, status, iters, t, Uc = solve_peer_free_tof(case, fixed, U0, window, 600.0)
        # re-flown in daddy's model: the free problem's controls with the stage-0 increment of
        # theta = ln(T / T_case) (scale 1, guess 0)
        W = np.column_stack([Uc, np.zeros(fixed.N)])
        W[0, 3] = math.log(T / case.tof)
        X = free.rollout(W)
        _, _, g_t, n_t = free.constraint_values(X, W)
        print(f"CasADi from {label}: {status}, {iters} it, {t:.1f} s; transcription mass "
              f"{mass:.6f} kg, ToF {T / day:.4f} d; re-flown in daddy's model: mass "
              f"{case.units.mass_kg(X[-1, 6]):.6f} kg, arrival miss {max_violation(g_t, n_t):.1e}")


if __name__ == "__main__":
    main()
