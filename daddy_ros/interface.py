"""The node's interface in one table: every topic it reads or writes (the parameter naming it,
its default name, message type, QoS, direction), its service and its node name. The node, the
client and the recorder all read it; msg_docs/ documents it.
"""
from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import InertiaStamped, Vector3Stamped
from nav_msgs.msg import Odometry
from nav_msgs.msg import Path as PathMsg
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy,
                       qos_profile_sensor_data)
from std_msgs.msg import Header
from trajectory_msgs.msg import JointTrajectory

from .config import NodeConfig

NODE_NAME = "daddy_guidance"
REPLAN_SERVICE = "~/replan"   # std_srvs/Trigger
# the plan's outputs: the last one stays available to late subscribers
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL, history=HistoryPolicy.KEEP_LAST)
RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                      history=HistoryPolicy.KEEP_LAST)


class Direction(Enum):
    IN = "in"     # the node subscribes
    OUT = "out"   # the node publishes


@dataclass(frozen=True)
class Topic:
    """One topic of the node: ``parameter`` names it (None: a fixed name), ``default`` is its
    name by default; ``qos`` is what the node uses (a client publishing to an input may use
    RELIABLE: sensor-data subscriptions accept it)."""

    parameter: str | None
    msg_type: type
    qos: QoSProfile
    direction: Direction
    fixed_name: str = ""

    @property
    def default(self) -> str:
        """The topic's name by default (``config.NodeConfig``: the one parameter table)."""
        if self.parameter is None:
            return self.fixed_name
        return NodeConfig.__dataclass_fields__[self.parameter].default


STATE = Topic("state_topic", Odometry, qos_profile_sensor_data, Direction.IN)
MASS = Topic("mass_topic", InertiaStamped, qos_profile_sensor_data, Direction.IN)
REQUEST = Topic("request_topic", Header, RELIABLE, Direction.IN)
SCHEDULE = Topic("schedule_topic", JointTrajectory, LATCHED, Direction.OUT)
PATH = Topic("path_topic", PathMsg, LATCHED, Direction.OUT)
THRUST = Topic("thrust_topic", Vector3Stamped, RELIABLE, Direction.OUT)
DIAGNOSTICS = Topic(None, DiagnosticArray, RELIABLE, Direction.OUT, "/diagnostics")

TOPICS = (STATE, MASS, REQUEST, SCHEDULE, PATH, THRUST, DIAGNOSTICS)
