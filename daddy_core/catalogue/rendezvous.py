"""A Clohessy-Wiltshire rendezvous written as a user writes a problem of their own (its right-hand
side declared a thrust with ``thrust_dynamics``, the paper's homotopy cost, a keep-out sphere
as ``g_path``): the case of issue 50's keep-out item, shared by its test and
``bench/bench_keep_out.py``.

Units: km and 1/n (n the target's mean motion: one orbit is 2 pi); x radial, y along-track,
z cross-track. From 3 km behind the target (``z0_km`` out of plane) to 3 km ahead, at rest
relative to it at both ends, in one orbit, thrust acceleration at most 0.5 km/(1/n)^2. Its free
fuel optimum (0.81892 km/(1/n) with z0 = 0.1 km) passes 1.26 km from the target.
"""
from __future__ import annotations

import numpy as np

from ..da import functions as dm
from ..dynamics.models import thrust_dynamics
from ..fuel import pseudo_huber_stage_cost
from ..problem import Problem, flow_step

A_MAX = 0.5   # thrust acceleration bound [km / (1/n)^2]


def propellant(U, stage_dt) -> float:
    """sum_k |u_k| dt_k of controls U (N, 3) [km/(1/n)]: the rendezvous's propellant measure."""
    return float(np.sum(np.linalg.norm(np.asarray(U, float), axis=1) * np.asarray(stage_dt)))


def cw_rhs(t, x, u):
    """Clohessy-Wiltshire equations with n = 1: x = [r (3), v (3)], u = thrust acceleration."""
    return dm.stack([x[3], x[4], x[5], 3.0 * x[0] + 2.0 * x[4] + u[0], -2.0 * x[3] + u[1],
                     -x[2] + u[2]])


def cw_rendezvous(keep_out_km: float | None = None, z0_km: float = 0.1,
                  stages: int = 40) -> Problem:
    """The rendezvous (module docstring), fuel-optimal with ``solve(..., fuel_optimal=True)``,
    with a keep-out sphere of radius ``keep_out_km`` around the target held along the whole
    trajectory (None: none). RK4 stages of 4 steps."""
    dyn = thrust_dynamics(cw_rhs, scalar_components=True)
    dt = 2.0 * np.pi / stages

    def keep_out(x, u):
        return dm.stack([keep_out_km - dm.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2])])

    return Problem(
        name="cw_rendezvous", nu=3, x0=np.array([0.0, -3.0, z0_km, 0.0, 0.0, 0.0]),
        x_target=np.array([0.0, 3.0, 0.0, 0.0, 0.0, 0.0]), stage_dt=np.full(stages, dt),
        step=flow_step(dyn, "rk4", rk4_steps=4), rhs=dyn,
        stage_cost=pseudo_huber_stage_cost(u_max=A_MAX, dt_ref=dt),
        terminal_cost=lambda x, xt: x[0] * 0.0,
        g_ineq=lambda x, u, dt: dm.stack([(u[0] * u[0] + u[1] * u[1] + u[2] * u[2])
                                          * (1.0 / A_MAX ** 2) - 1.0]),
        g_teq=lambda x, xt: x - xt, u_max=A_MAX,
        g_path=None if keep_out_km is None else keep_out,
        labels={"g_ineq": ("thrust bound",), "g_path": ("keep-out",)})
