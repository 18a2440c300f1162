"""Recording a run as ROS 2 messages in an MCAP file (the format of rosbag2's default storage,
readable by ``ros2 bag``, Foxglove and the ``mcap`` tools).

``McapRecorder`` subscribes to topics in their serialised form (rclpy ``raw=True``: the CDR
bytes as they crossed the middleware, no deserialisation) and writes each message with its
topic's ``ros2msg`` schema -- the message definition with its dependencies, assembled from the
``.msg`` files of the installed message packages (``message_definition``), as rosbag2 does.
Each channel carries its topic's QoS as rosbag2's ``offered_qos_profiles`` (``qos_yaml``), so
``ros2 bag play`` offers the latched plan topics transient local again and a late subscriber
gets the plan; a ``rosbag2`` metadata record names the ROS distribution.
Needs the ``record`` extra (``mcap``; ``mcap-ros2-support`` to decode a file in Python).
"""
from __future__ import annotations

import os
import re
import sys
import threading
import time
from pathlib import Path

from daddy_core.errors import DaddyError

from daddy_ros.spin import SpinThread

_PRIMITIVES = {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16",
               "uint16", "int32", "uint32", "int64", "uint64", "string", "wstring"}
_SEPARATOR = "=" * 80


def type_name(msg_type) -> str:
    """``pkg/msg/Type`` of a generated rclpy message class."""
    module = msg_type.__module__.split(".")   # e.g. nav_msgs.msg._odometry
    return f"{module[0]}/msg/{msg_type.__name__}"


def _msg_file(pkg: str, name: str) -> Path:
    """The installed ``pkg/msg/name.msg``: from the ament index (a sourced ROS 2 install), else
    this interpreter's prefix (the registry's ROS 2 wheels install ``share/`` into the venv)."""
    roots = []
    try:
        from ament_index_python.packages import get_package_share_directory
        roots.append(Path(get_package_share_directory(pkg)))
    except (ImportError, LookupError, OSError):   # no index, or the package not in it
        pass
    roots.append(Path(sys.prefix) / "share" / pkg)
    for root in roots:
        path = root / "msg" / f"{name}.msg"
        if path.exists():
            return path
    raise DaddyError(f"recording: no message definition {pkg}/msg/{name}.msg (looked in "
                     f"{', '.join(str(r) for r in roots)})")


def _dependencies(pkg: str, text: str) -> list[tuple[str, str]]:
    """(package, type) of every non-primitive field type of one .msg text, in order."""
    out = []
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        field_type = line.split()[0]      # (constants, TYPE NAME=VALUE, are primitive)
        base = re.sub(r"\[.*\]$", "", field_type)      # arrays: T[], T[3], T[<=3]
        base = re.sub(r"<=\d+$", "", base)             # bounded strings: string<=10
        if base in _PRIMITIVES:
            continue
        dep_pkg, _, dep = base.rpartition("/")
        out.append(((dep_pkg.split("/")[0] if dep_pkg else pkg), dep))
    return out


def message_definition(msg_type) -> str:
    """The ``ros2msg`` schema text of a message type: its .msg text, then each message type it
    uses (recursively, once each) after a line of 80 '=' and ``MSG: pkg/Type``."""
    pkg, _, name = type_name(msg_type).split("/")
    main = _msg_file(pkg, name).read_text()
    parts, seen, todo = [main.strip()], set(), _dependencies(pkg, main)
    while todo:
        dep = todo.pop(0)
        if dep in seen:
            continue
        seen.add(dep)
        text = _msg_file(*dep).read_text()
        parts.append(f"{_SEPARATOR}\nMSG: {dep[0]}/{dep[1]}\n{text.strip()}")
        todo.extend(_dependencies(dep[0], text))
    return "\n".join(parts) + "\n"


def qos_yaml(qos) -> str:
    """rosbag2's ``offered_qos_profiles`` of one publisher with the rclpy QoS profile ``qos``:
    a YAML list of one profile, policies as rmw's enum numbers (the form rosbag2 reads from an
    MCAP file whose ``rosbag2`` metadata record has no ``serialized_metadata``: every
    distribution since Humble reads it), durations as sec / nsec."""
    def duration(d) -> str:
        ns = d.nanoseconds
        return f"\n    sec: {ns // 1_000_000_000}\n    nsec: {ns % 1_000_000_000}"

    return (f"- history: {int(qos.history.value)}\n"
            f"  depth: {int(qos.depth)}\n"
            f"  reliability: {int(qos.reliability.value)}\n"
            f"  durability: {int(qos.durability.value)}\n"
            f"  deadline:{duration(qos.deadline)}\n"
            f"  lifespan:{duration(qos.lifespan)}\n"
            f"  liveliness: {int(qos.liveliness.value)}\n"
            f"  liveliness_lease_duration:{duration(qos.liveliness_lease_duration)}\n"
            f"  avoid_ros_namespace_conventions: "
            f"{'true' if qos.avoid_ros_namespace_conventions else 'false'}\n")


class McapRecorder:
    """Record topics of the ROS graph into an MCAP file until ``close()``.

    Args:
        path: output file (its folder is created).
        topics: {topic name: (message class, QoS profile)}; names resolve in the recorder
            node's namespace like any subscription.
    """

    def __init__(self, path: str | Path, topics: dict, node_name: str = "daddy_recorder"):
        try:
            from mcap.writer import CompressionType, Writer
        except ImportError as exc:
            raise DaddyError("recording needs the mcap package (the record extra: "
                             "pip install -r requirements/record.txt)") from exc
        from rclpy.node import Node
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(self.path, "wb")
        self._writer = Writer(self._file, compression=CompressionType.ZSTD)
        self._writer.start(profile="ros2", library="daddy")
        self._writer.add_metadata("rosbag2", {"ROS_DISTRO": os.environ.get("ROS_DISTRO",
                                                                           "jazzy")})
        self._lock = threading.Lock()
        self.counts: dict[str, int] = {}
        self.node = Node(node_name)
        for topic, (msg_type, qos) in topics.items():
            schema = self._writer.register_schema(
                name=type_name(msg_type), encoding="ros2msg",
                data=message_definition(msg_type).encode())
            resolved = self.node.resolve_topic_name(topic)
            channel = self._writer.register_channel(
                topic=resolved, message_encoding="cdr", schema_id=schema,
                metadata={"offered_qos_profiles": qos_yaml(qos)})
            self.counts[resolved] = 0
            self.node.create_subscription(
                msg_type, topic, lambda data, c=channel, t=resolved: self._write(c, t, data),
                qos, raw=True)
        self._spinner = SpinThread(self.node)

    def _write(self, channel: int, topic: str, data: bytes) -> None:
        now = time.time_ns()
        with self._lock:
            if self._writer is None:
                return
            self._writer.add_message(channel, log_time=now, data=data, publish_time=now,
                                     sequence=self.counts[topic])
            self.counts[topic] += 1

    def close(self) -> dict:
        """Stop, finish the file; returns the number of messages written per topic."""
        self._spinner.shutdown()
        with self._lock:
            self._writer.finish()
            self._writer = None
            self._file.close()
        self.node.destroy_node()
        return dict(self.counts)
