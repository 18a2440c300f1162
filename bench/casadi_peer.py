"""The peer of the robustness harness: the same catalogue case as a direct transcription
(CasADi + IPOPT), solved from the same initial guess as daddy (issue 18, item 4). Benchmark-
only: CasADi is never a dependency of the project (requirements/optional.txt).

The transcription is written independently of daddy's code: multiple shooting with the
controls constant on each stage (daddy's stages, in normalised units), the Cartesian dynamics
written again here in CasADi (Sun-centred two-body, Earth-Moon CR3BP with mass; the double
integrator's explicit-Euler stages exactly), ``substeps`` fixed RK4 steps per stage; the thrust
bound |u| <= u_max and the dry mass as inequalities, the arrival's position and velocity as
equalities. Objectives: energy-optimal, daddy's stage cost at h = 0 (gain / 2 |u dt / (dt_avg
u_max)|^2 summed over the stages); fuel-optimal, the true propellant -- the final mass is
maximised with the thrust written u_max s d, a throttle 0 <= s <= 1 and a unit direction |d| =
1 (as the reference solutions of ../shared/reference were computed), which keeps the NLP smooth
where |u| is not at zero thrust (a slack s >= |u| with |u|^2 <= s^2 let coasting stages keep
|u| ~ 1e-4 u_max under IPOPT's tolerance: re-flown misses of 5e-5). The pseudo-Huber homotopy is
daddy's way to the same optimum, not the transcription's. IPOPT: exact Hessian, MUMPS, tol 1e-8, a CPU cap per solve.

The initial guess is daddy's: its controls, the states of their rollout (daddy's own flows), and
for the fuel problem s = |u| / u_max, d = u / |u| (x-axis where u = 0). The answer is judged as daddy's is: the controls re-flown with
daddy's stage flows (RK78 at the case's tolerance), the arrival's miss and the final mass of
that re-flight; the RK4 transcription itself agrees with it only to its discretisation error,
so the miss is reported, and a peer solve counts as feasible at a miss <= ``PEER_MISS``.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from daddy_core.problem import max_violation

# a peer solve's re-flown arrival miss (normalised position / velocity) that counts as feasible:
# the transcription's RK4 stages carry a discretisation error daddy's adaptive RK78 does not
PEER_MISS = 1e-6
# RK4 steps per stage (the reference solutions of ../shared/reference: 20 for Earth-Mars, 8 for
# the Earth-Moon cases)
SUBSTEPS = {"sun_two_body": 20, "earth_moon_cr3bp": 8, "double_integrator": 1}


@dataclass
class PeerResult:
    ok_status: bool      # IPOPT reported Solve_Succeeded / Solved_To_Acceptable_Level
    status: str
    iterations: int
    cpu_s: float         # CasADi build + IPOPT
    value: float         # re-flown final mass [kg] (double integrator: its cost)
    miss: float          # re-flown arrival miss (max abs of the terminal equalities)
    violation: float     # re-flown max violation of the stage inequalities


def _rhs(case, ca):
    """The case's continuous dynamics dx/dt (x 7, u 3) as a CasADi function; the mass flow
    |u| / c is smoothed at zero thrust by 1e-24 under the root (the fuel problem's thrust
    u_max s d has |u| = u_max s exactly wherever s > 0)."""
    x, u = ca.SX.sym("x", 7), ca.SX.sym("u", 3)
    c = case.spacecraft.exhaust_speed(case.units)
    r, v, m = x[:3], x[3:6], x[6]
    if case.system == "sun_two_body":
        acc = -case.units.gm * r / ca.norm_2(r) ** 3
    elif case.system == "earth_moon_cr3bp":
        mu = case.units.gm
        r1 = ca.vertcat(r[0] + mu, r[1], r[2])
        r2 = ca.vertcat(r[0] - 1 + mu, r[1], r[2])
        acc = (ca.vertcat(r[0] + 2 * v[1], r[1] - 2 * v[0], 0)
               - (1 - mu) * r1 / ca.norm_2(r1) ** 3 - mu * r2 / ca.norm_2(r2) ** 3)
    else:
        raise ValueError(f"no CasADi transcription for system {case.system!r}")
    flow = ca.sqrt(ca.sumsqr(u) + 1e-24) / c
    return ca.Function("rhs", [x, u], [ca.vertcat(v, acc + u / m, -flow)])


def _stage_flow(case, problem, substeps: int, ca):
    """x_{k+1} = F(x_k, u_k, dt_k): RK4 over the stage (the double integrator: Euler)."""
    x, u, dt = ca.SX.sym("x", problem.nx), ca.SX.sym("u", 3), ca.SX.sym("dt")
    if case.system == "double_integrator":
        y = ca.vertcat(x[:3] + x[3:6] * dt, x[3:6] + u * dt)
        return ca.Function("F", [x, u, dt], [y])
    f = _rhs(case, ca)
    h = dt / substeps
    y = x
    for _ in range(substeps):
        k1 = f(y, u)
        k2 = f(y + h / 2 * k1, u)
        k3 = f(y + h / 2 * k2, u)
        k4 = f(y + h * k3, u)
        y = y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return ca.Function("F", [x, u, dt], [y])


def solve_peer(case, problem, U0: np.ndarray, fuel: bool, cap_s: float,
               substeps: int | None = None) -> PeerResult:
    """Build and solve the transcription from daddy's guess U0 (N, 3); see the module doc."""
    import casadi as ca
    t0 = time.process_time()
    N, nx = problem.N, problem.nx
    di = case.system == "double_integrator"
    F = _stage_flow(case, problem, substeps or SUBSTEPS[case.system], ca).map(N)
    dt = problem.stage_dt
    # W: the controls (energy, double integrator) or the thrust directions (fuel); S: the
    # throttles (fuel; fixed at 0 otherwise)
    X, W, S = ca.MX.sym("X", nx, N + 1), ca.MX.sym("W", 3, N), ca.MX.sym("S", 1, N)
    u_max = problem.u_max or 1.0
    U = u_max * W * ca.repmat(S, 3, 1) if fuel else W
    defects = F(X[:, :-1], U, dt[None, :]) - X[:, 1:]
    xt = problem.x_target
    n_t = 3 if di else 6
    g = [ca.vec(defects), X[:n_t, -1] - xt[:n_t]]
    lbg, ubg = [np.zeros(nx * N + n_t)], [np.zeros(nx * N + n_t)]
    if di:
        f = ca.sumsqr(U)            # the catalogue's l = u.u per stage (eq. 17)
    else:
        m_dry = case.spacecraft.dry_mass_kg / case.units.mu_kg
        g.append((m_dry - X[6, 1:]).T)
        lbg.append(np.full(N, -np.inf))
        ubg.append(np.zeros(N))
        if fuel:    # |d| = 1; the thrust bound is the throttle's, 0 <= s <= 1
            f = -X[6, -1]
            g.append(ca.sum1(W ** 2).T - 1)
            lbg.append(np.zeros(N))
            ubg.append(np.zeros(N))
        else:
            g.append((ca.sum1(U ** 2) / u_max ** 2 - 1).T)
            lbg.append(np.full(N, -np.inf))
            ubg.append(np.zeros(N))
            gain = case.problem.get("stage_cost_gain", 1e-2)
            w = dt / (case.tof / N * u_max)
            f = 0.5 * gain * ca.sum2(ca.sum1(U ** 2) * (w ** 2)[None, :])
    solver = ca.nlpsol("peer", "ipopt", {
        "x": ca.vertcat(ca.vec(X), ca.vec(W), ca.vec(S)), "f": f, "g": ca.vertcat(*g)}, {
        "ipopt.tol": 1e-8, "ipopt.print_level": 0, "ipopt.sb": "yes", "print_time": False,
        "ipopt.linear_solver": "mumps", "ipopt.max_cpu_time": float(cap_s),
        "ipopt.max_iter": 3000})
    iw = nx * (N + 1)                       # where W starts in the decision vector
    lbx, ubx = np.full(iw + 4 * N, -np.inf), np.full(iw + 4 * N, np.inf)
    lbx[:nx], ubx[:nx] = problem.x0, problem.x0
    if fuel:
        s0 = np.linalg.norm(U0, axis=1)
        d0 = np.where(s0[:, None] > 0, U0 / np.where(s0 > 0, s0, 1.0)[:, None], [1.0, 0.0, 0.0])
        w0, s0 = d0, np.minimum(s0 / u_max, 1.0)
        lbx[iw + 3 * N:], ubx[iw + 3 * N:] = 0.0, 1.0
    else:
        w0, s0 = U0, np.zeros(N)
        lbx[iw + 3 * N:] = ubx[iw + 3 * N:] = 0.0
    X0 = problem.rollout(U0)
    res = solver(x0=np.concatenate([X0.ravel(), w0.ravel(), s0]),   # vec(): column-major
                 lbx=lbx, ubx=ubx, lbg=np.concatenate(lbg), ubg=np.concatenate(ubg))
    stats = solver.stats()
    cpu = time.process_time() - t0
    zs = np.asarray(res["x"]).ravel()
    Uc = zs[iw:iw + 3 * N].reshape(N, 3)
    if fuel:
        Uc = u_max * Uc * zs[iw + 3 * N:, None]
    try:
        Xr = problem.rollout(Uc)
        g_k, n_ineq, g_t, n_tineq = problem.constraint_values(Xr, Uc)
        miss, viol = max_violation(g_t, n_tineq), max_violation(g_k, n_ineq)
        value = float(np.sum(Uc ** 2)) if di else float(case.units.mass_kg(Xr[-1, 6]))
    except Exception:  # noqa: BLE001  a re-flight that fails is a failed peer solve
        miss, viol, value = float("inf"), float("inf"), float("nan")
    status = str(stats["return_status"])
    return PeerResult(status in ("Solve_Succeeded", "Solved_To_Acceptable_Level"), status,
                      int(stats["iter_count"]), cpu, value, miss, viol)


