"""An independent optimum of the Clohessy-Wiltshire rendezvous of ``rendezvous`` (a test oracle
and the bench's peer, no daddy solver code): the same discrete problem -- the RK4 stage map of
the linear dynamics as matrices, 4 steps per stage -- solved by scipy's SLSQP on the stage
controls with analytic Jacobians, the propellant as slacks s_k >= |u_k|, the keep-out at
``samples`` points per stage.
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import minimize

from .rendezvous import A_MAX, propellant


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


def slsqp_reference(problem, keep_out_km: float | None, samples: int = 8,
                    start: np.ndarray | None = None
                    ) -> tuple[float, float | None, np.ndarray | None]:
    """SLSQP's propellant optimum of the rendezvous ``problem`` (``cw_rendezvous``) without and
    with a keep-out sphere of ``keep_out_km`` held at ``samples`` points per stage (free
    first, then the keep-out from the free optimum, or from the controls ``start`` (N, 3) when
    given): (free propellant, kept propellant,
    kept U (N, 3); None, None without a keep-out); propellant: ``rendezvous.propellant``.
    Raises RuntimeError when SLSQP fails."""
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
    n, eps, R = 4 * N, 1e-9, keep_out_km
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
    if keep_out_km is None:
        return propellant(free, problem.stage_dt), None, None
    kept = run(free if start is None else np.asarray(start, float), True)
    return propellant(free, problem.stage_dt), propellant(kept, problem.stage_dt), kept
