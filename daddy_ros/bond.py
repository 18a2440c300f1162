"""The node's side of a bond with nav2's lifecycle manager (bond_core's protocol, as nav2's
servers form it: ``nav2_util::LifecycleNode::createBond``).

Both sides publish ``bond/msg/Status`` on the topic ``bond`` (relative: the node's namespace,
where the manager is) with the bond id (the node's name) and their own instance id, every
heartbeat period. The bond forms when the sister's heartbeat arrives; it breaks when either side
publishes ``active: false`` (the other answers in kind) or when no heartbeat comes within the
heartbeat timeout. The node forms its bond when it is activated and breaks it when deactivated,
cleaned up or shut down, as nav2's servers do; a broken bond (the manager gone) is reported,
and guidance goes on: the manager's loss must not stop the spacecraft's guidance.

Needs the bond message package (a ROS 2 installation's, or interfaces/build.py's).
"""
from __future__ import annotations

import time
import uuid
from enum import Enum

try:
    from bond.msg import Status
except ImportError:   # not built: the node forms no bond
    Status = None

TOPIC = "bond"
HEARTBEAT_TIMEOUT_S = 4.0   # nav2's servers' (bond_core's DEFAULT_HEARTBEAT_TIMEOUT)
DEAD_ANSWERS = 3            # active: false messages sent when the bond breaks


def available() -> bool:
    """Whether the bond message package is importable."""
    return Status is not None


class BondState(Enum):
    WAITING = "waiting for the sister"
    FORMED = "formed"
    BROKEN = "broken"


class Bond:
    """One bond of ``node`` with id ``bond_id``, heartbeat every ``period_s``; ``on_broken``
    is called (once) with the reason when the sister breaks it or stops beating."""

    def __init__(self, node, bond_id: str, period_s: float, on_broken=None,
                 timeout_s: float = HEARTBEAT_TIMEOUT_S):
        self.node, self.id, self.period_s, self.timeout_s = node, bond_id, period_s, timeout_s
        self.instance_id = str(uuid.uuid4())
        self.on_broken = on_broken
        self.state = BondState.WAITING
        self.sister: str | None = None
        self._last_heartbeat = time.monotonic()
        self.pub = node.create_publisher(Status, TOPIC, 5)
        self.sub = node.create_subscription(Status, TOPIC, self._on_status, 100)
        self.timer = node.create_timer(period_s, self._beat)
        self._publish(True)

    def _publish(self, active: bool) -> None:
        msg = Status(id=self.id, instance_id=self.instance_id, active=active,
                     heartbeat_timeout=float(self.timeout_s), heartbeat_period=float(self.period_s))
        msg.header.stamp = self.node.get_clock().now().to_msg()
        self.pub.publish(msg)

    def _beat(self) -> None:
        if self.state is BondState.BROKEN:
            return
        if self.state is BondState.FORMED and \
                time.monotonic() - self._last_heartbeat > self.timeout_s:
            self._broken(f"no heartbeat from the lifecycle manager for {self.timeout_s:g} s")
            return
        self._publish(True)

    def _on_status(self, msg) -> None:
        if msg.id != self.id or msg.instance_id == self.instance_id:
            return   # another bond, or our own heartbeat
        if self.sister is None:
            self.sister = msg.instance_id
        if msg.instance_id != self.sister or self.state is BondState.BROKEN:
            return
        if msg.active:
            self.state = BondState.FORMED
            self._last_heartbeat = time.monotonic()
        else:
            self._broken("the lifecycle manager broke the bond")

    def _die(self) -> None:
        self.state = BondState.BROKEN
        for _ in range(DEAD_ANSWERS):   # (the acknowledgement bond_core's sister waits for)
            self._publish(False)

    def _broken(self, reason: str) -> None:
        self._die()
        if self.on_broken is not None:
            self.on_broken(reason)

    def destroy(self) -> None:
        """Break the bond (the sister sees ``active: false``) and remove its entities."""
        if self.state is not BondState.BROKEN:
            self._die()
        self.node.destroy_timer(self.timer)
        self.node.destroy_subscription(self.sub)
        self.node.destroy_publisher(self.pub)
