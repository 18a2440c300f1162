"""Robustness from random initial guesses (issue 18): for a catalogue case, solve from many
guesses -- the paper's 1e-6 N guess, zero thrust, and random ones (uniform directions,
magnitudes uniform up to the thrust bound) -- each with a time cap, and report the success
rate, the distinct optima found and the solve times (the measurement of PDDP's Table 3).

    .venv/bin/python bench/bench_robustness.py CASE [--guesses 100] [--seed 0] [--cap 60]
                                               [--jobs 2] [--energy]
                                               [--globalization trust_region] [--peer]
                                               [--multiplier-update sweep]
                                               [--r-min-km KM --reference-kg KG]

Success: converged (feasible and KKT residual <= tol_optimality), max violation <= 1e-10, and
the final mass within WINDOW_KG of the paper's (Tables 6 and 9: the Dyn column, m_N + 500 kg dry
mass; the double integrator: its closed-form cost). The count of runs feasible in that window
whatever their KKT residual is printed too (the success of the code before the KKT residual
became part of ``converged``).

``--peer``: the same guesses also go to a direct transcription, CasADi + IPOPT
(``casadi_peer.py``; benchmark-only, never a dependency: ``pip install -c requirements/pins.txt
casadi``), with the same cap, judged the same way on its controls re-flown in daddy's stage
flows (IPOPT's success status, the re-flown arrival within ``casadi_peer.PEER_MISS``, the mass in
the window); the two are printed side by side with the guesses each alone solved.

``--costate``: PDDP (issue 48) from random costate guesses beside scipy single shooting, the
same guesses for both (``bench_pddp.py robustness``, whose docstring defines them).

``--r-min-km``: the case with a keep-out sphere around the Moon (or the Sun) held along the
whole trajectory (issue 23); success then also needs the dense re-propagation's margin >= 0
(``Solution.min_path_margin`` >= -1e-10), and the window is centred on ``--reference-kg`` (the
constrained optimum's mass, which the paper does not give) instead of the paper's mass.
"""
from __future__ import annotations

import argparse
import concurrent.futures
import os
import statistics
import time

import numpy as np

from daddy_core.catalogue import load_case, problem_from_case
from daddy_core.solver import Globalization, MultiplierUpdate, case_options, solve
from daddy_core.solver.multistart import random_starts, value_of

# the paper's final masses (kg, Dyn method: Table 6 Earth-Mars fuel, Table 9 CR3BP) and the
# double integrator's closed-form cost; a solution within WINDOW_KG (or 1e-6 relative on a cost)
# of it counts as the paper's optimum
PAPER = {"earth_mars": 603.44, "halo_l2_l1": 973.93, "nrho_dro": 977.39,
         "lyapunov_l1_l2": 997.49, "dro_dro": 996.32, "dro_dro_2rev": 996.77,
         "dro_dro_3rev": 996.86, "double_integrator": 1.1272727}
WINDOW_KG = 0.5


def guesses(case_name: str, n: int, seed: int) -> list[np.ndarray]:
    """The paper's guess (1e-6 N on every component), zero thrust, then random guesses
    (``multistart.random_starts``: random directions, magnitudes up to the bound)."""
    case = load_case(case_name)
    prob = problem_from_case(case)
    scale = float(case.units.thrust(case.solver.get("u_guess_n", 1e-6))) if case.spacecraft \
        else case.solver.get("u_guess_n", 1e-6)
    out = [np.full((prob.N, prob.nu), scale), np.zeros((prob.N, prob.nu))]
    out += [s.guess for s in random_starts(prob, max(n - len(out), 0), seed)]
    return out[:n]


def _in_window(case_name: str, fuel: bool, value: float, is_mass: bool,
               reference: float | None = None) -> bool:
    """The final mass within WINDOW_KG of ``reference`` or else the paper's (a cost: 1e-6
    relative)."""
    ref = PAPER.get(case_name) if fuel or case_name == "double_integrator" else None
    ref = ref if reference is None else reference
    if ref is None:
        return True
    return abs(value - ref) <= (WINDOW_KG if is_mass else 1e-6 * abs(ref))


def run_one(job) -> dict:
    """Solve one guess (a worker process)."""
    case_name, fuel, U0, cap, globalization, update, peer, r_min_km, reference = job
    case = load_case(case_name)
    prob = problem_from_case(case, r_min_km=r_min_km)
    if peer:
        return run_peer(case, prob, U0, fuel, cap)
    opts = case_options(case, fuel, run=dict(time_budget_s=cap),
                        ddp=dict(globalization=globalization),
                        aul=dict(multiplier_update=update))
    t0 = time.process_time()
    try:
        sol = solve(prob, U0, method="dyn", fuel_optimal=fuel, options=opts)
    except Exception as exc:  # noqa: BLE001  a crash is a failed run, reported
        return {"ok": False, "value": float("nan"), "cpu_s": time.process_time() - t0,
                "reason": f"raised {type(exc).__name__}: {exc}"}
    value = value_of(sol)
    in_window = _in_window(case_name, fuel, value, sol.final_mass_kg is not None, reference)
    held = sol.min_path_margin is None or sol.min_path_margin >= -1e-10
    feasible = sol.max_violation <= 1e-10 and in_window and held
    ok = sol.converged and feasible
    return {"ok": ok, "converged": sol.converged, "feasible": feasible, "value": value,
            "cpu_s": time.process_time() - t0, "violation": sol.max_violation,
            "kkt": sol.kkt_residual, "reason": sol.reason if not ok else ""}


