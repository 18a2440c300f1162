"""The guidance node's settings: one place for every parameter's name, default, description
and whether it may change at run time. The node declares its ROS parameters from here, the
planner takes ``PlannerConfig``, and ``config/guidance.yaml`` lists the same defaults (a test
checks it)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from pathlib import Path

from daddy_core.errors import DaddyError
from daddy_core.solver import METHODS

PLANS_DIR = Path(__file__).with_name("plans")   # nominal plans computed by `daddy solve`


def bundled_plan(case_name: str, fuel_optimal: bool = True) -> Path | None:
    """The nominal plan shipped for a catalogue case (``plans/CASE_fuel.json``), if any."""
    p = PLANS_DIR / f"{case_name}_{'fuel' if fuel_optimal else 'energy'}.json"
    return p if p.exists() else None


def option(default, description: str, runtime: bool = False, static: bool = False,
           bounds: tuple | None = None):
    """A dataclass field with its description and limits: a node parameter (here) or a field
    of a campaign file (``campaigns``). ``runtime``: settable in every lifecycle state, in
    flight too (``GuidanceSession.reconfigure``; the others only while unconfigured); ``static``: read when the node is constructed, so never
    settable afterwards (a read-only descriptor); ``bounds``: the (lowest, highest) value, a
    range in the descriptor that rclpy enforces and the campaign file's check."""
    return field(default=default, metadata={"description": description, "runtime": runtime,
                                            "static": static, "bounds": bounds})


@dataclass(frozen=True)
class PlannerConfig:
    """What the guidance planner re-optimises and how (SI units; 0 for a tolerance: the case's
    own)."""

    scenario: str = option("halo_l2_l1", "catalogue case name or path to a case .json file")
    method: str = option("dyn", f"DDP method, one of {', '.join(METHODS)}", runtime=True)
    polish: bool = option(True, "Newton polishing after each re-optimisation", runtime=True)
    fuel_optimal: bool = option(True, "fuel-optimal cost (else energy-optimal)")
    stages: int = option(0, "stage count of the scenario (0: the case's own)",
                         bounds=(0, 100_000))
    r_min_km: float = option(0.0, "keep the whole trajectory at least this far from the Moon "
                                  "(Earth-Moon scenarios) or the Sun (heliocentric) [km]; "
                                  "plans are checked along their dense re-propagation, not "
                                  "only at the nodes; 0: the scenario's own (its "
                                  "problem.r_min_km), none if it has none",
                             bounds=(0.0, 1e9))
    tol_aul: float = option(0.0, "augmented-Lagrangian tolerance (0: the case's own for cold "
                                 "solves, 1e-5 for polished warm re-optimisations, which Newton "
                                 "then takes to tol_newton)", bounds=(0.0, 1.0), runtime=True)
    tol_newton: float = option(0.0, "Newton polishing tolerance (0: the case's own)",
                               bounds=(0.0, 1.0), runtime=True)
    time_budget_s: float = option(60.0, "wall-clock budget of one re-optimisation [s]",
                                  runtime=True, bounds=(1e-3, 86_400.0))
    restore_first: bool = option(True, "restore feasibility of the warm start by Newton before "
                                       "DDP, so a re-optimisation stopped by its budget still "
                                       "yields a feasible plan (and re-plans are faster)",
                                       runtime=True)
    arrival_tolerance_m: float = option(0.0, "in the arrival phase (the last stages, split) "
                                             "the terminal position is aimed where the plan "
                                             "arrives, brought within this distance of the "
                                             "target, the velocity exact [m]; 0: position "
                                             "exact too", bounds=(0.0, 1e9), runtime=True)
    thrust_margin: float = option(0.05, "fraction of the thrust rating plans hold back for "
                                        "closed-loop corrections; a re-optimisation gives it up "
                                        "in steps (with 0.05: 95, 97, 98.5, 100 % of the "
                                        "rating) only when the target is out of reach "
                                        "otherwise; 0: the full rating", bounds=(0.0, 0.99),
                                        runtime=True)
    staleness_s: float = option(600.0, "estimates older than this relative to the request are "
                                       "rejected [s]", runtime=True, bounds=(1e-3, 1e9))
    fit_position_m: float = option(1e7, "thrust is commanded from a plan only for an "
                                          "estimate within this distance of the plan's "
                                          "predicted state at its stamp; else the command is "
                                          "withheld and the node re-plans from the estimate "
                                          "(PLAN_DOES_NOT_FIT) [m] (0: no position test)",
                                   bounds=(0.0, 1e12), runtime=True)
    fit_velocity_m_s: float = option(100.0, "... and within this speed of it [m/s] (0: no "
                                          "velocity test)", bounds=(0.0, 1e6), runtime=True)
    max_stamp_jump_stages: float = option(10.0, "a state estimate stamped more than this many "
                                                "of the plan's longest stages from the newest "
                                                "accepted one is rejected (STAMP_JUMP) and "
                                                "changes nothing (0: no test)",
                                          bounds=(0.0, 1e9), runtime=True)
    stamp_jump_confirmations: int = option(3, "... unless this many estimates in a row agree "
                                              "on the new clock: the last sets it, and the node "
                                              "re-plans from it (CLOCK_CHANGED)",
                                           bounds=(1, 1000), runtime=True)
    # a mass estimate may exceed the wet mass by this [kg] (not a node parameter)
    mass_tolerance_kg: float = 1e-6

    def __post_init__(self):
        if not (math.isfinite(self.arrival_tolerance_m) and self.arrival_tolerance_m >= 0.0):
            raise DaddyError(f"arrival_tolerance_m must be a finite number >= 0, got "
                             f"{self.arrival_tolerance_m!r}")
        if not 0.0 <= self.thrust_margin < 1.0:
            raise DaddyError(f"thrust_margin must be in [0, 1), got {self.thrust_margin!r}")


