"""Spinning rclpy nodes: a guarded spin loop and a node spun on its own executor thread.

One single-threaded executor per node: rclpy's multi-threaded executor busy-polls, taking CPU
the solver worker needs.
"""
from __future__ import annotations

import signal
import sys
import threading
from collections.abc import Callable
from typing import Protocol

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from daddy_core.errors import DaddyError


def spin_guarded(executor, stop: threading.Event, on_error=None) -> None:
    """spin_once until ``stop`` is set or rclpy shuts down. A callback that raises is logged
    (and passed to ``on_error``) instead of ending the loop: a failing callback must not end
    guidance."""
    while not stop.is_set() and rclpy.ok():
        try:
            executor.spin_once(timeout_sec=0.05)
        except Exception as exc:  # noqa: BLE001
            if stop.is_set() or not rclpy.ok():
                return
            rclpy.logging.get_logger("daddy_guidance").error(
                f"callback raised {type(exc).__name__}: {exc}")
            if on_error is not None:
                on_error(exc)


class SpinThread:
    """A node spun by its own single-threaded executor in a daemon thread (in-process use:
    demo, tests, tools, the service helper). ``shutdown()`` stops and joins the thread before
    the executor is shut down, so no rclpy call is in flight when nodes are destroyed."""

    def __init__(self, node: Node):
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(node)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, daemon=True,
                                        name=f"spin_{node.get_name()}")
        self._thread.start()

    def _spin(self) -> None:
        spin_guarded(self.executor, self._stop)

    def shutdown(self, timeout_sec: float = 2.0) -> None:
        self._stop.set()
        self._thread.join(timeout_sec)
        self.executor.shutdown(timeout_sec=timeout_sec)


class ServedNode(Protocol):
    """What ``run_node`` needs of a node: rclpy's Node, a helper node for a blocking service
    (or None), a way to stop its worker, and where an escaped callback error is reported."""

    service_node: Node | None

    def stop(self) -> None: ...

    def report_internal_error(self, exc: BaseException) -> None: ...

    def destroy_node(self) -> None: ...


def run_node(node_factory: Callable[[], ServedNode], args=None) -> int:
    """Spin a node with our own SIGINT/SIGTERM handling and a clean shutdown sequence; 2 when
    the node cannot be built (a bad parameter: the message on stderr).

    The node's callbacks run on a single-threaded executor; a blocking service hosted on
    ``node.service_node`` gets its own executor thread so it never stalls the subscriptions.
    The ROS environment (discovery range, domain) is the caller's: nothing is set here."""
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    try:
        node = node_factory()
    except DaddyError as exc:   # a bad parameter (unknown scenario, unreadable plan file, ...)
        print(f"guidance_node: {exc}", file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    side = node.service_node
    side_executor = SpinThread(side) if side is not None else None
    try:
        spin_guarded(executor, stop, node.report_internal_error)
    finally:
        node.stop()
        for ex in (executor, side_executor):
            if ex is not None:
                ex.shutdown(timeout_sec=2.0)
        node.destroy_node()
        if side is not None:
            side.destroy_node()
        rclpy.try_shutdown()
    return 0