def run_peer(case, prob, U0, fuel: bool, cap: float) -> dict:
    """The CasADi + IPOPT transcription from the same guess (``casadi_peer``)."""
    from casadi_peer import PEER_MISS, solve_peer
    t0 = time.process_time()
    try:
        r = solve_peer(case, prob, U0, fuel, cap)
    except Exception as exc:  # noqa: BLE001  a crash is a failed run, reported
        return {"ok": False, "value": float("nan"), "cpu_s": time.process_time() - t0,
                "reason": f"raised {type(exc).__name__}: {exc}"}
    feasible = (r.miss <= PEER_MISS and r.violation <= 1e-10
                and _in_window(case.name, fuel, r.value, case.spacecraft is not None))
    ok = r.ok_status and feasible
    return {"ok": ok, "converged": r.ok_status, "feasible": feasible, "value": r.value,
            "cpu_s": r.cpu_s, "violation": max(r.miss, r.violation), "kkt": None,
            "reason": "" if ok else f"IPOPT {r.status}, {r.iterations} iterations, re-flown "
                                    f"miss {r.miss:.1e}"}


def _summary(label: str, runs: list, args, fuel: bool, wall: float) -> None:
    ok = [r for r in runs if r["ok"]]
    values = sorted(round(r["value"], 2) for r in runs if r.get("converged"))
    optima = {v: values.count(v) for v in dict.fromkeys(values)}
    cpu = [r["cpu_s"] for r in runs]
    kind = "fuel" if fuel else "energy"
    print(f"{label}: {args.case} {kind}, {len(runs)} guesses (seed {args.seed}, "
          f"cap {args.cap:g} s, {args.jobs} jobs): success {len(ok)}/{len(runs)} "
          f"({len(ok) / len(runs):.0%}; feasible in the window whatever the optimality "
          f"measure: {sum(bool(r.get('feasible')) for r in runs)}); "
          f"CPU per solve median {statistics.median(cpu):.2f} s, max {max(cpu):.2f} s; wall "
          f"{wall:.0f} s")
    ref = PAPER.get(args.case) if fuel or args.case == "double_integrator" else None
    for name, group in (("successes", ok), ("failures", [r for r in runs if not r["ok"]])):
        if group:
            times = [r["cpu_s"] for r in group]
            print(f"  {name}: CPU median {statistics.median(times):.1f} s, max {max(times):.1f} s")
    if args.r_min_km:
        print(f"  keep-out r_min {args.r_min_km:g} km, window centred on {args.reference_kg}")
    print(f"  paper {ref if ref is not None else '-'}; converged optima (value: count): "
          + ", ".join(f"{v:g}: {c}" for v, c in optima.items()))
    for i, r in enumerate(runs):
        if not r["ok"]:
            print(f"  guess {i}: {r['value']:.4f}, violation {r.get('violation', float('nan')):.1e},"
                  f" {r['cpu_s']:.1f} s: {r['reason'] or 'outside the window'}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("case")
    ap.add_argument("--guesses", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cap", type=float, default=60.0, help="time budget of one solve [s]")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--energy", action="store_true", help="energy-optimal (default: fuel)")
    ap.add_argument("--globalization", default="line_search",
                    choices=[g.value for g in Globalization])
    ap.add_argument("--multiplier-update", default="first_order",
                    choices=[m.value for m in MultiplierUpdate])
    ap.add_argument("--peer", action="store_true",
                    help="also solve every guess with the CasADi + IPOPT transcription")
    ap.add_argument("--r-min-km", type=float, default=None,
                    help="keep-out sphere around the Moon (Sun) held along the trajectory")
    ap.add_argument("--reference-kg", type=float, default=None,
                    help="centre of the success window (default: the paper's mass)")
    ap.add_argument("--costate", action="store_true",
                    help="PDDP from random costate guesses beside scipy single shooting "
                         "(bench_pddp.py robustness; Earth-Moon CR3BP cases)")
    args = ap.parse_args()
    if args.costate:   # the costate parametrisation's own guesses and peer (issue 48)
        from bench_pddp import robustness
        robustness(args.case, args.guesses, 1.0, args.seed, args.cap, max(1, args.jobs))
        return 0
    if args.peer and args.r_min_km:
        ap.error("--peer has no keep-out constraint: drop --r-min-km")
    fuel = not args.energy and args.case != "double_integrator"
    U0s = guesses(args.case, args.guesses, args.seed)
    solvers = [(f"daddy (dyn, {args.globalization}, {args.multiplier_update} multipliers)",
                 False)]
    if args.peer:
        solvers.append(("CasADi + IPOPT", True))
    results = {}
    for label, peer in solvers:
        jobs = [(args.case, fuel, U0, args.cap, args.globalization, args.multiplier_update, peer,
                 args.r_min_km, args.reference_kg) for U0 in U0s]
        wall = time.perf_counter()
        with concurrent.futures.ProcessPoolExecutor(max(1, args.jobs)) as pool:
            runs = list(pool.map(run_one, jobs))
        results[label] = runs
        _summary(label, runs, args, fuel, time.perf_counter() - wall)
    if args.peer:
        (la, a), (lb, b) = results.items()
        only_a = [i for i, (x, y) in enumerate(zip(a, b)) if x["ok"] and not y["ok"]]
        only_b = [i for i, (x, y) in enumerate(zip(a, b)) if y["ok"] and not x["ok"]]
        print(f"same guesses: {la} alone solved {len(only_a)} {only_a}; {lb} alone solved "
              f"{len(only_b)} {only_b}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
