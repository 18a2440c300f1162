"""Spinning rclpy nodes: a guarded spin loop, a node spun on its own executor thread, and the
awaitable pause with which coroutine callbacks wait for the solver worker.

One single-threaded executor per node: rclpy's multi-threaded executor busy-polls, taking CPU
the solver worker needs. A callback that waits for a solve (the Trigger service, the Replan
action) is a coroutine that awaits ``pause`` between looks at the worker, so the estimates are
served meanwhile.
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
from rclpy.task import Future

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


async def pause(node: Node, seconds: float) -> None:
    """Await ``seconds`` in a coroutine callback of ``node``: its executor serves the other
    callbacks meanwhile (a one-shot timer completes the future)."""
    done = Future()
    timer = node.create_timer(seconds, lambda: done.done() or done.set_result(None))
    try:
        await done
    finally:
        node.destroy_timer(timer)


class SpinThread:
    """A node spun by its own single-threaded executor in a daemon thread (in-process use:
    demo, tests, tools). ``shutdown()`` stops and joins the thread before
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
    """What ``run_node`` needs of a node: rclpy's Node, a way to stop its worker, where an
    escaped callback error is reported, and ``when_finalized``, which it calls when its
    lifecycle reaches finalized (the process then exits)."""

    when_finalized: Callable[[], None] | None

    def stop(self) -> None: ...

    def report_internal_error(self, exc: BaseException) -> None: ...

    def destroy_node(self) -> None: ...


def run_node(node_factory: Callable[[], ServedNode], args=None) -> int:
    """Spin a node with our own SIGINT/SIGTERM handling and a clean shutdown sequence; 2 when
    the node cannot be built (a bad parameter: the message on stderr).

    The node's callbacks run on a single-threaded executor; the process exits on SIGINT or
    SIGTERM, or once the node's lifecycle is finalized (its shutdown transition). The ROS
    environment (discovery range, domain) is the caller's: nothing is set here."""
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
    node.when_finalized = stop.set
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    try:
        spin_guarded(executor, stop, node.report_internal_error)
    finally:
        node.stop()
        executor.shutdown(timeout_sec=2.0)
        node.destroy_node()
        rclpy.try_shutdown()
    return 0
