"""A valid control schedule (``Plan``), what one re-optimisation produced (``ReplanOutcome``
with a ``Level``), and the plan file format of the node's persistence. ROS-free; times are
seconds on the caller's clock, states SI (position m, velocity m/s, mass kg), thrust N."""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path

import numpy as np

from daddy_core import trajectory_output
from daddy_core.dynamics import models
from daddy_core.dynamics.units import Units
from daddy_core.errors import DaddyError
from daddy_core.solver import Solution

# clock comparisons: times closer than this to a stage boundary count as on it [s]
TIME_TOLERANCE_S = 1e-6
# relative thrust-bound excess (solver tolerance) saturated onto the bound rather than rejected
SATURATION_SLACK = 1e-3
PLAN_FORMAT = "daddy-plan-1"


class Level(str, Enum):
    """Severity of an outcome, as diagnostic_msgs/DiagnosticStatus names its levels."""

    OK = "OK"
    WARN = "WARN"
    ERROR = "ERROR"

    __str__ = str.__str__
    __format__ = str.__format__


class Code(str, Enum):
    """The stable result code of a diagnostic event (the ``code`` value on /diagnostics; the
    message is free text for people, the code is for programs). Values never change meaning;
    new ones may be added."""

    OK = "OK"                               # re-optimised, converged, within budget
    NOT_CONVERGED = "NOT_CONVERGED"         # stored the best feasible iterate
    BUDGET_EXCEEDED = "BUDGET_EXCEEDED"     # stored, but the solve took longer than the budget
    INFEASIBLE = "INFEASIBLE"               # target out of reach: best effort stored, or kept
    UNSAFE_RESULT = "UNSAFE_RESULT"         # the solver's result is not flyable: plan kept
    SOLVER_FAILED = "SOLVER_FAILED"         # the solver raised: plan kept
    INPUT_REJECTED = "INPUT_REJECTED"       # an estimate / request field is unusable
    STALE = "STALE"                         # the estimate is older than staleness_s
    FUTURE = "FUTURE"                       # every estimate is in the request's future
    PLAN_ENDED = "PLAN_ENDED"               # no stage of the plan remains after the stamp
    NO_ESTIMATE = "NO_ESTIMATE"             # no valid state and mass estimate yet
    NOT_ACTIVE = "NOT_ACTIVE"               # request while the node is not active
    CONFIGURE_FAILED = "CONFIGURE_FAILED"   # a parameter failed the configure transition
    PARAMETER_REJECTED = "PARAMETER_REJECTED"
    PLAN_ADOPTED = "PLAN_ADOPTED"           # a nominal or given plan is now in force
    PLAN_FILE_ERROR = "PLAN_FILE_ERROR"     # plan_file / persist_file unreadable
    RESTORED = "RESTORED"                   # a persisted plan restored after a restart
    FEEDBACK_LAW = "FEEDBACK_LAW"           # a stage's thrust from the plan's feedback law
    PLAN_DOES_NOT_FIT = "PLAN_DOES_NOT_FIT"  # the estimate is far from the plan: no thrust from it
    CANCELLED = "CANCELLED"                 # the re-plan was cancelled: plan kept
    NOT_BUILT = "NOT_BUILT"                 # an interface package is missing: no action / bond
    BOND_BROKEN = "BOND_BROKEN"             # the lifecycle manager's bond broke: guidance goes on
    STAMP_JUMP = "STAMP_JUMP"               # an estimate's stamp far from the flight's clock
    CLOCK_CHANGED = "CLOCK_CHANGED"         # consistent estimates set a new flight clock
    INTERNAL_ERROR = "INTERNAL_ERROR"       # a bug: reported, the node goes on

    __str__ = str.__str__
    __format__ = str.__format__