def _kepler_target(xt, dt, gm, ca):
    """The target (r, v) (6,) on its Keplerian orbit dt after xt, with the eccentric-anomaly
    difference E an NLP variable: returns (state, Kepler's equation residual). Written here
    again, independently of ``daddy_core.dynamics.kepler``."""
    r0, v0 = np.asarray(xt[:3], float), np.asarray(xt[3:6], float)
    rn = float(np.linalg.norm(r0))
    a = 1.0 / (2.0 / rn - float(v0 @ v0) / gm)
    sigma = float(r0 @ v0) / np.sqrt(gm)
    E = ca.MX.sym("E")
    kepler = (E + sigma / np.sqrt(a) * (1 - ca.cos(E)) - (1 - rn / a) * ca.sin(E)
              - dt * np.sqrt(gm / a ** 3))
    r = a + (rn - a) * ca.cos(E) + sigma * np.sqrt(a) * ca.sin(E)
    f = 1 - a / rn * (1 - ca.cos(E))
    g = a * sigma / np.sqrt(gm) * (1 - ca.cos(E)) + rn * np.sqrt(a / gm) * ca.sin(E)
    fd = -np.sqrt(gm * a) / (r * rn) * ca.sin(E)
    gd = 1 - a / r * (1 - ca.cos(E))
    return E, ca.vertcat(f * r0 + g * v0, fd * r0 + gd * v0), kepler


