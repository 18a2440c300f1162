"""A small problem written as a user writes one, and the three ways of making it infeasible
that issue 50 names: shared by its test (``test_solver.py``) and ``bench/bench_infeasible.py``.

From rest at the origin to rest at x = 1 in 2 s (20 RK4 stages of 0.1 s), |u| <= 10,
energy cost (a 3-D double integrator, normalised units). Nothing in the solver was tuned on it.
"""
from __future__ import annotations

import numpy as np

from ..da import functions as dm
from ..dynamics import Dynamics
from ..problem import Problem, flow_step


def _rhs(t, x, u):
    return dm.stack([x[3], x[4], x[5], u[0], u[1], u[2]])


def double_integrator(**changes) -> Problem:
    """The feasible problem of the module docstring, with ``Problem`` fields replaced."""
    d = dict(name="di3", nu=3, x0=np.zeros(6), x_target=np.array([1.0, 0, 0, 0, 0, 0]),
             stage_dt=np.full(20, 0.1), step=flow_step(Dynamics(_rhs), "rk4", rk4_steps=1),
             rhs=Dynamics(_rhs), stage_cost=lambda x, u, dt, hom: dm.dot(u, u) * dt,
             terminal_cost=lambda x, xt: x[0] * 0.0,
             g_ineq=lambda x, u, dt: dm.stack([dm.dot(u, u) - 100.0]),
             g_teq=lambda x, xt: x - xt, u_max=10.0)
    return Problem(**{**d, **changes})


# kind -> (the changes that make the problem infeasible, its least terminal miss max |g_teq|
# where known in closed form: the keep-out's radius; half the distance between x = 1 and 2)
INFEASIBLE = {
    "thrust too weak for the time": (dict(
        g_ineq=lambda x, u, dt: dm.stack([dm.dot(u, u) - 0.25]), u_max=0.5), None),
    "a keep-out containing the target": (dict(
        g_path=lambda x, u: dm.stack([0.09 - ((x[0] - 1) ** 2 + x[1] ** 2 + x[2] ** 2)])), 0.3),
    "contradictory terminal rows": (dict(
        g_teq=lambda x, xt: dm.concatenate([x - xt, dm.stack([x[0] - 2.0])])), 0.5),
}
