"""Estimate intake latency of the guidance node: publish -> state callback, over Fast DDS on
loopback, with the node idle and while its worker solves back to back (Earth-Mars re-plans
requested at 4 Hz), optionally with another process keeping one core busy.

    .venv/bin/python bench/bench_intake.py [--seconds 8] [--busy-core]

The node runs in-process as ``guidance_node`` runs it (a single-threaded executor thread for
the callbacks, the solver worker thread); the client publishes 50 Hz estimates stamped on the
wall clock, and the callback's arrival time minus the stamp is the latency. It tells whether a
solve starves the node's intake (the GIL held by the worker) and what delivery allowance a
consumer of "the newest estimate" needs (test/reliability uses the node's own, 0.5 s).
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import threading
import time

import numpy as np

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"   # loopback only

FRAME = "sun_ecliptic"


def percentiles(xs) -> str:
    if not xs:
        return "no samples"
    a = np.sort(np.asarray(xs)) * 1e3
    return (f"n {a.size}, median {statistics.median(a):.1f} ms, p99 "
            f"{a[int(0.99 * (a.size - 1))]:.1f} ms, max {a[-1]:.1f} ms")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=8.0, help="length of each phase")
    ap.add_argument("--busy-core", action="store_true",
                    help="another process spins on one core during the measurement")
    args = ap.parse_args()
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    from bench_da import machine
    from daddy_ros.client import GuidanceClient
    from daddy_ros.guidance_node import GuidanceNode
    from daddy_sim.sim import TruthSim
    from daddy_ros.spin import SpinThread
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    wall0 = time.time()
    t0 = 1000.0
    arrivals = []                    # (phase, latency s)
    phase = ["idle"]
    node = GuidanceNode(scenario="earth_mars", frame_id=FRAME, time_budget_s=60.0,
                        autostart=False)
    on_state = node._on_state

    def timed(msg):                  # the subscription is made at configure: wrap it first
        stamp = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
        arrivals.append((phase[0], time.time() - (wall0 + stamp - t0)))
        on_state(msg)
    node._on_state = timed
    node.trigger_configure()
    node.trigger_activate()
    spin = SpinThread(node)
    client = GuidanceClient(FRAME, name="daddy_intake_bench")
    busy = (subprocess.Popen([sys.executable, "-c", "while True: pass"])
            if args.busy_core else None)
    stop = threading.Event()
    sim = TruthSim("earth_mars", t0_s=t0)
    pos, vel, mass = sim.truth_si()

    def estimates():
        tick = 0
        while not stop.is_set():
            stamp = t0 + (time.time() - wall0)
            client.send_mass(mass, stamp)
            client.send_state(pos, vel, stamp)
            tick += 1
            time.sleep(max(0.0, wall0 + tick / 50.0 - time.time()))
    try:
        end = time.monotonic() + 15
        while time.monotonic() < end and not client.pub_state.get_subscription_count():
            time.sleep(0.05)
        th = threading.Thread(target=estimates, daemon=True)
        th.start()
        time.sleep(1.0)              # the nominal plan is adopted at the first estimates
        arrivals.clear()
        time.sleep(args.seconds)     # idle
        phase[0] = "solving"
        n_before = node.queue.finished
        k, t_end = 0, time.monotonic() + args.seconds
        while time.monotonic() < t_end:
            client.request(f"bench-{k}", t0 + (time.time() - wall0))
            k += 1
            time.sleep(0.25)
        solves = node.queue.finished - n_before
        stop.set()
        th.join(5)
        print(f"machine: {machine()}; busy core: {'yes' if busy else 'no'}")
        for ph in ("idle", "solving"):
            print(f"{ph:8s}: publish -> state callback {percentiles([d for p, d in arrivals if p == ph])}")
        print(f"solving phase: {k} requests, {solves} solves finished")
    finally:
        if busy is not None:
            busy.kill()
        client.close()
        spin.shutdown()
        node.trigger_shutdown()
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    main()
