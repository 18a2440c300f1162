"""The node's reports on /diagnostics: one ``DiagnosticStatus`` per event with its result
``Code`` (``event``) and the periodic health status (``health``), which never repeats the last
solve's reason in its message (a periodic message must not read as a new event)."""
from __future__ import annotations

import time

from . import conversions as cv
from .plan import Code, Level


class DiagnosticsReporter:
    """Publishes the node's diagnostics (``publisher``: /diagnostics) under its fully qualified
    name ``fqn``, logging non-OK events through ``logger`` (at most once per ``log_every_s``
    when given, so a flood of bad inputs does not flood the log); ``now_s``: the node's clock
    [s], for events without a message time."""

    def __init__(self, publisher, fqn: str, logger, now_s):
        self.publisher, self.fqn, self.logger, self.now_s = publisher, fqn, logger, now_s
        self.last_solve: tuple = ()   # (level, reason, solve s or None, unix time)

    def event(self, level: Level, code: Code, message: str, values: dict, stamp,
              log_every_s: float | None = None) -> None:
        if stamp is None:   # no message time to refer to: the node's clock
            stamp = self.now_s()
        self.publisher.publish(cv.diagnostics(level, message, {"code": code, **values}, stamp,
                                              self.fqn))
        # rclpy fixes a call site's filters at its first call: one call site per filter
        if level is not Level.OK and log_every_s:
            self.logger.warning(f"{level}: {message}", throttle_duration_sec=log_every_s)
        elif level is not Level.OK:
            self.logger.warning(f"{level}: {message}")

    def solved(self, level: Level, reason: str, solve_s: float | None) -> None:
        """Remember the last solve for the health status."""
        self.last_solve = (level, reason, solve_s, time.time())

    def health(self, lifecycle_state: str, configured: bool, active: bool, plan, newest,
               solves: int, coalesced: int) -> None:
        """The periodic status: lifecycle state, the plan's age and the time to its next stage
        (mission time of the newest estimate ``newest``), the last solve."""
        values = {"lifecycle_state": lifecycle_state}
        level, message = Level.OK, lifecycle_state
        if plan is not None:
            values.update(plan_epoch_s=f"{plan.epoch_s:.3f}",
                          plan_max_violation=f"{plan.max_violation:.3e}")
            if newest is not None:
                now = newest.stamp_s
                nxt = plan.end_times_s[plan.end_times_s > now]
                values["plan_age_s"] = f"{now - plan.epoch_s:.3f}"
                values["time_to_next_stage_s"] = f"{nxt[0] - now:.3f}" if nxt.size else "none"
        if self.last_solve:
            lvl, reason, solve_s, wall = self.last_solve
            values.update(last_solve_level=str(lvl), last_solve_reason=reason[:200],
                          last_solve_time_s=f"{solve_s:.4f}" if solve_s is not None else "",
                          last_solve_age_s=f"{time.time() - wall:.1f}")
        values.update(solves=str(solves), coalesced=str(coalesced))
        if not configured:
            level = Level.WARN
        elif active and plan is None:
            level, message = Level.WARN, "active: no plan yet"
        elif active and self.last_solve and self.last_solve[0] is Level.ERROR:
            level, message = Level.WARN, "active: the last re-plan failed; last valid plan in force"
        elif active:
            message = "active: plan in force"
        else:
            message = "inactive: no thrust commands, no re-plans"
        self.publisher.publish(cv.diagnostics(level, message, values, self.now_s(), self.fqn,
                                              kind="health"))