def solve_peer_free_tof(case, problem, U0: np.ndarray, window, cap_s: float,
                        substeps: int | None = None):
    """The fuel-optimal transcription of a Sun-centred case with the time of flight T free in
    ``window`` (normalised) and the target moving on its Keplerian orbit to T: equal stages
    T / N, the same throttle-direction form as ``solve_peer``. Returns (final mass [kg] of the
    transcription, T [normalised], IPOPT status, iterations, CPU s, the controls (N, 3))."""
    import casadi as ca
    t0 = time.process_time()
    N, nx = problem.N, problem.nx
    F = _stage_flow(case, problem, substeps or SUBSTEPS[case.system], ca).map(N)
    X, W, S = ca.MX.sym("X", nx, N + 1), ca.MX.sym("W", 3, N), ca.MX.sym("S", 1, N)
    T = ca.MX.sym("T")
    u_max = problem.u_max
    U = u_max * W * ca.repmat(S, 3, 1)
    defects = F(X[:, :-1], U, ca.repmat(T / N, 1, N)) - X[:, 1:]
    E, target, kepler = _kepler_target(problem.x_target, T - case.tof, case.units.gm, ca)
    m_dry = case.spacecraft.dry_mass_kg / case.units.mu_kg
    g = [ca.vec(defects), X[:6, -1] - target, kepler, (m_dry - X[6, 1:]).T,
         ca.sum1(W ** 2).T - 1]
    zeros = np.zeros(nx * N + 7)
    lbg = np.concatenate([zeros, np.full(N, -np.inf), np.zeros(N)])
    ubg = np.zeros(nx * N + 7 + 2 * N)
    solver = ca.nlpsol("peer_free", "ipopt", {
        "x": ca.vertcat(ca.vec(X), ca.vec(W), ca.vec(S), T, E), "f": -X[6, -1],
        "g": ca.vertcat(*g)}, {
        "ipopt.tol": 1e-8, "ipopt.print_level": 0, "ipopt.sb": "yes", "print_time": False,
        "ipopt.linear_solver": "mumps", "ipopt.max_cpu_time": float(cap_s),
        "ipopt.max_iter": 3000})
    iw = nx * (N + 1)
    n = iw + 4 * N + 2
    lbx, ubx = np.full(n, -np.inf), np.full(n, np.inf)
    lbx[:nx], ubx[:nx] = problem.x0, problem.x0
    lbx[iw + 3 * N:iw + 4 * N], ubx[iw + 3 * N:iw + 4 * N] = 0.0, 1.0
    lbx[n - 2], ubx[n - 2] = window
    s0 = np.linalg.norm(U0, axis=1)
    d0 = np.where(s0[:, None] > 0, U0 / np.where(s0 > 0, s0, 1.0)[:, None], [1.0, 0.0, 0.0])
    X0 = problem.rollout(U0)
    res = solver(x0=np.concatenate([X0.ravel(), d0.ravel(), np.minimum(s0 / u_max, 1.0),
                                    [case.tof, 0.0]]),
                 lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
    stats = solver.stats()
    zs = np.asarray(res["x"]).ravel()
    Uc = u_max * zs[iw:iw + 3 * N].reshape(N, 3) * zs[iw + 3 * N:iw + 4 * N, None]
    mass = float(case.units.mass_kg(zs[iw - 1]))
    return (mass, float(zs[n - 2]), str(stats["return_status"]), int(stats["iter_count"]),
            time.process_time() - t0, Uc)
