"""Spinning rclpy nodes: a guarded spin loop and a node spun on its own executor thread.

One single-threaded executor per node: rclpy's multi-threaded executor busy-polls, taking CPU
the solver worker needs.
"""
from __future__ import annotations

import threading

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node


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
