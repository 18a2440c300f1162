"""daddy against a direct transcription (CasADi + IPOPT) on an Earth-centred transfer, energy-
optimal, same case, same run (issue 20: "below the CasADi + IPOPT transcription").

The transcription is independent of daddy's code: multiple shooting in modified equinoctial
elements with the true longitude as the independent variable, the Gauss equations written
again here in CasADi, ``--substeps`` RK4 steps per stage; the same stages (equal arcs of L),
the same stage cost (the energy term of the pseudo-Huber cost, each stage's duration taken as
dL p^1.5 / sqrt(mu)), the thrust bound and dry mass as inequalities, and the arrival -- the
target's p, f, g, h, k and t_N = ToF -- as equalities (daddy's terminal cost is then zero). Both
start from the catalogue's cold guess, 1e-6 N along each RTN axis (the transcription's states
by default linear in L from x0 to the target, its usual guess: from daddy's guess rolled out,
``--guess rollout``, IPOPT crawled at steps of 2e-4 with the infeasibility stuck at 0.24 after
87 iterations, 2026-12-02). IPOPT: exact Hessian, MUMPS, tol 1e-8. The transcription's controls are re-flown in daddy's stage flows
(RK78 at 1e-13) to report how far its RK4 trajectory is from the arrival.

    .venv/bin/python -m pip install -c requirements/pins.txt casadi   # optional.txt
    OPENBLAS_NUM_THREADS=1 .venv/bin/python bench/bench_earth_casadi.py [--case meo_meo]
"""
from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np

from daddy_core.catalogue import load_case, problem_from_case
from daddy_core.solver import case_options, solve