@dataclass
class Plan:
    """A valid control schedule anchored at ``epoch_s``.

    Attributes:
        epoch_s: time of the first stage start [s].
        stage_dt_s: (K,) stage durations [s].
        thrust_n: (K, 3) thrust per stage [N].
        states_si: (K+1, 7) predicted states (m, m/s, kg).
        solution: the Solution (normalised), for warm starts.
        request_id, solve_time_s, warm_start, max_violation: provenance for diagnostics.
        thrust_bound_n: the thrust bound the plan was optimised under [N] (a rung of the
            margin ladder, see ``replan_policy``).
        thrust_rtn: the thrust is in the radial / transverse / normal axes of the osculating
            orbit (Earth-centred scenarios), not in the scenario's frame.
        arrival: solved as the arrival phase (``shift``): its stages split, its terminal
            position aimed within the arrival tolerance; every re-plan of it is one too.
    """

    epoch_s: float
    stage_dt_s: np.ndarray
    thrust_n: np.ndarray
    states_si: np.ndarray
    solution: Solution
    request_id: str = ""
    solve_time_s: float = 0.0
    warm_start: bool = False
    max_violation: float = 0.0
    thrust_bound_n: float = 0.0
    thrust_rtn: bool = False
    arrival: bool = False

    @classmethod
    def of(cls, sol: Solution, X: np.ndarray, epoch_s: float, units: Units, thrust_bound: float,
           request_id: str = "", solve_time_s: float = 0.0, warm_start: bool = False,
           arrival: bool = False) -> "Plan":
        """The plan flying ``sol``'s controls from ``epoch_s``, predicted states X (normalised)
        and thrust bound (normalised). A solution staged in true longitude (Earth-centred)
        gives its stage durations from its time states and its states in Cartesian
        coordinates, as every plan holds them."""
        rtn = trajectory_output.is_earth_centred(sol)
        if rtn:
            dt_s = np.diff(X[:, sol.time_index]) * units.tu_s
            states = trajectory_output.earth_cartesian_si(sol, X)
        else:
            dt_s, states = sol.stage_dt * units.tu_s, units.states_si(X)
        return cls(epoch_s, dt_s, sol.thrust_n.copy(), states, sol, request_id, solve_time_s,
                   warm_start, sol.max_violation, float(units.thrust_n(thrust_bound)), rtn,
                   arrival)

    @property
    def stage_start_s(self) -> np.ndarray:
        """(K,) stage start times relative to ``epoch_s``."""
        return np.concatenate([[0.0], np.cumsum(self.stage_dt_s)[:-1]])

    @property
    def start_times_s(self) -> np.ndarray:
        """(K,) stage start times [s] on the caller's clock."""
        return self.epoch_s + self.stage_start_s

    @property
    def end_times_s(self) -> np.ndarray:
        """(K,) stage end times [s] on the caller's clock."""
        return self.start_times_s + self.stage_dt_s

    @property
    def end_s(self) -> float:
        return self.epoch_s + float(np.sum(self.stage_dt_s))

    def stage_index(self, t_s: float) -> int | None:
        """The stage containing time t (a time on a stage boundary opens the stage), or None
        before the epoch or after the end."""
        rel = t_s - self.epoch_s + TIME_TOLERANCE_S
        if rel < 0 or t_s + TIME_TOLERANCE_S >= self.end_s:
            return None
        k = int(np.searchsorted(np.cumsum(self.stage_dt_s), rel, side="right"))
        return min(k, len(self.thrust_n) - 1)

    def thrust_at(self, t_s: float) -> np.ndarray:
        """Thrust [N] of the stage containing time t (zero before the epoch or after the end)."""
        k = self.stage_index(t_s)
        return np.zeros(3) if k is None else self.thrust_n[k].copy()

    def mass_at(self, t_s: float) -> float | None:
        """The plan's mass [kg] at time t: linear across the stage holding it (the mass flow is
        constant at a stage's constant thrust); None outside the plan's stages."""
        k = self.stage_index(t_s)
        if k is None:
            return None
        f = (t_s - float(self.start_times_s[k])) / float(self.stage_dt_s[k])
        m0, m1 = self.states_si[k, 6], self.states_si[k + 1, 6]
        return float(m0 + min(max(f, 0.0), 1.0) * (m1 - m0))

    def fly_law(self, k: int, thrust_n: np.ndarray) -> None:
        """Stage k flies ``thrust_n`` [N], a feedback law's (``daddy_ros.feedback``)."""
        self.thrust_n[k] = thrust_n

    def command_at(self, t_s: float, pos_m, vel_m_s) -> np.ndarray:
        """The thrust command [N] at time t in the scenario's frame, for a spacecraft at
        position pos_m and velocity vel_m_s (an RTN plan's thrust turns with the orbit: its
        axes are those of the osculating orbit of that state)."""
        u = self.thrust_at(t_s)
        return models.rtn_basis(pos_m, vel_m_s) @ u if self.thrust_rtn else u


@dataclass
class ReplanOutcome:
    """What one re-optimisation produced (ok: a new valid plan was stored)."""

    ok: bool
    level: Level
    reason: str
    request_id: str
    solve_time_s: float
    plan: Plan | None
    iterations: dict = field(default_factory=dict)
    warm_start: bool = False
    code: Code = Code.OK


def write_plan_file(path: str | Path, plan: Plan, scenario: str) -> None:
    """Write ``plan`` (epoch, provenance and solution) atomically to ``path``."""
    data = {"format": PLAN_FORMAT, "scenario": scenario, "epoch_s": plan.epoch_s,
            "request_id": plan.request_id, "arrival": plan.arrival,
            "solution": plan.solution.to_dict()}
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(data, allow_nan=False))
    os.replace(tmp, path)   # a crash mid-write leaves the previous file intact


def read_plan_file(path: str | Path, scenario: str, max_stages: int,
                   max_thrust_n: float) -> tuple[Solution, float, str, bool]:
    """(solution, epoch s, request id, arrival plan) of a file written by ``write_plan_file``
    for ``scenario``. Raises DaddyError naming what is wrong with the file."""
    try:
        data = json.loads(Path(path).read_text())
        sol = Solution.from_dict(data["solution"])
        epoch = float(data["epoch_s"])
        arrival = data.get("arrival", False)
        if not isinstance(arrival, bool):
            raise TypeError(f"arrival must be true or false, got {arrival!r}")
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise DaddyError(f"persisted plan {path}: unreadable ({exc!r})") from exc
    if data.get("format") != PLAN_FORMAT or data.get("scenario") != scenario:
        raise DaddyError(f"persisted plan {path} is not a {PLAN_FORMAT} plan of scenario "
                         f"{scenario!r}")
    thrust = sol.thrust_n
    if not (math.isfinite(epoch) and 1 <= len(thrust) <= max_stages
            and np.all(np.isfinite(thrust)) and np.all(np.isfinite(sol.X))):
        raise DaddyError(f"persisted plan {path} has a bad epoch, stage count or values")
    if np.max(np.linalg.norm(thrust, axis=1)) > max_thrust_n * (1 + SATURATION_SLACK):
        raise DaddyError(f"persisted plan {path} violates the thrust bound")
    return sol, epoch, str(data.get("request_id", "restored")), arrival
