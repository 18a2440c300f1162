"""Messages <-> arrays. SI units throughout (REP 103): metres, m/s, kg, newtons, seconds."""
from __future__ import annotations

import array
import math
from dataclasses import dataclass

import numpy as np
from builtin_interfaces.msg import Duration, Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import InertiaStamped, PoseStamped, Vector3Stamped
from nav_msgs.msg import Odometry, Path
from std_msgs.msg import Header
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from .checks import InputRejected
from .plan import Level, Plan

JOINT_NAMES = ["thrust_x", "thrust_y", "thrust_z"]
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


# a pose orientation used to rotate a body-frame twist must be a unit quaternion to this
QUATERNION_NORM_TOL = 1e-3


@dataclass(frozen=True)
class OdometryState:
    """A state estimate read from an Odometry as its definition says (msg_docs/state_estimate.md):
    position and velocity in ``header.frame_id`` [m, m/s], the stamp [s], and the RMS 1-sigma of
    the position and of the linear velocity from the covariances (None: not given)."""

    pos_m: np.ndarray
    vel_m_s: np.ndarray
    stamp_s: float
    frame_id: str
    pos_sigma_m: float | None
    vel_sigma_m_s: float | None


def odometry_to_state(msg: Odometry) -> OdometryState:
    """Read an Odometry: the pose is in ``header.frame_id``, the twist in ``child_frame_id``
    (nav_msgs/Odometry's definition). A twist in another frame than the header's -- the body
    frame of a standard estimator -- is rotated into it by the pose orientation (body to header
    frame); an empty ``child_frame_id`` or the header's own frame means it is there already.
    Raises InputRejected naming the field for an orientation that is not a unit quaternion
    (when it is needed) and for a covariance that is given but not finite and positive
    definite on its position / linear-velocity block."""
    p, v, q = msg.pose.pose.position, msg.twist.twist.linear, msg.pose.pose.orientation
    pos = np.array([p.x, p.y, p.z], dtype=float)
    vel = np.array([v.x, v.y, v.z], dtype=float)
    if msg.child_frame_id not in ("", msg.header.frame_id):
        with np.errstate(invalid="ignore", over="ignore"):   # a non-finite twist: checked next
            vel = _rotation(np.array([q.w, q.x, q.y, q.z], dtype=float)) @ vel
    return OdometryState(pos, vel, stamp_to_s(msg.header.stamp), msg.header.frame_id,
                         _sigma(msg.pose.covariance, "state_estimate.pose.covariance"),
                         _sigma(msg.twist.covariance, "state_estimate.twist.covariance"))


def _rotation(q: np.ndarray) -> np.ndarray:
    """The rotation matrix (3, 3) of the quaternion q = [w, x, y, z] (body -> frame)."""
    norm = float(np.sqrt(q @ q))
    if not (math.isfinite(norm) and abs(norm - 1.0) <= QUATERNION_NORM_TOL):
        raise InputRejected(
            f"state_estimate.pose.pose.orientation is not a unit quaternion (norm {norm:.6g}): "
            "it is needed to rotate the twist from child_frame_id into header.frame_id")
    w, x, y, z = q / norm
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _sigma(cov, field: str) -> float | None:
    """RMS 1-sigma sqrt(trace / 3) of the linear block of a 6 x 6 row-major covariance; None
    when it is not given (all zeros, or -1 first as sensor_msgs marks an unknown one)."""
    c = np.asarray(cov, dtype=float)
    if not c.any() or c[0] == -1.0:
        return None
    block = c.reshape(6, 6)[:3, :3]
    if not np.all(np.isfinite(block)):
        raise InputRejected(f"{field} has non-finite entries in its linear block")
    if np.min(np.linalg.eigvalsh(0.5 * (block + block.T))) <= 0.0:
        raise InputRejected(f"{field} is not positive definite on its linear block "
                            f"(diagonal {np.diag(block).tolist()})")
    return float(np.sqrt(np.trace(block) / 3.0))


def state_to_odometry(pos_m, vel_m_s, stamp_s: float, frame_id: str) -> Odometry:
    msg = Odometry()
    msg.header = Header(stamp=s_to_stamp(stamp_s), frame_id=frame_id)
    msg.child_frame_id = "spacecraft"
    msg.pose.pose.position.x, msg.pose.pose.position.y, msg.pose.pose.position.z = map(float, pos_m)
    msg.pose.pose.orientation.w = 1.0
    msg.twist.twist.linear.x, msg.twist.twist.linear.y, msg.twist.twist.linear.z = map(float, vel_m_s)
    return msg


def schedule_frame(plan: Plan, frame_id: str) -> str:
    """The frame a plan's schedule is given in: the node's, or its RTN axes ("<frame>_rtn")."""
    return f"{frame_id}_rtn" if plan.thrust_rtn else frame_id


def plan_to_joint_trajectory(plan: Plan, frame_id: str, from_s: float | None = None) -> JointTrajectory:
    """One point per remaining stage: thrust [N] in ``effort``, stage start in
    ``time_from_start`` relative to ``header.stamp`` (= the plan epoch, or ``from_s``)."""
    t0 = plan.epoch_s if from_s is None else from_s
    msg = JointTrajectory()
    msg.header = Header(stamp=s_to_stamp(t0), frame_id=frame_id)
    msg.joint_names = list(JOINT_NAMES)
    for start, end, u in zip(plan.start_times_s, plan.end_times_s, plan.thrust_n):
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


def mass_estimate(mass_kg: float, stamp_s: float, frame_id: str) -> InertiaStamped:
    """A mass estimate [kg] as ``mass_estimate`` takes it (msg_docs/mass_estimate.md)."""
    msg = InertiaStamped()
    msg.header = Header(stamp=s_to_stamp(stamp_s), frame_id=frame_id)
    msg.inertia.m = float(mass_kg)
    return msg


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


def diagnostics(level: Level, message: str, values: dict, stamp_s: float, node_fqn: str,
                kind: str = "replan") -> DiagnosticArray:
    """One DiagnosticStatus named "<node's fully qualified name>: <kind>" (kind ``replan``
    for events, ``health`` for the periodic status), hardware_id the node's name: namespaced
    instances are told apart."""
    st = DiagnosticStatus(level=LEVELS[level], name=f"{node_fqn}: {kind}", message=message[:500],
                          hardware_id=node_fqn)
    st.values = [KeyValue(key=str(k), value=str(v)) for k, v in values.items()]
    arr = DiagnosticArray()
    arr.header = Header(stamp=s_to_stamp(stamp_s))
    arr.status = [st]
    return arr
