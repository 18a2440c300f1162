"""A catalogue case with its time of flight free in a window (issue 46): ``problem.tof_window``
in a case file, ``daddy solve CASE --free-tof LO HI``.

The case's ``x_target`` is the target's state at the case's own time of flight; with the time
free, the target moves on with its natural motion to the arrival time T:

- ``sun_two_body``: a planet on its Keplerian orbit about the Sun (``dynamics.kepler``), e.g.
  Mars for ``earth_mars``;
- ``double_integrator``: a body in free space, r_t + v_t (T - T_case).

Earth-centred cases arrive anywhere on the target orbit at t = ToF, so what is free there is
the arrival angle: ``problem.revolutions_window`` in a case file, ``daddy solve CASE
--free-revolutions LO HI``, the angle the stages span free in [LO, HI] revolutions
(``with_free_time`` on a problem staged in true longitude), one solve where
``revolutions.search_revolutions`` runs a golden-section search over whole solves. The
Earth-Moon cases' targets are periodic orbits of the rotating frame, whose flow is not written
here: a free time of flight is refused for them (and for Earth-centred cases) by name.
"""
from __future__ import annotations

import math

from ..da import functions as dm
from ..dynamics.kepler import kepler_flow
from ..dynamics.units import DAY_S
from ..errors import DaddyError
from ..problem import Problem
from ..static_parameters import with_free_time
from .cases import Case

FIELD = "problem.tof_window"
REVOLUTIONS_FIELD = "problem.revolutions_window"
ANGLE = "angle"   # the parameter's name: the true longitude the stages span [rad]


def window_of(case: Case, window=None) -> tuple[float, float] | None:
    """The time-of-flight window [lower, upper] normalised: ``window`` if given, else the case's
    ``problem.tof_window``, both in the case's own time unit (days where the case gives
    ``tof_days``, normalised for ``stage_duration``); None when neither is set."""
    window = case.problem.get("tof_window") if window is None else window
    if window is None:
        return None
    if not (isinstance(window, (list, tuple)) and len(window) == 2
            and all(isinstance(w, (int, float)) and math.isfinite(w) for w in window)
            and 0 < window[0] < window[1]):
        raise DaddyError(f"{FIELD} must be [lower, upper] with 0 < lower < upper (the case's "
                         f"time unit), got {window!r}")
    if case.system == "double_integrator":
        return float(window[0]), float(window[1])
    return tuple(float(case.units.time(w * DAY_S)) for w in window)


def target_motion(case: Case):
    """target(T, x_target): the case's target at the arrival time T (module docstring)."""
    t_case = case.tof
    if case.system == "sun_two_body":
        gm = case.units.gm

        def planet(T, xt):
            return dm.concatenate([kepler_flow(xt[:3], xt[3:6], T - t_case, gm), xt[6:]])
        return planet
    if case.system == "double_integrator":
        def drifting(T, xt):
            dt = T - t_case
            return dm.stack([xt[i] + xt[3 + i] * dt for i in range(3)]
                            + [xt[3 + i] + 0.0 * dt for i in range(3)])
        return drifting
    raise DaddyError(f"{FIELD}: a free time of flight is built for the sun_two_body and "
                     f"double_integrator systems; {case.name!r} is {case.system} (Earth-centred "
                     f"cases free their arrival angle instead: {REVOLUTIONS_FIELD}, "
                     "--free-revolutions)")


def with_free_tof(case: Case, problem: Problem, window) -> Problem:
    """``problem`` (built from ``case``) with the time of flight free in ``window`` (normalised,
    ``window_of``), the target moving to the arrival time; guess: the case's time of flight
    where the window holds it. ``Solution.parameters["tof"]`` is T, normalised."""
    motion = target_motion(case)
    lower, upper = window
    return with_free_time(problem, lower, upper, min(max(case.tof, lower), upper),
                          target=motion)


def revolutions_window_of(case: Case, window=None) -> tuple[float, float] | None:
    """The arrival-angle window [lower, upper] in revolutions: ``window`` if given, else the
    case's ``problem.revolutions_window``; None when neither is set. Earth-centred cases only."""
    window = case.problem.get("revolutions_window") if window is None else window
    if window is None:
        return None
    if not case.staged_in_angle:
        raise DaddyError(f"{REVOLUTIONS_FIELD}: a free arrival angle is for Earth-centred cases "
                         f"(staged in true longitude); {case.name!r} is {case.system} (free its "
                         f"time of flight instead: {FIELD}, --free-tof)")
    if not (isinstance(window, (list, tuple)) and len(window) == 2
            and all(isinstance(w, (int, float)) and math.isfinite(w) for w in window)
            and 0 < window[0] < window[1]):
        raise DaddyError(f"{REVOLUTIONS_FIELD} must be [lower, upper] revolutions with 0 < lower "
                         f"< upper, got {window!r}")
    return float(window[0]), float(window[1])


def with_free_revolutions(case: Case, problem: Problem, window) -> Problem:
    """``problem`` (built from the Earth-centred ``case``) with the angle its stages span free
    in ``window`` [lower, upper] revolutions (``revolutions_window_of``); guess: the case's own
    revolutions where the window holds them. ``Solution.parameters["angle"]`` is the span in
    radians (revolutions: / 2 pi)."""
    lower, upper = window
    guess = min(max(case.revolutions, lower), upper)
    return with_free_time(problem, 2 * math.pi * lower, 2 * math.pi * upper,
                          2 * math.pi * guess, name=ANGLE)
