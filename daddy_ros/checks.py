"""Input checks of state and mass estimates: every rejection names the field (message field
paths as in msg_docs/). ROS-free; states are SI in the scenario's frame, stamps seconds on the
caller's clock."""
from __future__ import annotations

import math

import numpy as np

from daddy_core.catalogue import Case
from daddy_core.dynamics.units import EARTH_RADIUS_KM, MOON_RADIUS_KM
from daddy_core.errors import DaddyError

from .plan import Code

# an estimate stamped up to this much after the request time is still usable [s]
FUTURE_TOLERANCE_S = 1.0


class InputRejected(DaddyError):
    """A state estimate, mass or request that is not used; the message names the field, the
    code says which kind of rejection it is (plan.Code)."""

    def __init__(self, message: str, code: Code = Code.INPUT_REJECTED):
        super().__init__(message)
        self.code = code


class EstimateChecks:
    """The checks of one scenario's estimates (its spacecraft and domain)."""

    def __init__(self, case: Case, staleness_s: float, mass_tolerance_kg: float):
        self.case, self.units = case, case.units
        self.staleness_s = staleness_s
        self.mass_tolerance_kg = mass_tolerance_kg

    def check_estimate(self, pos_m, vel_m_s, stamp_s: float) -> None:
        """Raise InputRejected (naming the field) for a state estimate that cannot be used at any
        time: non-finite, unset stamp, or outside the scenario's domain."""
        pos = np.asarray(pos_m, dtype=float)
        vel = np.asarray(vel_m_s, dtype=float)
        if pos.shape != (3,) or not np.all(np.isfinite(pos)):
            raise InputRejected("state_estimate.pose.pose.position is not 3 finite numbers")
        if vel.shape != (3,) or not np.all(np.isfinite(vel)):
            raise InputRejected("state_estimate.twist.twist.linear is not 3 finite numbers")
        check_stamp(stamp_s, "state_estimate")
        self._check_domain(self.units.cartesian_normalised(np.concatenate([pos, vel])))

    def check_mass(self, mass_kg, stamp_s: float | None = None) -> None:
        """Raise InputRejected unless dry mass < mass_kg <= wet mass (+ tolerance)."""
        if mass_kg is None or not math.isfinite(mass_kg):
            raise InputRejected("mass_estimate.inertia.m is missing or not finite")
        sc = self.case.spacecraft
        if mass_kg <= sc.dry_mass_kg:
            raise InputRejected(f"mass_estimate.inertia.m = {mass_kg:.6g} kg is not above the dry "
                                f"mass {sc.dry_mass_kg:.6g} kg")
        if mass_kg > sc.wet_mass_kg + self.mass_tolerance_kg:
            raise InputRejected(f"mass_estimate.inertia.m = {mass_kg:.6g} kg exceeds the wet mass "
                                f"{sc.wet_mass_kg:.6g} kg")
        if stamp_s is not None:
            check_stamp(stamp_s, "mass_estimate")

    def check_state(self, pos_m, vel_m_s, mass_kg, stamp_s: float,
                    now_s: float | None = None) -> np.ndarray:
        """All checks of one estimate used at time now_s; returns the normalised Cartesian
        state [r, v, m] (7,) (``frames`` maps it onto the scenario's own state). Raises
        InputRejected (naming the field) for an estimate the planner must not use."""
        self.check_estimate(pos_m, vel_m_s, stamp_s)
        self.check_mass(mass_kg)
        if now_s is not None:
            if stamp_s > now_s + FUTURE_TOLERANCE_S:
                raise InputRejected(f"state_estimate.header.stamp is {stamp_s - now_s:.3g} s in "
                                    "the future of the request", Code.FUTURE)
            if now_s - stamp_s > self.staleness_s:
                raise InputRejected(f"state_estimate.header.stamp is stale ({now_s - stamp_s:.3g}"
                                    f" s old, bound staleness_s = {self.staleness_s:.3g} s)", Code.STALE)
        return self.units.cartesian_normalised(np.concatenate([np.asarray(pos_m, float),
                                                               np.asarray(vel_m_s, float),
                                                               [mass_kg]]))

    def _check_domain(self, x: np.ndarray) -> None:
        sys = self.case.system
        r = x[:3]
        if sys == "earth_moon_cr3bp":
            mu = self.units.gm
            if np.linalg.norm(r - [1 - mu, 0, 0]) < MOON_RADIUS_KM / self.units.lu_km:
                raise InputRejected("state_estimate.pose.pose.position is inside the Moon")
            if np.linalg.norm(r + [mu, 0, 0]) < EARTH_RADIUS_KM / self.units.lu_km:
                raise InputRejected("state_estimate.pose.pose.position is inside the Earth")
            if np.linalg.norm(r) > 5.0 or np.linalg.norm(x[3:6]) > 10.0:
                raise InputRejected("state_estimate (position or velocity) is far outside the "
                                    "Earth-Moon domain")
        elif sys == "earth_equinoctial":
            # the elements of an open orbit do not exist
            if np.linalg.norm(r) < EARTH_RADIUS_KM / self.units.lu_km:
                raise InputRejected("state_estimate.pose.pose.position is inside the Earth")
            if not x[3:6] @ x[3:6] / 2 - self.units.gm / np.linalg.norm(r) < 0:
                raise InputRejected("state_estimate.twist.twist.linear: not a closed orbit "
                                    "(escape speed or above), which the Earth-centred "
                                    "scenario's orbital elements need")
        elif sys == "sun_two_body":
            if not 0.05 < np.linalg.norm(r) < 50.0 or np.linalg.norm(x[3:6]) > 10.0:
                raise InputRejected("state_estimate (position or velocity) is outside the "
                                    "heliocentric domain")


