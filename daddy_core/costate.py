"""Costate-controlled stages (issue 48, Pontryagin-Bellman DDP, Sidhoum & Oguri): a stage's
decision variables are the costates lambda at its start; inside it the state and costate are
integrated together and the thrust follows the minimum principle, so one stage spans hours to
days of changing thrust.

Fuel-optimal control of x = [r, v, m] with the cost J = int T / c dt (propellant, c = g0 Isp
normalised) and the Hamiltonian H = lambda^T f(x, T u_hat) + T / c. The standard primer-vector
law (Lawden; the paper's equations were lost in its text conversion, so this follows the
textbook form, e.g. Taheri & Junkins):

    u_hat = -lambda_v / |lambda_v|                       (the primer vector p = -lambda_v)
    S     = |lambda_v| c / m + lambda_m - 1              (switching function: S > 0 burns)
    T     = T_max (1 + tanh(S / rho)) / 2                (smoothed throttle, rho -> 0: bang-bang)
    lambda' = -dH/dx

The tanh throttle is the minimiser of H plus an entropy term in the throttle that does not
depend on x, so the costate equations are H's partial derivatives with the law held (the
envelope theorem). |lambda_v| is regularised as sqrt(|lambda_v|^2 + PRIMER_FLOOR^2), as the
models regularise the thrust norm.

``cr3bp_costate``: the Earth-Moon CR3BP with mass (``models.cr3bp``), its costate equations
written out (the gravity's Hessian and the Coriolis term) on scalar components, for floats and
DA alike; ``test/test_costate.py`` checks them against -dH/dx from the DA engine. Other models
need their own (the generic route, H differentiated by the DA engine inside a DA integration,
nests algebras: not built).
"""
from __future__ import annotations

import numpy as np

from .da import functions as dm
from .dynamics.rhs import Dynamics
from .errors import DaddyError
from .integrators import rk78
from .problem import FlowStep, Problem, StageStep

PRIMER_FLOOR = 1e-12


def switching(lv, lm, m, c: float):
    """The switching function S = |lambda_v| c / m + lambda_m - 1 (S > 0 burns)."""
    return lv * c / m + lm - 1.0


def primer_law(lvx, lvy, lvz, lm, m, c: float, u_max: float, rho: float):
    """(T, |lambda_v|): the smoothed throttle's thrust magnitude and the regularised primer
    magnitude for the costates lambda_v, lambda_m at mass m (module docstring); the thrust
    points along -lambda_v."""
    lv = dm.sqrt(lvx * lvx + lvy * lvy + lvz * lvz + PRIMER_FLOOR ** 2)
    return (dm.tanh(switching(lv, lm, m, c) * (1.0 / rho)) + 1.0) * (0.5 * u_max), lv


def cr3bp_costate(mu: float, exhaust_speed: float, u_max: float, rho: float) -> Dynamics:
    """The state-costate right-hand side z' = F(z) of the CR3BP with mass, z = [r (3), v (3),
    m, lambda_r (3), lambda_v (3), lambda_m] (14, *batch), normalised units, throttle sharpness
    ``rho`` (module docstring); the control argument is unused (the costates are the
    decisions)."""
    gm1, gm2 = 1.0 - mu, mu
    c = exhaust_speed

    def rhs(t, z, _u):
        px, py, pz, vx, vy, vz, m = z[0], z[1], z[2], z[3], z[4], z[5], z[6]
        lrx, lry, lrz, lvx, lvy, lvz, lm = z[7], z[8], z[9], z[10], z[11], z[12], z[13]
        d1, d2 = px + mu, px + (mu - 1.0)
        yz2 = py * py + pz * pz
        r1s, r2s = d1 * d1 + yz2, d2 * d2 + yz2
        k1 = r1s ** -1.5 * gm1                        # (1 - mu) / r1^3
        k2 = r2s ** -1.5 * gm2                        # mu / r2^3
        q1, q2 = k1 * 3.0 / r1s, k2 * 3.0 / r2s       # 3 (1 - mu) / r1^5, 3 mu / r2^5
        ksum = k1 + k2
        inv_m = 1.0 / m
        thrust, lv = primer_law(lvx, lvy, lvz, lm, m, c, u_max, rho)
        a = thrust * inv_m / lv                       # thrust acceleration per unit primer
        ax = vy * 2.0 + px - d1 * k1 - d2 * k2 - lvx * a
        ay = vx * -2.0 + py - py * ksum - lvy * a
        az = -pz * ksum - lvz * a
        # the gravity's Hessian (symmetric): d(a_grav)/dr
        gxx = 1.0 - ksum + q1 * d1 * d1 + q2 * d2 * d2
        gyy = 1.0 - ksum + (q1 + q2) * py * py
        gzz = -ksum + (q1 + q2) * pz * pz
        gxy = (q1 * d1 + q2 * d2) * py
        gxz = (q1 * d1 + q2 * d2) * pz
        gyz = (q1 + q2) * py * pz
        return dm.vector([
            vx, vy, vz, ax, ay, az, thrust * (-1.0 / c),
            -(gxx * lvx + gxy * lvy + gxz * lvz),
            -(gxy * lvx + gyy * lvy + gyz * lvz),
            -(gxz * lvx + gyz * lvy + gzz * lvz),
            -lrx + lvy * 2.0, -lry - lvx * 2.0, -lrz,
            -thrust * lv * inv_m * inv_m])
    return Dynamics(rhs, scalar_components=True)