def transcription(case, N: int, substeps: int, max_cpu_s: float, verbose: bool):
    """(solver, bounds and guess builder): the NLP of the module docstring."""
    import casadi as ca
    units, sc = case.units, case.spacecraft
    gm, c = units.gm, sc.exhaust_speed(units)
    u_max = float(units.thrust(sc.max_thrust_n))
    dL = case.stage_lengths(N)[0]
    gain = case.problem.get("stage_cost_gain", 1e-2)
    scale = 1.0 / (case.tof / N * u_max)

    x, u, L = ca.SX.sym("x", 7), ca.SX.sym("u", 3), ca.SX.sym("L")
    p, f, g, h, k, m = x[0], x[1], x[2], x[3], x[4], x[6]
    ar, at, an = u[0] / m, u[1] / m, u[2] / m
    sL, cL = ca.sin(L), ca.cos(L)
    w = 1 + f * cL + g * sL
    sq = ca.sqrt(p / gm)
    hk = h * sL - k * cL
    s2 = 1 + h * h + k * k
    tau = 1 / (ca.sqrt(gm * p) * (w / p) ** 2 + sq * hk * an / w)        # dt/dL
    rhs = ca.Function("rhs", [L, x, u], [tau * ca.vertcat(
        2 * p / w * sq * at,
        sq * (ar * sL + ((w + 1) * cL + f) * at / w - g * hk * an / w),
        sq * (-ar * cL + ((w + 1) * sL + g) * at / w + f * hk * an / w),
        sq * s2 * cL / (2 * w) * an,
        sq * s2 * sL / (2 * w) * an,
        1,
        -ca.sqrt(u[0] ** 2 + u[1] ** 2 + u[2] ** 2 + 1e-24) / c)])
    y, hs = x, dL / substeps
    for j in range(substeps):
        Lj = L + j * hs
        k1 = rhs(Lj, y, u)
        k2 = rhs(Lj + hs / 2, y + hs / 2 * k1, u)
        k3 = rhs(Lj + hs / 2, y + hs / 2 * k2, u)
        k4 = rhs(Lj + hs, y + hs * k3, u)
        y = y + hs / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    flow = ca.Function("flow", [L, x, u], [y]).map(N)
    cost = ca.Function("cost", [x, u], [0.5 * gain * ca.sumsqr(u) * (dL * p ** 1.5 / np.sqrt(gm)
                                                                    * scale) ** 2]).map(N)

    X, U = ca.MX.sym("X", 7, N + 1), ca.MX.sym("U", 3, N)
    Ls = case.t_start + dL * np.arange(N)
    defects = flow(Ls[None, :], X[:, :-1], U) - X[:, 1:]
    xt = case.x_target
    arrival = ca.vertcat(X[:5, -1] - xt[:5], (X[5, -1] - xt[5]) / xt[5])
    thrust = ca.sum1(U ** 2).T / u_max ** 2 - 1                            # <= 0
    dry = sc.dry_mass_kg / units.mu_kg - X[6, 1:].T                        # <= 0
    nlp = {"x": ca.vertcat(ca.vec(X), ca.vec(U)), "f": ca.sum2(cost(X[:, :-1], U)),
           "g": ca.vertcat(ca.vec(defects), arrival, thrust, dry)}
    solver = ca.nlpsol("transcription", "ipopt", nlp, {
        "ipopt.tol": 1e-8, "ipopt.print_level": 5 if verbose else 0, "print_time": False,
        "ipopt.linear_solver": "mumps", "ipopt.max_cpu_time": max_cpu_s})
    n_eq = 7 * N + 6
    lbg = np.concatenate([np.zeros(n_eq), np.full(2 * N, -np.inf)])
    ubg = np.zeros(n_eq + 2 * N)
    lbx = np.full(7 * (N + 1) + 3 * N, -np.inf)
    ubx = np.full_like(lbx, np.inf)
    lbx[:7], ubx[:7] = case.x0, case.x0                                    # x_0 fixed
    return solver, lbg, ubg, lbx, ubx


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", default="meo_meo")
    ap.add_argument("--substeps", type=int, default=4, help="RK4 steps per stage")
    ap.add_argument("--max-cpu", type=float, default=1200.0, help="IPOPT's CPU budget [s]")
    ap.add_argument("--verbose", action="store_true", help="IPOPT's iteration log")
    ap.add_argument("--skip-daddy", action="store_true")
    ap.add_argument("--guess", choices=("interpolated", "rollout"), default="interpolated",
                    help="the transcription's initial states: linear in L from x0 to the "
                         "target (its usual guess), or daddy's cold guess rolled out")
    args = ap.parse_args()
    case = load_case(args.case)
    problem = problem_from_case(case)
    N = problem.N
    U0 = case.cold_guess(N)
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores; "
          f"case {case.name}, {N} stages")

    daddy_s = float("nan")
    if not args.skip_daddy:
        t = time.process_time()
        sol = solve(problem, U0, fuel_optimal=False, options=case_options(case, False))
        daddy_s = time.process_time() - t
        print(f"daddy (dyn, energy-optimal): {daddy_s:.1f} s CPU, {sol.final_mass_kg:.3f} kg, "
              f"cost {sol.cost:.8f}, violation {sol.max_violation:.1e}, converged "
              f"{sol.converged}", flush=True)

    t = time.process_time()
    solver, lbg, ubg, lbx, ubx = transcription(case, N, args.substeps, args.max_cpu,
                                               args.verbose)
    build_s = time.process_time() - t
    if args.guess == "rollout":
        X0 = problem.rollout(U0)
    else:   # each element, the time and the mass linear in L from x0 to the target
        X0 = case.x0 + np.linspace(0.0, 1.0, N + 1)[:, None] * (case.x_target - case.x0)
    t = time.process_time()
    res = solver(x0=np.concatenate([X0.ravel(), U0.ravel()]), lbg=lbg, ubg=ubg, lbx=lbx,
                 ubx=ubx)
    ipopt_s = time.process_time() - t
    stats = solver.stats()
    z = np.asarray(res["x"]).ravel()
    Xc = z[:7 * (N + 1)].reshape(N + 1, 7)
    Uc = z[7 * (N + 1):].reshape(N, 3)
    refly = problem.rollout(Uc)
    miss = problem.terminal_violation(refly[-1])
    mass_kg = float(case.units.mass_kg(Xc[-1, 6]))
    print(f"CasADi + IPOPT ({args.substeps} RK4 steps per stage): build {build_s:.1f} s, "
          f"solve {ipopt_s:.1f} s CPU, {stats['return_status']}, {stats['iter_count']} "
          f"iterations, {mass_kg:.3f} kg, cost {float(res['f']):.8f}; its controls re-flown "
          f"with RK78 miss the arrival by {miss:.1e}")
    print(f"ratio daddy / (build + IPOPT): {daddy_s / (build_s + ipopt_s):.2f}; daddy / IPOPT "
          f"alone: {daddy_s / ipopt_s:.2f}")


if __name__ == "__main__":
    main()
