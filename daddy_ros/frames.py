"""How the planner maps a navigation estimate onto a scenario's stage grid. ROS-free.

Estimates are Cartesian and timed (position, velocity, mass at a stamp on the caller's clock);
a problem's state and stages are its own: Cartesian states on stages of time for the Sun- and
Earth-Moon-system scenarios (``CartesianGrid``), modified equinoctial elements, time and mass on
stages of true longitude for the Earth-centred ones (``LongitudeGrid``, Sundman-transformed
stages: ``models.equinoctial_sundman``). A grid says where an estimate lies along the plan's
stages (``state``), where the stages end (``ends``) and how a remaining part becomes a
problem's stage lengths and start (``problem_grid``); ``shift.shift_plan`` cuts the plan with
them, the same way for both.
"""
from __future__ import annotations

import math

import numpy as np

from daddy_core import trajectory_output
from daddy_core.catalogue import Case
from daddy_core.dynamics import models

from .plan import Plan


# Positions on a grid this close are the same: an estimate this close to a boundary (a stage
# start, the arrival phase's limits) is on it; the boundaries are sums of stage lengths, equal
# only to round-off
TIME_EPS_S = 1e-3
ANGLE_EPS_RAD = 1e-9


class CartesianGrid:
    """Stages of time: the grid variable is the time on the caller's clock [s]; the state is
    the estimate's (normalised)."""

    eps = TIME_EPS_S

    def __init__(self, case: Case):
        self.units = case.units

    def nominal_stage_length(self, stage_dt: np.ndarray) -> float:
        """A problem's mean stage length (normalised durations) in the grid's variable [s]."""
        return float(self.units.time_s(np.mean(stage_dt)))

    def state(self, x_cart: np.ndarray, t_s: float, plan: Plan | None) -> tuple[np.ndarray, float]:
        """The problem's initial state (normalised) and the grid position of an estimate x_cart
        = [r, v, m] (normalised) at time t_s."""
        return np.asarray(x_cart, float), float(t_s)

    def ends(self, plan: Plan) -> tuple[np.ndarray, np.ndarray]:
        """(stage ends (K,), stage lengths (K,)) of ``plan`` in the grid variable."""
        return plan.epoch_s + np.cumsum(plan.stage_dt_s), np.asarray(plan.stage_dt_s, float)

    def problem_grid(self, lengths: np.ndarray, start: float) -> tuple[np.ndarray, float | None]:
        """(stage lengths, t_start) of a problem over ``lengths`` of the grid from ``start``:
        normalised durations; the start is not needed (time-invariant dynamics)."""
        return np.asarray(lengths, float) / self.units.tu_s, None


class LongitudeGrid:
    """Stages of true longitude (Earth-centred scenarios): the grid variable is the true
    longitude [rad], unwrapped along the plan (a plan's stages span hundreds of revolutions);
    the state is [p, f, g, h, k, t, m] with t the time since the plan's departure."""

    eps = ANGLE_EPS_RAD

    def __init__(self, case: Case):
        self.case, self.units = case, case.units

    def nominal_stage_length(self, stage_dt: np.ndarray) -> float:
        """A problem's mean stage length [rad] (its stages are angles already)."""
        return float(np.mean(stage_dt))

    def state(self, x_cart: np.ndarray, t_s: float, plan: Plan | None) -> tuple[np.ndarray, float]:
        """The elements, time and mass (normalised) of an estimate x_cart = [r, v, m]
        (normalised) at time t_s, and its true longitude on the plan's grid: the revolution
        the plan is in at t_s (without a plan: the case's departure revolution)."""
        x_cart = np.asarray(x_cart, float)
        mee, L = models.cartesian_to_mee(x_cart[:6], self.units.gm)
        if plan is None:
            t, reference = 0.0, self.case.t_start
        else:
            sol = plan.solution
            t = float(sol.X[0, sol.time_index] + self.units.time(t_s - plan.epoch_s))
            reference = float(np.interp(t, sol.X[:, sol.time_index],
                                        trajectory_output.node_longitudes(sol)))
        L = reference + math.remainder(L - reference, 2 * math.pi)
        return np.concatenate([mee, [t, x_cart[6]]]), L

    def ends(self, plan: Plan) -> tuple[np.ndarray, np.ndarray]:
        sol = plan.solution
        return trajectory_output.node_longitudes(sol)[1:], np.asarray(sol.stage_dt, float)

    def problem_grid(self, lengths: np.ndarray, start: float) -> tuple[np.ndarray, float | None]:
        """The lengths are the problem's (angles); it starts at the estimate's longitude."""
        return np.asarray(lengths, float), float(start)


def grid_of(case: Case) -> CartesianGrid | LongitudeGrid:
    """The stage grid of a scenario."""
    return LongitudeGrid(case) if case.staged_in_angle else CartesianGrid(case)