def check_stamp(stamp_s: float, topic: str) -> None:
    """Raise InputRejected for an unset, negative or non-finite stamp of ``topic``."""
    if not math.isfinite(stamp_s) or stamp_s <= 0.0:
        raise InputRejected(f"{topic}.header.stamp is unset, negative or not finite "
                            f"({stamp_s!r} s)")


class StampGuard:
    """The flight's clock as the accepted state estimates set it. An estimate stamped more than
    the bound from the newest accepted one (a glitch: +100 days) is rejected and changes
    nothing -- not the re-plan policy's prediction, not the plan's stage -- unless
    ``confirmations`` estimates in a row agree on the new clock (each within the bound of the
    one before): the last of them is accepted and sets it. The bound is ``stages`` times the
    longest stage of the plan in force (none without a plan, or with ``stages`` = 0)."""

    def __init__(self, stages: float, confirmations: int):
        self.stages, self.confirmations = stages, confirmations
        self.newest: float | None = None
        self._pending: list[float] = []

    def bound_s(self, plan) -> float:
        if plan is None or not self.stages:
            return math.inf
        return self.stages * float(np.max(plan.stage_dt_s))

    def accept(self, stamp_s: float, topic: str, plan) -> bool:
        """Raise InputRejected (code STAMP_JUMP) for a jump not yet confirmed; True when this
        estimate confirms a new clock, False for an ordinary one."""
        bound = self.bound_s(plan)
        if self.newest is None or abs(stamp_s - self.newest) <= bound:
            self.newest = stamp_s if self.newest is None else max(self.newest, stamp_s)
            self._pending = []
            return False
        if not (self._pending and abs(stamp_s - self._pending[-1]) <= bound):
            self._pending = []
        self._pending.append(stamp_s)
        if len(self._pending) >= self.confirmations:
            self.newest, self._pending = stamp_s, []
            return True
        raise InputRejected(
            f"{topic}.header.stamp is {stamp_s - self.newest:+.6g} s from the newest accepted "
            f"estimate, beyond max_stamp_jump_stages ({bound:.6g} s); {len(self._pending)} of "
            f"stamp_jump_confirmations = {self.confirmations} estimates in a row would set the "
            f"new clock", Code.STAMP_JUMP)

