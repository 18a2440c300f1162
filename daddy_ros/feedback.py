"""Flying the plan's feedback laws between re-plans (issue 47), ROS-free: where the re-plan
policy (``self_trigger``) calls for a stage-boundary re-plan and the estimate lies inside the
laws' validity, the stage's thrust comes from the plan's law -- a polynomial evaluation of
microseconds instead of a solve. Drift and arrival re-plans are unchanged.

The laws are ``daddy_core.policy.tracking_policy``'s: for a deviation from the plan, the
thrust of the remaining stages that still meets the plan's terminal conditions with the least
correction. Unlike the optimal laws of ``feedback_policy`` they need no optimum: a warm
re-plan, stopped by its budget or kept on a lower thrust rung (an exact warm start's interior
throttle), is not one, and its optimal laws jump away from it at once (constant terms of 1e-2
to 40 measured on a halo flight, design notes), while its tracking laws have none. A
correction may use the thrust the plans hold back (``thrust_margin``); it is clipped to the
spacecraft's rating.

Validity: the estimate, taken back to the stage's start with the stage's thrust, lies within
``feedback_position_m`` / ``feedback_velocity_m_s`` of the plan's state there (the laws are
Taylor series about the plan), and the stage has a law (the last stages, which cannot move
every terminal row, have none); a plan whose laws cannot be built is re-planned as before. The
laws of a plan are built once (~25 ms for the halo's 110 stages): by the node's worker after
each new plan (``prepare``), else at the first stage boundary that asks. Cartesian scenarios only (an Earth-centred plan's
thrust is in RTN on equinoctial stages).
"""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass

import numpy as np

from daddy_core.errors import DaddyError
from daddy_core.policy import Policy, tracking_policy

from .plan import TIME_TOLERANCE_S, Plan
from .self_trigger import propagate


@dataclass(frozen=True)
class Served:
    """A stage whose thrust a law set: the stage, the estimate's distance from the plan at the
    stage's start [m, m/s], the law's thrust [N] and its evaluation time [s]."""
    stage: int
    position_m: float
    velocity_m_s: float
    thrust_n: np.ndarray
    evaluation_s: float


class FeedbackLaws:
    """The laws of the plans a planner makes, served at stage boundaries (module docstring)."""

    def __init__(self, planner, order: int, position_m: float, velocity_m_s: float):
        self.planner, self.order = planner, int(order)
        self.position_m, self.velocity_m_s = position_m, velocity_m_s
        self._built: tuple | None = None   # (the plan's solution, its laws or None)
        self._lock = threading.Lock()

    @classmethod
    def for_planner(cls, planner, settings) -> "FeedbackLaws | None":
        """From a ``TriggerConfig``: None when ``feedback_order`` is 0."""
        if not settings.feedback_order:
            return None
        return cls(planner, settings.feedback_order, settings.feedback_position_m,
                   settings.feedback_velocity_m_s)

    def prepare(self, plan: Plan | None) -> None:
        """Build the laws of ``plan`` (the one in force; earlier plans' are dropped)."""
        if plan is not None and not plan.thrust_rtn:
            self._policy(plan)

    def serve(self, plan: Plan, t_s: float, pos_m, vel_m_s, mass_kg: float) -> Served | None:
        """Fly the law of the stage holding t_s if the estimate is inside its validity: the
        stage's thrust set on the plan (``Plan.fly_law``); None when it is not (re-plan)."""
        if plan.thrust_rtn:
            return None
        k = plan.stage_index(t_s)
        policy = self._policy(plan)
        if k is None or policy is None or not policy.has_law[k]:
            return None
        case, units = self.planner.case, self.planner.units
        x = units.cartesian_normalised(np.concatenate([pos_m, vel_m_s, [mass_kg]]))
        back = t_s - float(plan.start_times_s[k])
        if back > TIME_TOLERANCE_S:   # the estimate taken back to the stage's start
            x = propagate(case, x, plan.thrust_n[k], -back)
        at = units.cartesian_si(x)
        dr = float(np.linalg.norm(at[:3] - plan.states_si[k, :3]))
        dv = float(np.linalg.norm(at[3:6] - plan.states_si[k, 3:6]))
        if dr > self.position_m or dv > self.velocity_m_s:
            return None
        t0 = time.perf_counter()
        thrust = np.asarray(units.thrust_n(policy.control(k, x)), float)
        spent = time.perf_counter() - t0
        if not np.all(np.isfinite(thrust)):
            return None
        norm, rating = float(np.linalg.norm(thrust)), case.spacecraft.max_thrust_n
        if norm > rating:
            thrust *= rating / norm
        plan.fly_law(k, thrust)
        return Served(k, dr, dv, thrust, spent)

    def _policy(self, plan: Plan) -> Policy | None:
        """The plan's laws, built at the first call (None: it has none). The solution itself is
        kept as the key: an id() would be reused by a later plan once this one is freed."""
        sol = plan.solution
        with self._lock:
            if self._built is not None and self._built[0] is sol:
                return self._built[1]
            self._built = (sol, self._build(plan))
            return self._built[1]

    def _build(self, plan: Plan) -> Policy | None:
        sol = plan.solution
        problem = self.planner.base_problem.with_x0(sol.X[0], sol.stage_dt, sol.t_start)
        try:
            return tracking_policy(problem, sol.X, sol.U, self.order)
        except (DaddyError, ValueError, ArithmeticError):
            return None

