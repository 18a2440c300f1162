"""The paper's optimal-control problems (eq. 14, 17-21) built from a catalogue ``Case``: its
dynamics, the pseudo-Huber stage cost of the fuel homotopy, the terminal cost, the thrust and
dry-mass bounds, and the normalisation units."""
from __future__ import annotations

import numpy as np

from ..da import functions as dm
from ..errors import DaddyError
from ..fuel import pseudo_huber_stage_cost
from ..problem import Problem, flow_step
from .cases import Case


def low_thrust_costs(n_pos: int, u_max: float, dt_avg: float, stage_gain: float,
                     terminal_gain: float):
    """Paper/reference-code costs for low-thrust transfers.

    Stage cost (eq. 14 with the reference's scaling): ``fuel.pseudo_huber_stage_cost`` with
    w = u dt / (dt_avg u_max), h = 0 energy-optimal, delta -> 0 fuel-optimal.
    Terminal cost: terminal_gain / 2 * |x[:n_pos] - x_t[:n_pos]|^2.
    """
    stage_cost = pseudo_huber_stage_cost(u_max, dt_avg, stage_gain)

    def terminal_cost(x, xt):
        e = x[:n_pos] - xt[:n_pos]
        return dm.dot(e, e) * (0.5 * terminal_gain)

    return stage_cost, terminal_cost


def problem_from_case(case: Case, integrator: str = "rk78", integrator_tol: float | None = None,
                      stages: int | None = None, max_thrust_n: float | None = None) -> Problem:
    """Build the paper's problem for a catalogue ``Case`` (costs, constraints, units).

    ``max_thrust_n`` overrides the spacecraft's thrust bound (e.g. a derated bound that leaves
    guidance a control margin); the cost scaling keeps the spacecraft's rating.
    """
    s = case.problem
    N = case.stages if stages is None else int(stages)
    if N < 1:
        raise DaddyError(f"stages must be >= 1, got {N}")
    dt = np.full(N, case.tof / N)
    if case.system == "double_integrator":
        from ..dynamics.models import double_integrator_step as step

        def stage_cost(x, u, d, hom=(0.0, 1.0)):
            return u[0] * u[0] + u[1] * u[1] + u[2] * u[2]

        def terminal_cost(x, xt):
            e = x[:3] - xt[:3]
            return dm.dot(e, e)

        return Problem(name=case.name, x0=case.x0, x_target=case.x_target, stage_dt=dt, step=step,
                       stage_cost=stage_cost, terminal_cost=terminal_cost,
                       g_teq=lambda x, xt: x[:3] - xt[:3], units=case.units)

    sc = case.spacecraft
    units = case.units
    u_max = float(units.thrust(sc.max_thrust_n))
    u_bound = u_max if max_thrust_n is None else float(units.thrust(max_thrust_n))
    if not u_bound > 0:
        raise DaddyError(f"max_thrust_n must be positive, got {max_thrust_n!r}")
    m_dry = sc.dry_mass_kg / units.mu_kg
    n_pos = 5 if case.system == "earth_equinoctial" else 6
    stage_cost, terminal_cost = low_thrust_costs(
        n_pos, u_max, case.tof / N, s.get("stage_cost_gain", 1e-2), s.get("terminal_cost_gain", 1e4))
    rhs = case.rhs()
    tol = integrator_tol if integrator_tol is not None else s.get("integrator_tol", 1e-13)

    def g_ineq(x, u, d):
        # thrust bound |u|^2 / u_max^2 - 1 <= 0 and dry mass m_dry - m <= 0 (paper eq. 18)
        return dm.stack([(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]) * (1.0 / u_bound ** 2) - 1.0,
                         m_dry - x[6]])

    return Problem(name=case.name, x0=case.x0, x_target=case.x_target, stage_dt=dt,
                   step=flow_step(rhs, integrator, tol), stage_cost=stage_cost,
                   terminal_cost=terminal_cost, g_ineq=g_ineq,
                   g_teq=lambda x, xt: x[:n_pos] - xt[:n_pos], units=units, spacecraft=sc,
                   u_max=u_bound, mass_index=6, rhs=rhs)