def cr3bp_hamiltonian(mu: float, exhaust_speed: float, u_max: float, rho: float):
    """H(z) = lambda^T f(x, T u_hat) + T / c with the smoothed law held at z's costates: the
    function whose partial derivatives ``cr3bp_costate``'s costate rates are (for the tests)."""
    from .dynamics.models import cr3bp
    f = cr3bp(mu, exhaust_speed)
    c = exhaust_speed

    def hamiltonian(z, law_z):
        lvx, lvy, lvz, lm = law_z[10], law_z[11], law_z[12], law_z[13]
        thrust, lv = primer_law(lvx, lvy, lvz, lm, law_z[6], c, u_max, rho)
        u = [-lvx * thrust / lv, -lvy * thrust / lv, -lvz * thrust / lv]
        x = [z[i] for i in range(7)]
        dx = f.f(0.0, x, dm.vector(u + [thrust]))
        return sum(z[7 + i] * dx[i] for i in range(7)) + thrust / c
    return hamiltonian


def costate_scale(exhaust_speed: float, m0: float):
    """(7,) the costates' units: lambda = scale * sigma with sigma the stage's decision
    variables. lambda_r and lambda_v in m0 / c, lambda_m in 1, so that a unit change of any
    sigma moves the switching function S by O(1) (S = |lambda_v| c / m + lambda_m - 1): the
    trust region, a sphere in sigma, then bounds the costates' effects alike (the paper's
    scaling matrix, whose values were lost in its text)."""
    return np.r_[np.full(6, m0 / exhaust_speed), 1.0]


class CostateStep(StageStep):
    """The stage map of a costate-controlled stage: x_{k+1} = the state part of the
    state-costate flow from [x_k, lambda_k] over the stage, lambda_k = scale * sigma_k
    (``problem.StageStep`` protocol: x (7, B), sigma (7, B) as the control, floats or DA)."""

    def __init__(self, rhs: Dynamics, law: tuple, scale, tol: float = 1e-12,
                 derivative_tol: float = 1e-9):
        super().__init__(self.__call__, takes_t0=True)   # (its fn: the flow below)
        self.flow14 = FlowStep(rhs, "rk78", tol, 0, derivative_tol)
        self.law = law            # (c, u_max, rho) of ``primer_law``
        self.scale = np.asarray(scale, float)

    def costates(self, sigma):
        """lambda (7, *batch) of the decision variables sigma (7, *batch), floats or DA."""
        extra = len(sigma.shape) - 1
        return sigma * self.scale.reshape((7,) + (1,) * extra)

    def __call__(self, x, sigma, dt, t0=0.0):
        lam = self.costates(sigma)
        return self.flow14(dm.concatenate([x, lam]), lam, dt, t0)[:7]

    def flow(self, x, sigma, dt, t0=0.0):
        lam = self.costates(np.asarray(sigma, float))
        return np.asarray(self.flow14.flow(np.concatenate([x, lam]), lam, dt, t0))[:7]


def costate_problem(case, stages: int, rho: float):
    """The catalogue CR3BP ``case`` with ``stages`` costate-controlled stages of equal length
    at throttle sharpness ``rho``: controls sigma_k (7, ``costate_scale``), cost m_0 - m_N (the
    propellant, without the constant a relative stopping test would drown it in), terminal
    position and velocity on the target (``Problem.g_teq``)."""
    units = case.units
    if case.system != "earth_moon_cr3bp":
        raise DaddyError(f"costate stages are built for the Earth-Moon CR3BP, not "
                         f"{case.system!r}")
    c = case.spacecraft.exhaust_speed(units)
    u_max = float(units.thrust(case.spacecraft.max_thrust_n))
    x0 = np.asarray(case.cartesian_x0(), float)
    step = CostateStep(cr3bp_costate(units.gm, c, u_max, rho), (c, u_max, rho),
                       costate_scale(c, x0[6]))
    xt = np.r_[np.asarray(case.x_target, float)[:6], 0.0]
    return Problem(name=f"{case.name}_costate", nu=7, x0=x0, x_target=xt,
                   stage_dt=np.full(stages, case.tof / stages), step=step,
                   stage_cost=lambda x, lam, dt, hom=(0.0, 1.0): 0.0 * lam[0],
                   terminal_cost=lambda x, xt: (x0[6] - x[6]) + 0.0 * x[0],
                   g_teq=lambda x, xt: x[:6] - xt[:6], units=units,
                   spacecraft=case.spacecraft, mass_index=6)


def thrust_schedule(problem, sigma, stages: int, points: int = 8):
    """The thrust of a costate-controlled solution (controls ``sigma`` (N, 7) of ``problem``,
    ``costate_problem``'s) averaged over each of ``stages`` equal stages of the same time of
    flight: (stages, 3), normalised -- a warm start for a thrust-controlled solve of those
    stages (the polish to the exact bang-bang optimum). The law is sampled at ``points``
    Gauss-Legendre nodes per stage."""
    rhs = problem.step.flow14.rhs
    lam = problem.step.costates(np.asarray(sigma, float).T).T
    edges = np.r_[0.0, np.cumsum(problem.stage_dt)]
    fine = np.linspace(0.0, edges[-1], stages + 1)
    nodes, weights = np.polynomial.legendre.leggauss(points)
    U = np.zeros((stages, 3))
    x = np.asarray(problem.x0, float)
    z, k, t = np.r_[x, lam[0]], 0, 0.0
    for j in range(stages):
        a, b = fine[j], fine[j + 1]
        for s, w in zip(a + (nodes + 1) * (b - a) / 2, weights):
            while s > edges[k + 1]:                     # on to the costate stage holding s
                z = rk78(rhs, z, None, t, edges[k + 1] - t, tol=1e-12)
                k, t = k + 1, edges[k + 1]
                z = np.r_[z[:7], lam[k]]
            z, t = rk78(rhs, z, None, t, s - t, tol=1e-12) if s > t else z, s
            thrust, lv = primer_law(*z[10:14], z[6], *problem.step.law)
            U[j] += w / 2 * thrust * -z[10:13] / lv
    return U