@dataclass(frozen=True)
class TriggerConfig:
    """When the node re-plans by itself (``self_trigger``): every ``replan_every_stages``-th
    stage boundary, on drift from its prediction of the schedule in force, and on every
    estimate of the arrival phase. 0 turns a rule off."""

    self_replan: bool = option(True, "re-plan by itself (stage boundaries, drift, arrival "
                                     "phase); false: only on requests", runtime=True)
    replan_every_stages: int = option(1, "re-plan at every n-th stage boundary of the "
                                         "transfer's nominal grid (0: never)",
                                      bounds=(0, 100_000), runtime=True)
    trigger_position_m: float = option(5000.0, "re-plan when the estimate drifts this far from "
                                               "the predicted flight of the schedule in force "
                                               "[m] (0: no position test)", bounds=(0.0, 1e12),
                                               runtime=True)
    trigger_velocity_m_s: float = option(0.05, "... or this fast [m/s] (0: no velocity test)",
                                         bounds=(0.0, 1e6), runtime=True)
    arrival_stages: int = option(2, "the arrival phase: the last n nominal stages, where every "
                                    "estimate re-plans (0: none)", bounds=(0, 100_000),
                                    runtime=True)
    arrival_min_step: float = option(1 / 256, "... until less than this fraction of a nominal "
                                              "stage remains (the last open-loop interval)",
                                     bounds=(0.0, 1.0), runtime=True)
    feedback_order: int = option(1, "at a stage-boundary re-plan, fly the plan's feedback law "
                                    "of this order instead where the estimate is near the plan "
                                    "(feedback_position_m, feedback_velocity_m_s; 0: always "
                                    "re-plan; docs/policies.md)", bounds=(0, 1), runtime=True)
    feedback_position_m: float = option(20000.0, "a feedback law is flown only within this "
                                                "distance of the plan's state [m]",
                                        bounds=(0.0, 1e9), runtime=True)
    feedback_velocity_m_s: float = option(0.2, "... and within this speed of it [m/s]",
                                          bounds=(0.0, 1e9), runtime=True)


@dataclass(frozen=True)
class NodeConfig:
    """The node's frame, files and topic names."""

    autostart: bool = option(True, "configure and activate at start-up (a plain `ros2 run`); "
                                   "false: an external lifecycle manager drives the "
                                   "transitions through the standard lifecycle services",
                             static=True)
    diagnostics_period_s: float = option(1.0, "period of the node's health status on "
                                              "/diagnostics [s] (lifecycle state, plan age, "
                                              "next stage, last solve); 0: none",
                                         static=True, bounds=(0.0, 3600.0))
    bond_heartbeat_period_s: float = option(0.1, "heartbeat period of the bond with nav2's "
                                                 "lifecycle manager [s], formed on activation "
                                                 "(topic bond, id the node's name); 0: no bond",
                                            bounds=(0.0, 10.0))
    frame_id: str = option("earth_moon_rotating", "frame of state estimates and thrust")
    plan_file: str = option("", "nominal plan (solution JSON) adopted at the first estimate; "
                                "empty: the bundled nominal of the scenario if any, else a cold "
                                "solve on request")
    persist_file: str = option("", "the current plan is written here after every new plan and "
                                   "restored from here at start-up (crash recovery); empty: no "
                                   "persistence")
    state_topic: str = option("state_estimate", "nav_msgs/Odometry input")
    mass_topic: str = option("mass_estimate", "geometry_msgs/InertiaStamped input (kg)")
    request_topic: str = option("replan_request", "std_msgs/Header input: frame_id = request id")
    schedule_topic: str = option("control_schedule", "trajectory_msgs/JointTrajectory output (N)",
                                 static=True)
    thrust_topic: str = option("thrust_command", "geometry_msgs/Vector3Stamped output (N)",
                               static=True)
    path_topic: str = option("planned_path", "nav_msgs/Path output (m)", static=True)


@dataclass(frozen=True)
class Parameter:
    """One node parameter: its name, default, description, when it may change (``option``)
    and its bounds."""

    name: str
    default: object
    description: str
    runtime: bool
    static: bool = False
    bounds: tuple | None = None


def parameters() -> list[Parameter]:
    """The node's parameters in declaration order: the planner's, the re-plan policy's, then
    the node's own."""
    return [Parameter(f.name, f.default, f.metadata["description"], f.metadata["runtime"],
                      f.metadata["static"], f.metadata["bounds"])
            for cls in (PlannerConfig, TriggerConfig, NodeConfig) for f in fields(cls)
            if f.metadata]
