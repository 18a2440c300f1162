"""Path constraints with the fuel homotopy from the default guess (issue 50, item 1): the
Clohessy-Wiltshire rendezvous of ``daddy_core.catalogue.rendezvous`` without and with its keep-out
sphere, solved by daddy with default options, beside an independent optimum of the same
discrete problem: scipy's SLSQP on the stage controls with analytic Jacobians (the RK4 stage
map of the linear dynamics as matrices, the propellant as slacks s_k >= |u_k|, the keep-out at
``--samples`` points per stage), started from its own free optimum.

    .venv/bin/python bench/bench_keep_out.py [--keep-out-km 1.5] [--z0-km 0.1] [--cap 300]

Prints CPU, propellant (sum |u_k| dt, km per 1/n), converged and the reason, the dense
keep-out margin, and the ratios the issue states: daddy's keep-out CPU over its free CPU, and
its propellant over the oracle's.
"""
from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.optimize import minimize

from daddy_core.catalogue.rendezvous import A_MAX, cw_rendezvous
from daddy_core.solver import SolverOptions, solve


def _stage_matrices(h: float, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """(P, Q): ``steps`` RK4 steps of h / steps of the CW equations under a constant control,
    x+ = P x + Q u (the RK4 step of a linear system is the degree-4 Taylor polynomial of its
    matrix exponential)."""
    A = np.zeros((9, 9))
    A[:3, 3:6] = np.eye(3)
    A[3, 0], A[3, 4], A[4, 3], A[5, 2] = 3.0, 2.0, -2.0, -1.0
    A[3:6, 6:9] = np.eye(3)
    M = (h / steps) * A
    S = np.linalg.matrix_power(np.eye(9) + M + M @ M / 2 + M @ M @ M / 6 + M @ M @ M @ M / 24,
                               steps)
    return S[:6, :6], S[:6, 6:]


def oracle(problem, samples: int) -> tuple[float, float, np.ndarray]:
    """SLSQP's propellant optimum of ``problem`` with and without its keep-out (free first,
    then the keep-out from the free optimum): (free propellant, kept propellant, kept U)."""
    N, dt = problem.N, float(problem.stage_dt[0])
    P, Q = _stage_matrices(dt, 4)
    subs = [_stage_matrices(dt * j / samples, 1) for j in range(1, samples + 1)]
    c, D = [problem.x0], [np.zeros((6, 3 * N))]          # x_k = c_k + D_k u
    for k in range(N):
        Dk = P @ D[-1]
        Dk[:, 3 * k:3 * k + 3] += Q
        c.append(P @ c[-1])
        D.append(Dk)
    cs, Ds = [], []                                      # sample positions r = cs + Ds u
    for k in range(N):
        for Pj, Qj in subs:
            d = Pj @ D[k]
            d[:, 3 * k:3 * k + 3] += Qj
            cs.append((Pj @ c[k])[:3])
            Ds.append(d[:3])
    cs, Ds = np.array(cs), np.array(Ds)
    n, eps, R = 4 * N, 1e-9, 1.5
    Aeq = np.hstack([D[-1], np.zeros((6, N))])
    beq = problem.x_target - c[-1]

    def fuel(z):
        return float(np.sum(z[3 * N:]) * dt)

    def gfuel(z):
        g = np.zeros(n)
        g[3 * N:] = dt
        return g

    def ineq(z, keep):
        u, s = z[:3 * N].reshape(N, 3), z[3 * N:]
        rows = [s - (np.sqrt(np.sum(u * u, 1) + eps ** 2) - eps), A_MAX - s]
        if keep:
            r = cs + Ds @ z[:3 * N]
            rows.append(np.sum(r * r, 1) - R * R)
        return np.concatenate(rows)

    def jineq(z, keep):
        u = z[:3 * N].reshape(N, 3)
        J1 = np.zeros((N, n))
        norm = np.sqrt(np.sum(u * u, 1) + eps ** 2)
        for k in range(N):
            J1[k, 3 * k:3 * k + 3] = -u[k] / norm[k]
            J1[k, 3 * N + k] = 1.0
        J2 = np.zeros((N, n))
        J2[np.arange(N), 3 * N + np.arange(N)] = -1.0
        rows = [J1, J2]
        if keep:
            r = cs + Ds @ z[:3 * N]
            rows.append(np.hstack([2.0 * np.einsum("pi,pij->pj", r, Ds), np.zeros((len(r), N))]))
        return np.vstack(rows)

    def run(u0, keep):
        z0 = np.concatenate([u0.ravel(), np.linalg.norm(u0, axis=1)])
        r = minimize(fuel, z0, jac=gfuel, method="SLSQP", options=dict(maxiter=3000, ftol=1e-14),
                     constraints=[dict(type="eq", fun=lambda z: Aeq @ z - beq,
                                       jac=lambda z: Aeq),
                                  dict(type="ineq", fun=lambda z: ineq(z, keep),
                                       jac=lambda z: jineq(z, keep))])
        if not r.success:
            raise RuntimeError(f"the SLSQP oracle failed: {r.message}")
        return r.x[:3 * N].reshape(N, 3)

    free = run(np.full((N, 3), 0.01), False)
    kept = run(free, True)
    total = lambda U: float(np.sum(np.linalg.norm(U, axis=1)) * dt)  # noqa: E731
    return total(free), total(kept), kept


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
        fuel = float(np.sum(np.linalg.norm(sol.U, axis=1)) * problem.stage_dt[0])
        rows[label] = (cpu, fuel)
        margin = "" if sol.min_path_margin is None else f", margin {sol.min_path_margin:+.2e} km"
        print(f"daddy {label:9s} CPU {cpu:7.2f} s, propellant {fuel:.8f}, converged "
              f"{sol.converged}, exact {sol.exact_fuel}, max violation {sol.max_violation:.1e}"
              f"{margin}: {sol.reason[:160]}", flush=True)
    t0 = time.process_time()
    f_free, f_kept, _ = oracle(cw_rendezvous(keep_out_km=args.keep_out_km, z0_km=args.z0_km),
                               args.samples)
    print(f"SLSQP oracle ({args.samples} keep-out samples per stage, {time.process_time() - t0:.1f} s"
          f" CPU): free {f_free:.8f}, keep-out {f_kept:.8f}")
    print(f"ratios: keep-out CPU / free CPU {rows['keep-out'][0] / rows['free'][0]:.1f} "
          f"(target <= 10); propellant / oracle: free {rows['free'][1] / f_free - 1:+.2e}, "
          f"keep-out {rows['keep-out'][1] / f_kept - 1:+.2e} (target |.| <= 1e-4)")


if __name__ == "__main__":
    main()
