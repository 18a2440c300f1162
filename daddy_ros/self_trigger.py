"""When guidance re-plans by itself: the policy that produced the closed-loop Monte Carlo's
figures, owned by the node (nav2's controller server owns its progress and goal checkers the
same way). ROS-free and thread-safe; the node asks it on every accepted estimate, the
in-process Monte Carlo likewise.

A re-plan is due at an estimate (parameters: ``config.TriggerConfig``) when
- ``STAGE``: it is the first at or after a stage boundary of the transfer's nominal grid
  (every ``replan_every_stages``-th; the arrival phase has its own rule);
- ``ARRIVAL``: it lies in the last ``arrival_stages`` nominal stages and more than
  ``arrival_min_step`` of a stage remains: every estimate there re-plans, so the last
  open-loop interval -- where execution errors can no longer be corrected -- is as short as the
  estimates come;

the nominal grid is the scenario's own (``frames.grid_of``): equal stages of time, or of true
longitude for the Earth-centred scenarios, whose stages last longer as the orbit rises (and
vary around an eccentric orbit), so an estimate's place on them is its unwrapped longitude;
- ``DRIFT``: it has drifted from the prediction of the schedule in force by more than
  ``trigger_position_m`` or ``trigger_velocity_m_s``. The prediction is reset to the estimate
  each re-plan starts from, then propagated with the plan's thrust (the dynamics without
  errors, RK78), so the drift measures navigation and execution errors, not the plan.

The node withholds the thrust command of an estimate that triggers a re-plan until the re-plan
has finished (then from the new plan): the command for an estimate reflects what that estimate
showed, and a simulated loop can wait for it (``demo.RosLink``).
"""
from __future__ import annotations

import enum
import threading

import numpy as np

from daddy_core.catalogue import Case
from daddy_core.integrators import rk78

from .config import TriggerConfig
from .frames import TIME_EPS_S, CartesianGrid, LongitudeGrid
from .plan import Plan



class Reason(str, enum.Enum):
    STAGE = "stage"
    ARRIVAL = "arrival"
    DRIFT = "drift"

    __str__ = str.__str__


def propagate(case: Case, x: np.ndarray, thrust_n, dt_s: float) -> np.ndarray:
    """The dynamics without errors: the normalised Cartesian state x = [r, v, m] after dt_s
    under thrust_n [N] (in the scenario's frame; Earth-centred scenarios: in RTN)."""
    u = case.units
    return rk78(case.cartesian_rhs(), x, u.thrust(np.asarray(thrust_n, float)), 0.0,
                float(u.time(dt_s)), tol=1e-12)


class ReplanTrigger:
    """The policy for one transfer (module docstring).

    Args:
        case: the scenario (its dynamics and units).
        settings: the policy's parameters.
        grid: where an estimate lies on the scenario's stages (time [s] or true longitude [rad]).
        stage_length: the nominal stage length in the grid's variable (the transfer's N stages
            of equal length).
        stages: N.
    """

    def __init__(self, case: Case, settings: TriggerConfig, grid: CartesianGrid | LongitudeGrid,
                 stage_length: float, stages: int):
        self.case, self.settings, self.grid = case, settings, grid
        self.stage_length, self.stages = stage_length, stages
        self._lock = threading.Lock()
        self._x = None        # predicted normalised state at time self._t
        self._t = None
        self._last = None     # grid position of the last estimate observed

    @classmethod
    def for_planner(cls, planner, settings: TriggerConfig) -> "ReplanTrigger | None":
        """The policy for a ``GuidancePlanner``'s transfer: its scenario and nominal stage grid
        (the base problem's N stages of equal length); None with ``self_replan`` off (nothing
        re-plans by itself: the node serves requests only, an in-process loop flies open
        loop)."""
        if not settings.self_replan:
            return None
        base = planner.base_problem
        return cls(planner.case, settings, planner.grid,
                   planner.grid.nominal_stage_length(base.stage_dt), base.N)

    def observe(self, t_s: float, pos_m, vel_m_s, mass_kg: float,
                plan: Plan | None) -> Reason | None:
        """The reason a re-plan is due at this estimate (None: not due). The first estimate
        with a plan in force only starts the prediction; one older than the prediction (topics
        are not ordered: a re-plan may have started from a newer estimate) is not judged."""
        with self._lock:
            if self._t is not None and t_s < self._t - TIME_EPS_S:
                return None
            x = self._normalised(pos_m, vel_m_s, mass_kg)
            here = self.grid.state(x, t_s, plan)[1]
            last, self._last = self._last, here
            if plan is None:
                return None
            if self._x is None:
                self._x, self._t = x, t_s
                return None
            self._advance(t_s, plan)
            end = float(self.grid.ends(plan)[0][-1])
            s = self.settings
            remaining = (end - here) / self.stage_length      # in nominal stages
            eps = self.grid.eps / self.stage_length
            if (s.arrival_stages and remaining <= s.arrival_stages + eps
                    and remaining > s.arrival_min_step + eps):
                return Reason.ARRIVAL
            if (s.replan_every_stages and last is not None
                    and self._boundary_between(last, here, end)):
                return Reason.STAGE
            if self._drifted(pos_m, vel_m_s):
                return Reason.DRIFT
            return None

    def replanned(self, t_s: float, pos_m, vel_m_s, mass_kg: float) -> None:
        """A re-plan starts from this estimate: the prediction restarts from it."""
        with self._lock:
            self._x, self._t = self._normalised(pos_m, vel_m_s, mass_kg), t_s

    # ------------------------------------------------------------------ internals
    def _normalised(self, pos_m, vel_m_s, mass_kg) -> np.ndarray:
        """An estimate's normalised Cartesian state [r, v, m] (7,)."""
        return self.case.units.cartesian_normalised(np.concatenate([pos_m, vel_m_s,
                                                                    [mass_kg]]))

    def _advance(self, t_s: float, plan: Plan) -> None:
        """Propagate the prediction to t_s with the plan's thrust, piece by piece between its
        stage starts."""
        starts = plan.start_times_s
        cuts = [self._t, *starts[(starts > self._t + TIME_EPS_S) & (starts < t_s - TIME_EPS_S)],
                t_s]
        for a, b in zip(cuts[:-1], cuts[1:]):
            if b > a:
                self._x = propagate(self.case, self._x, plan.thrust_at(a), b - a)
        self._t = t_s

    def _boundary_between(self, prev: float, here: float, end: float) -> bool:
        """A nominal boundary k (k % replan_every_stages == 0, before the arrival phase) in
        (prev, here] (grid positions; the grid ends at ``end``)."""
        origin, eps = end - self.stages * self.stage_length, self.grid.eps
        k_hi = int(np.floor((here - origin + eps) / self.stage_length))
        k_lo = int(np.floor((prev - origin + eps) / self.stage_length))
        last_k = self.stages - max(self.settings.arrival_stages, 0) - 1
        return any(0 < k <= last_k and k % self.settings.replan_every_stages == 0
                   for k in range(k_lo + 1, k_hi + 1))

    def _drifted(self, pos_m, vel_m_s) -> bool:
        s = self.settings
        if not (s.trigger_position_m or s.trigger_velocity_m_s):
            return False
        x = self.case.units.cartesian_si(self._x)
        dr = float(np.linalg.norm(np.asarray(pos_m) - x[:3]))
        dv = float(np.linalg.norm(np.asarray(vel_m_s) - x[3:6]))
        return bool((s.trigger_position_m and dr > s.trigger_position_m)
                    or (s.trigger_velocity_m_s and dv > s.trigger_velocity_m_s))
