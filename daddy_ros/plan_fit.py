"""Whether a plan fits a state estimate (issue 49, safety): the node commands thrust from a
plan only for an estimate near the plan's own predicted state at the estimate's stamp. ROS-free;
SI states in the scenario's frame, stamps in seconds on the caller's clock."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from daddy_core.catalogue import Case

from .plan import Plan
from .self_trigger import propagate


@dataclass(frozen=True)
class Fit:
    """The estimate against the plan's prediction: ``fits``; the position and velocity
    differences [m, m/s] (nan where the stamp is outside the plan's stages: nothing to check,
    and the plan commands zero thrust there)."""

    fits: bool
    position_m: float
    velocity_m_s: float

    def values(self, stamp_s: float) -> dict:
        """The PLAN_DOES_NOT_FIT diagnostic's values for the estimate of ``stamp_s``."""
        return {"request_id": f"fit-{stamp_s:.3f}",
                "deviation_position_m": f"{self.position_m:.3f}",
                "deviation_velocity_m_s": f"{self.velocity_m_s:.6f}"}


class PlanFit:
    """The test ``fit_position_m`` / ``fit_velocity_m_s`` of one scenario (0: no test)."""

    def __init__(self, case: Case, position_m: float, velocity_m_s: float):
        self.case, self.position_m, self.velocity_m_s = case, position_m, velocity_m_s

    def predicted(self, plan: Plan, t_s: float) -> np.ndarray | None:
        """(7,) the plan's state [m, m/s, kg] at t_s, flown from the start of the stage holding
        it with that stage's thrust; None outside the plan's stages."""
        k = plan.stage_index(t_s)
        if k is None:
            return None
        dt = t_s - float(plan.start_times_s[k])
        if dt <= 0.0:
            return plan.states_si[k]
        u = self.case.units
        x = propagate(self.case, u.cartesian_normalised(plan.states_si[k]), plan.thrust_n[k], dt)
        return u.cartesian_si(x)

    def check(self, plan: Plan, t_s: float, pos_m, vel_m_s) -> Fit:
        if not (self.position_m or self.velocity_m_s):
            return Fit(True, np.nan, np.nan)
        x = self.predicted(plan, t_s)
        if x is None:
            return Fit(True, np.nan, np.nan)
        dr = float(np.linalg.norm(np.asarray(pos_m, float) - x[:3]))
        dv = float(np.linalg.norm(np.asarray(vel_m_s, float) - x[3:6]))
        fits = ((not self.position_m or dr <= self.position_m)
                and (not self.velocity_m_s or dv <= self.velocity_m_s))
        return Fit(fits, dr, dv)
