"""Messages <-> arrays. SI units throughout (REP 103): metres, m/s, kg, newtons, seconds."""
from __future__ import annotations

import array
import math

import numpy as np
from builtin_interfaces.msg import Duration, Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped, Vector3Stamped
from nav_msgs.msg import Odometry, Path
from std_msgs.msg import Header
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from .plan import Level, Plan

JOINT_NAMES = ["thrust_x", "thrust_y", "thrust_z"]
STATUS_NAME = "daddy_guidance: replan"
LEVELS = {Level.OK: DiagnosticStatus.OK, Level.WARN: DiagnosticStatus.WARN,
          Level.ERROR: DiagnosticStatus.ERROR}


def stamp_to_s(t: Time) -> float:
    return float(t.sec) + 1e-9 * float(t.nanosec)


def s_to_stamp(s: float) -> Time:
    if not math.isfinite(s) or s < 0:
        s = 0.0
    sec = int(math.floor(s))
    return Time(sec=sec, nanosec=min(int(round((s - sec) * 1e9)), 999_999_999))


def s_to_duration(s: float) -> Duration:
    sec = int(math.floor(s))
    return Duration(sec=sec, nanosec=min(int(round((s - sec) * 1e9)), 999_999_999))


def odometry_to_state(msg: Odometry):
    """(position m (3,), velocity m/s (3,), stamp s, frame_id) from an Odometry."""
    p = msg.pose.pose.position
    v = msg.twist.twist.linear
    return (np.array([p.x, p.y, p.z], dtype=float), np.array([v.x, v.y, v.z], dtype=float),
            stamp_to_s(msg.header.stamp), msg.header.frame_id)


def state_to_odometry(pos_m, vel_m_s, stamp_s: float, frame_id: str) -> Odometry:
    msg = Odometry()
    msg.header = Header(stamp=s_to_stamp(stamp_s), frame_id=frame_id)
    msg.child_frame_id = "spacecraft"
    msg.pose.pose.position.x, msg.pose.pose.position.y, msg.pose.pose.position.z = map(float, pos_m)
    msg.pose.pose.orientation.w = 1.0
    msg.twist.twist.linear.x, msg.twist.twist.linear.y, msg.twist.twist.linear.z = map(float, vel_m_s)
    return msg


def plan_to_joint_trajectory(plan: Plan, frame_id: str, from_s: float | None = None) -> JointTrajectory:
    """One point per remaining stage: thrust [N] in ``effort``, stage start in
    ``time_from_start`` relative to ``header.stamp`` (= the plan epoch, or ``from_s``)."""
    t0 = plan.epoch_s if from_s is None else from_s
    msg = JointTrajectory()
    msg.header = Header(stamp=s_to_stamp(t0), frame_id=frame_id)
    msg.joint_names = list(JOINT_NAMES)
    starts = plan.epoch_s + plan.stage_start_s
    ends = starts + plan.stage_dt_s
    for start, end, u in zip(starts, ends, plan.thrust_n):
        if end <= t0:
            continue
        pt = JointTrajectoryPoint()
        pt.effort = array.array("d", [float(c) for c in u])
        pt.time_from_start = s_to_duration(max(start - t0, 0.0))
        msg.points.append(pt)
    return msg


def joint_trajectory_to_schedule(msg: JointTrajectory):
    """(start times s relative to header.stamp (K,), thrust N (K, 3)) from a schedule."""
    t = np.array([p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec for p in msg.points])
    u = np.array([list(p.effort) for p in msg.points], dtype=float).reshape(-1, 3)
    return t, u


def thrust_command(u_n, stamp_s: float, frame_id: str) -> Vector3Stamped:
    msg = Vector3Stamped()
    msg.header = Header(stamp=s_to_stamp(stamp_s), frame_id=frame_id)
    msg.vector.x, msg.vector.y, msg.vector.z = map(float, u_n)
    return msg


def plan_to_path(plan: Plan, frame_id: str) -> Path:
    msg = Path()
    msg.header = Header(stamp=s_to_stamp(plan.epoch_s), frame_id=frame_id)
    times = plan.epoch_s + np.concatenate([[0.0], np.cumsum(plan.stage_dt_s)])
    for t, x in zip(times, plan.states_si):
        ps = PoseStamped()
        ps.header = Header(stamp=s_to_stamp(t), frame_id=frame_id)
        ps.pose.position.x, ps.pose.position.y, ps.pose.position.z = map(float, x[:3])
        ps.pose.orientation.w = 1.0
        msg.poses.append(ps)
    return msg


def diagnostics(level: Level, message: str, values: dict, stamp_s: float,
                hardware_id: str = "daddy_guidance") -> DiagnosticArray:
    st = DiagnosticStatus(level=LEVELS[level], name=STATUS_NAME, message=message[:500],
                          hardware_id=hardware_id)
    st.values = [KeyValue(key=str(k), value=str(v)) for k, v in values.items()]
    arr = DiagnosticArray()
    arr.header = Header(stamp=s_to_stamp(stamp_s))
    arr.status = [st]
    return arr
