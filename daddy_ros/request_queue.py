"""ROS-free hand-off between the node's callbacks and its solver worker: the estimates accepted
so far, the re-plan request waiting for the worker (coalesced), and which estimate serves a
request. Thread-safe: one condition guards everything.

A request arriving while another waits or a solve runs replaces the waiting one (coalescing:
the next solve serves the newest request, from the newest estimate). Topics are not ordered
with each other, so the worker waits up to ``estimate_wait_s`` for an estimate near the
request's stamp and for the mass estimate of the newest state's time.
"""
from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass, replace

from .checks import FUTURE_TOLERANCE_S, InputRejected
from .plan import TIME_TOLERANCE_S, Code

STATE_HISTORY = 64   # accepted estimates kept to serve requests stamped in their past
# a request stamped after the newest estimate waits this long for the estimate of its time
# (a request can overtake the estimate sent before it)
ESTIMATE_WAIT_S = 0.5
REPORTS_KEPT = 16   # finished solves whose reports a late goal can still read


@dataclass(frozen=True)
class Estimate:
    """An accepted state estimate (SI): position, velocity, stamp, and the RMS 1-sigma of its
    position and velocity where its covariances gave them."""

    pos_m: object
    vel_m_s: object
    stamp_s: float
    pos_sigma_m: float | None = None
    vel_sigma_m_s: float | None = None


@dataclass(frozen=True)
class Request:
    """A re-plan request taken by the worker: its id and mission time (None: serve the newest
    estimate, as the Trigger service does), whether to solve cold, and its time budget [s]
    (None: the node's)."""

    request_id: str
    stamp_s: float | None
    cold: bool = False
    time_budget_s: float | None = None


class RequestQueue:
    """Estimates, the waiting request and the worker's progress (solves started / finished)."""

    def __init__(self, history: int = STATE_HISTORY, estimate_wait_s: float = ESTIMATE_WAIT_S):
        self.cond = threading.Condition()
        self._states: deque[Estimate] = deque(maxlen=history)   # arrival order
        self._masses: deque[tuple[float, float]] = deque(maxlen=history)   # (stamp, kg)
        self._pending = None        # (request_id, request_stamp, monotonic arrival)
        self._busy = False
        self._stopped = False
        self.estimate_wait_s = estimate_wait_s
        self.started = 0            # solves started / finished (sequential, one worker)
        self.finished = 0
        self.coalesced = 0
        self._reports: dict[int, object] = {}   # solve number -> its report (the last few)

    # ------------------------------------------------------------------ estimates
    def add_state(self, pos_m, vel_m_s, stamp_s: float, pos_sigma_m: float | None = None,
                  vel_sigma_m_s: float | None = None) -> None:
        with self.cond:
            self._states.append(Estimate(pos_m, vel_m_s, stamp_s, pos_sigma_m, vel_sigma_m_s))
            self.cond.notify_all()

    def add_mass(self, stamp_s: float, mass_kg: float) -> None:
        with self.cond:
            self._masses.append((stamp_s, mass_kg))
            self.cond.notify_all()

    def has_estimates(self) -> bool:
        """A state and a mass estimate have both been accepted."""
        with self.cond:
            return bool(self._states and self._masses)

    def state_for(self, request_stamp: float | None) -> Estimate | None:
        """The estimate a request is served from: the newest received (request_stamp None), or
        the newest stamped at most FUTURE_TOLERANCE_S after the request's mission time. Raises
        InputRejected when every stored estimate is in the future of that time."""
        with self.cond:
            states = list(self._states)
        if not states or request_stamp is None:
            return states[-1] if states else None
        usable = [s for s in states if s.stamp_s <= request_stamp + FUTURE_TOLERANCE_S]
        if not usable:
            ahead = min(s.stamp_s for s in states) - request_stamp
            raise InputRejected(f"every state_estimate is in the future of the request stamp "
                                f"(the oldest by {ahead:.3g} s)", Code.FUTURE)
        return max(usable, key=lambda s: s.stamp_s)

    def mass_sample_for(self, stamp_s: float) -> tuple[float, float] | None:
        """(stamp s, kg) of the mass estimate for a state's time: same stamp, else the newest
        before it, else the newest received; None before any (the session carries it to the
        state's time along the plan: ``GuidanceSession.mass_at``)."""
        with self.cond:
            masses = list(self._masses)
        if not masses:
            return None
        before = [m for m in masses if m[0] <= stamp_s + TIME_TOLERANCE_S]
        return max(before) if before else masses[-1]

    # ------------------------------------------------------------------ requests
    def enqueue(self, request_id: str, stamp_s: float | None, cold: bool = False,
                time_budget_s: float | None = None) -> int:
        """Queue a re-plan; returns the number of the solve that will serve it (a request
        coalesced with a waiting one replaces it, options included)."""
        with self.cond:
            if self._pending is not None or self._busy:
                self.coalesced += 1
            self._pending = (Request(request_id, stamp_s, cold, time_budget_s),
                             time.monotonic())
            self.cond.notify_all()
            return self.started + 1

    def take(self) -> Request | None:
        """(worker) Block until a request waits, then take it, once its estimate has arrived or
        ``estimate_wait_s`` has passed; its mission time is its stamp plus the time it waited.
        None when stopped."""
        with self.cond:
            while self._pending is None and not self._stopped:
                self.cond.wait(0.2)
            if self._stopped:
                return None
            req, arrived = self._pending
            self._pending = None
            self._wait_for_estimate(req.stamp_s)
            if req.stamp_s is not None:
                req = replace(req, stamp_s=req.stamp_s + time.monotonic() - arrived)
            self._busy = True
            self.started += 1
            return req

    def _wait_for_estimate(self, request_stamp: float | None) -> None:
        """(cond held) Wait for an estimate stamped near the request and for the mass
        estimate of the newest state's time."""
        end = time.monotonic() + self.estimate_wait_s

        def ready():
            if not self._states:
                return False
            newest = max(s.stamp_s for s in self._states)
            if request_stamp is not None and newest < request_stamp - FUTURE_TOLERANCE_S:
                return False
            return any(m[0] >= newest - TIME_TOLERANCE_S for m in self._masses)

        while not self._stopped and time.monotonic() < end and not ready():
            self.cond.wait(0.02)

    def record(self, report) -> None:
        """The report of the solve running now (``session.SolveReport``: what the requests it
        served are answered, ``report_of``)."""
        with self.cond:
            self._reports[self.started] = report
            for n in [n for n in self._reports if n <= self.started - REPORTS_KEPT]:
                del self._reports[n]

    def report_of(self, number: int):
        """The report of solve ``number`` (None: not finished, or long forgotten)."""
        with self.cond:
            return self._reports.get(number)

    def running(self, number: int) -> bool:
        """Solve ``number`` has started and not finished."""
        with self.cond:
            return self._busy and self.started == number

    def waiting(self, number: int) -> bool:
        """Solve ``number`` has not started yet."""
        with self.cond:
            return self.started < number and not self._stopped

    def done(self) -> None:
        """(worker) The solve taken last has finished."""
        with self.cond:
            self._busy = False
            self.finished += 1
            self.cond.notify_all()

    def stopped(self) -> bool:
        with self.cond:
            return self._stopped

    def stop(self) -> None:
        with self.cond:
            self._stopped = True
            self.cond.notify_all()
