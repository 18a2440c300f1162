"""Closed-loop GNC demo: a truth simulator and the guidance node over real ROS 2 topics.

    gnc_demo [--case halo_l2_l1|earth_mars] [--replan-every K] [--plot FILE] [--seed S]
    gnc_demo --runs 100            # Monte Carlo, same guidance logic called directly (no graph):
                                   # a daddy_campaign campaign of the demo's settings, results in
                                   # out/gnc_demo_runs.jsonl (daddy_campaign summary / plot)

The simulator is a thin client: it publishes noisy state and mass estimates on its time grid
and flies the schedule it receives with execution errors. The node decides the re-plans itself
(``self_trigger``: every K stages, on drift from its prediction, on every estimate of the
arrival phase); the Monte Carlo runs the same policy in-process. It reports the terminal miss,
the propellant against the open-loop optimum, the number of re-optimisations and their latency.
"""
from __future__ import annotations

import argparse
import os
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

from .campaign_cli import cores, run_and_report
from .campaign_executors import Executor
from .campaign_results import Header, Results, ResultsWriter, format_summary, summarise
from .campaigns import CampaignConfig, CampaignError, Guidance, Simulation, flight_record
from .closed_loop import fly, nominal_planner
from daddy_ros.plan import Level
from daddy_ros.self_trigger import Reason
from .sim import T0_S, TruthSim


_LEVEL_OF = {0: Level.OK, 1: Level.WARN, 2: Level.ERROR}   # DiagnosticStatus level -> Level

# a thrust command later than this after its estimate was withheld for a re-plan (a solve takes
# tens of milliseconds at least; an immediate command, ~2 ms: bench/bench_intake.py)
SELF_REPLAN_HINT_S = 0.02


def truth_topics() -> dict:
    """The simulator's true state, published beside the node's topics (and recorded):
    {topic: (message class, QoS)}; the state as ``nav_msgs/Odometry`` in the node's frame
    (position m, velocity m/s, as the estimates), the mass as ``geometry_msgs/InertiaStamped``
    [kg], stamped with the simulation's time after every flown piece."""
    from geometry_msgs.msg import InertiaStamped
    from nav_msgs.msg import Odometry

    from daddy_ros.interface import RELIABLE
    return {"/truth/state": (Odometry, RELIABLE), "/truth/mass": (InertiaStamped, RELIABLE)}


class RosLink:
    """Guidance over ROS 2 topics (``client.GuidanceClient``): the GNC side of the loop
    (estimates and the simulator's truth out; thrust commands, schedules and diagnostics
    in)."""

    def __init__(self, frame_id: str, timeout_s: float):
        from daddy_ros.client import GuidanceClient
        from daddy_ros.conversions import stamp_to_s
        self._stamp_s = stamp_to_s
        self.client = GuidanceClient(frame_id, name="daddy_gnc_sim")
        self.node = self.client.node
        self.frame_id = frame_id
        self.timeout_s = timeout_s
        self.served: list = []   # stage boundaries the node served by a feedback law
        (state, qos), (mass, qos_m) = truth_topics().values()
        self._truth_state = self.node.create_publisher(state, "/truth/state", qos)
        self._truth_mass = self.node.create_publisher(mass, "/truth/mass", qos_m)

    def truth(self, pos, vel, mass, t_s) -> None:
        """Publish the simulator's true state (``truth_topics``)."""
        from daddy_ros import conversions as cv
        self._truth_state.publish(cv.state_to_odometry(pos, vel, t_s, self.frame_id))
        self._truth_mass.publish(cv.mass_estimate(mass, t_s, self.frame_id))

    def publish_estimate(self, pos, vel, mass, t_s):
        self.client.publish_estimate(pos, vel, mass, t_s)

    def wait_connected(self, timeout_s=15.0):
        """Poll (never a fixed sleep) until the guidance node subscribes to our topics and its
        latched schedule has reached us."""
        c = self.client
        return bool(c.wait_for(lambda: c.schedules and c.pub_state.get_subscription_count()
                               and c.pub_req.get_subscription_count()
                               and c.pub_mass.get_subscription_count(), timeout_s))

    def estimate(self, pos, vel, mass, t_s, rid):
        """Publish an estimate and wait for its thrust command: the node withholds it while a
        re-plan the estimate triggered runs (``self_trigger``), so the simulated loop flies on
        only once guidance has answered. (reason, level, latency s) of that re-plan, or None.
        ``rid`` is unused: the node names its own re-plans."""
        c = self.client
        n_diags, n_schedules = len(c.diags), len(c.schedules)
        t0 = time.perf_counter()
        self.publish_estimate(pos, vel, mass, t_s)
        if not c.wait_for(lambda: self._thrust_for(t_s), self.timeout_s):
            return (None, f"ERROR no thrust command for the estimate at {t_s:.3f} s",
                    time.perf_counter() - t0)
        lat = time.perf_counter() - t0
        # a law's command is not withheld; at a stage boundary its event (on its own topic)
        # may still be on its way
        if np.any(np.abs(self.stage_starts() - t_s) < 1e-3):
            c.wait_for(lambda: self._law(t_s, n_diags) or self._self_replan(t_s, n_diags),
                       SELF_REPLAN_HINT_S * 10)
        law = self._law(t_s, n_diags)
        if law is not None:   # the stage flies the law: its re-published schedule holds it
            self.served.append(law)
            c.wait_for(lambda: len(c.schedules) > n_schedules, self.timeout_s)
            return None
        # a withheld command took a solve (>= tens of ms); the re-plan's diagnostic was
        # published before it: allow it a moment to arrive on its own topic
        wait = 0.5 if lat > SELF_REPLAN_HINT_S else 0.0
        diag = c.wait_for(lambda: self._self_replan(t_s, n_diags), wait) or \
            self._self_replan(t_s, n_diags)
        if not diag:
            return None
        rid_self, (level, text, vals) = diag
        if vals.get("plan_kept") == "no":   # its schedule is stamped with the estimate time
            c.wait_for(lambda: (c.latest_schedule() or (-np.inf,))[0] >= t_s - 1e-3,
                       self.timeout_s)
        return Reason(rid_self.split("-")[1]), _LEVEL_OF.get(level, f"ERROR {text}"), lat

    def request(self, pos, vel, mass, t_s, rid):
        """An external re-plan request (``replan_request``) from this estimate; waits for its
        diagnostic and, when a new plan was stored, for its schedule: (level, latency s)
        (bench_replan's trigger -> schedule latency)."""
        c = self.client
        self.publish_estimate(pos, vel, mass, t_s)
        time.sleep(0.02)  # let the estimate arrive before the request (same reliable link)
        t0 = time.perf_counter()
        n_diags = len(c.diags)
        c.request(rid, t_s)
        diag = c.wait_for(lambda: c.diag_for(rid, n_diags), self.timeout_s)
        level, text, vals = diag or (None, "timeout", {})
        if vals.get("plan_kept") == "no":
            c.wait_for(lambda: (c.latest_schedule() or (-np.inf,))[0] >= t_s - 1e-3,
                       max(0.0, self.timeout_s - (time.perf_counter() - t0)))
        return _LEVEL_OF.get(level, f"ERROR {text}"), time.perf_counter() - t0

    def _thrust_for(self, t_s) -> bool:
        with self.client.cond:
            recent = [m for _, m in self.client.thrust[-5:]]
        return any(abs(self._stamp_s(m.header.stamp) - t_s) < 1e-6 for m in recent)

    def _law(self, t_s, after: int):
        """The ``FEEDBACK_LAW`` event of the estimate at t_s (a ``feedback.Served``-like record
        with its ``evaluation_s``), among the diagnostics from index ``after`` on, or None."""
        from types import SimpleNamespace

        from daddy_ros.client import status_of
        for _, m in self.client.diags[after:]:
            for st in m.status:
                vals = status_of(st)[2]
                if vals.get("code") == "FEEDBACK_LAW" and \
                        vals.get("request_id") == f"law-{t_s:.3f}":
                    return SimpleNamespace(evaluation_s=float(vals["evaluation_s"]))
        return None

    def _self_replan(self, t_s, after: int):
        """(request id, (level, message, values)) of a self-triggered re-plan that started from
        the estimate at t_s, among the diagnostics from index ``after`` on."""
        from daddy_ros.client import status_of
        for _, m in self.client.diags[after:]:
            for st in m.status:
                level, text, vals = status_of(st)
                rid = vals.get("request_id", "")
                if rid.startswith("self-") and abs(float(vals.get("state_stamp_s", "nan"))
                                                    - t_s) < 1e-6:
                    return rid, (level, text, vals)
        return None

    def thrust_at(self, t_s, pos, vel, mass):
        sched = self.client.latest_schedule()
        if sched is None:
            return np.zeros(3)
        stamp, starts, u = sched
        rel = t_s - stamp
        k = int(np.searchsorted(starts, rel + 1e-6, side="right")) - 1
        return u[k].copy() if 0 <= k < len(u) else np.zeros(3)

    def stage_starts(self) -> np.ndarray:
        sched = self.client.latest_schedule()
        return np.zeros(0) if sched is None else sched[0] + np.asarray(sched[1])

    def close(self) -> None:
        self.client.close()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="gnc_demo", description=__doc__.splitlines()[0])
    ap.add_argument("--case", default="halo_l2_l1", choices=["halo_l2_l1", "earth_mars", "dro_dro"])
    ap.add_argument("--runs", type=int, default=0, help="Monte Carlo runs without the ROS graph")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--jobs", type=int, default=cores(),
                    help="Monte Carlo runs in parallel worker processes (default: one per core)")
    policy, sim_defaults = Guidance(), Simulation()   # the node's and the campaigns' defaults
    ap.add_argument("--replan-every", type=int, default=policy.replan_every_stages,
                    help="stages between the node's re-optimisations (0: every 5 %% of the "
                         "stages; node parameter replan_every_stages)")
    ap.add_argument("--substeps", type=int, default=sim_defaults.substeps,
                    help="simulation steps per stage")
    ap.add_argument("--final-stages", type=int, default=policy.arrival_stages,
                    help="the arrival phase, where every estimate re-plans (arrival_stages)")
    ap.add_argument("--final-substeps", type=int, default=sim_defaults.final_substeps,
                    help="simulation steps (estimates) per stage in the arrival phase")
    ap.add_argument("--final-min-step", type=float, default=policy.arrival_min_step,
                    help="shortest final step (fraction of a stage): the remaining time is "
                         "halved at each estimate down to it (arrival_min_step)")
    ap.add_argument("--trigger-km", type=float, default=policy.trigger_position_m / 1e3,
                    help="the node also re-plans when the estimate drifts this far from its "
                         "prediction (0: off; trigger_position_m)")
    ap.add_argument("--trigger-cm-s", type=float, default=policy.trigger_velocity_m_s * 100,
                    help="... or this fast (0: off; trigger_velocity_m_s)")
    ap.add_argument("--arrival-tolerance-km", type=float,
                    default=policy.arrival_tolerance_m / 1e3,
                    help="in the arrival phase the guidance targets the velocity exactly and the "
                         "position within this distance (node parameter arrival_tolerance_m)")
    ap.add_argument("--time-budget", type=float, default=policy.time_budget_s)
    ap.add_argument("--no-errors", action="store_true", help="perfect navigation and execution")
    ap.add_argument("--plot", default="out/gnc_demo.png", help="PNG of flown vs planned")
    ap.add_argument("--record", metavar="FILE.mcap", default="",
                    help="record every topic of the ROS run to an MCAP file (the record extra)")
    ap.add_argument("--results", default="out/gnc_demo_runs.jsonl",
                    help="--runs: the campaign's results file (replaced; daddy_campaign "
                         "summary/plot read it)")
    args = ap.parse_args(argv)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"  # the demo stays on loopback
    planner, m_open = nominal_planner(args.case, args.time_budget, args.arrival_tolerance_km * 1e3)
    try:
        config = campaign_config(args, planner.base_problem.N)
    except CampaignError as exc:
        ap.error(str(exc))
    e = config.errors
    print(f"closed-loop GNC demo: {args.case}, navigation errors {e.nav_pos_m} m / "
          f"{e.nav_vel_m_s * 1e3} mm/s, execution errors {e.exec_mag:.0%} / "
          f"{e.exec_point_deg} deg (1 sigma)", flush=True)
    header = Header(config, m_open, planner.case.spacecraft.wet_mass_kg)
    print(f"open-loop optimum: final mass {m_open:.3f} kg", flush=True)
    if args.runs:
        writer = ResultsWriter.create(args.results, header, overwrite=True)
        results = run_and_report(writer, config, Executor.LOCAL, args.jobs)
        return 0 if results is not None else 130
    return _ros_demo(args, config, planner, header)


def campaign_config(args, stages: int) -> CampaignConfig:
    """The command line as a campaign (the ROS run is the campaign's first seed; ``--runs``
    flies the rest in-process): errors, the node's re-plan policy and the loop's time grid.
    Validated as a campaign file is (CampaignError names the field)."""
    zero = {"position_m": 0.0, "velocity_m_s": 0.0}
    return CampaignConfig.from_dict({
        "case": args.case,
        "seeds": {"first": args.seed, "count": max(args.runs, 1)},
        "navigation": zero if args.no_errors else {},
        "execution": {"magnitude": 0.0, "pointing_deg": 0.0} if args.no_errors else {},
        "guidance": {"replan_every_stages": args.replan_every or max(1, stages // 20),
                     "trigger_position_m": args.trigger_km * 1e3,
                     "trigger_velocity_m_s": args.trigger_cm_s / 100,
                     "arrival_stages": args.final_stages,
                     "arrival_min_step": args.final_min_step,
                     "arrival_tolerance_m": args.arrival_tolerance_km * 1e3,
                     "time_budget_s": args.time_budget},
        "simulation": {"substeps": args.substeps, "final_substeps": args.final_substeps},
    }, where="gnc_demo")


def _ros_demo(args, config: CampaignConfig, planner, header: Header) -> int:
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    from daddy_ros.guidance_node import GuidanceNode
    from daddy_ros.spin import SpinThread
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    g = config.guidance
    guidance = GuidanceNode(scenario=config.case, time_budget_s=g.time_budget_s,
                            arrival_tolerance_m=g.arrival_tolerance_m, **asdict(g.policy))
    recorder = None
    if args.record:   # before anything is published: the recorder sees the whole run
        from .recording import McapRecorder
        recorder = McapRecorder(args.record, {**guidance.interface_topics(), **truth_topics()})
    guidance.adopt_plan(planner.plan)            # the nominal plan, anchored at T0
    link = RosLink(guidance.frame_id, timeout_s=3 * args.time_budget + 30)
    spinner = SpinThread(guidance)
    try:
        if not link.wait_connected():
            print("ROS graph did not connect on loopback", flush=True)
            return 1
        sim = TruthSim(config.case, config.errors, seed=config.seeds[0], t0_s=T0_S)
        t_wall, t_cpu = time.perf_counter(), time.process_time()
        r = fly(link, sim, guidance.planner, g.policy, config.simulation.substeps,
                config.simulation.final_substeps, progress=lambda s: print(s, flush=True))
    finally:
        if recorder is not None:
            counts = recorder.close()
            print(f"recorded {sum(counts.values())} messages to {args.record}: "
                  + ", ".join(f"{t} {n}" for t, n in counts.items()), flush=True)
        guidance.stop()
        spinner.shutdown(timeout_sec=2.0)
        link.close()
        guidance.destroy_node()
        rclpy.try_shutdown()
    record = flight_record(config, config.seeds[0], r, header.propellant_open_loop_kg,
                           header.wet_mass_kg, wall_s=time.perf_counter() - t_wall,
                           cpu_s=time.process_time() - t_cpu)   # the node's solves included
    print(format_summary(summarise(Results(header, (record,))), header))
    print(f"re-optimisations: {r['replans']} ({sum(1 for x in r['levels'] if x == 'OK')} OK), "
          f"coalesced triggers: {guidance.coalesced}")
    if args.plot:
        try:
            plot_closed_loop(r, planner.plan, args.plot)
            print(f"plot: {args.plot}")
        except ImportError:
            print("plot skipped: matplotlib not installed (the plots extra; make demo installs it)")
    return 0


def plot_closed_loop(r: dict, plan, path) -> None:
    """PNG of a closed-loop run against the open-loop ``plan`` it started from: the flown and
    planned trajectories (x-y, km, the case's frame), the thrust magnitude actually applied
    (execution errors included) and planned, and the flown minus planned position and velocity
    at the plan's nodes beside each estimate's navigation error, over days since departure.

    Raises ImportError without matplotlib (the plots extra)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig, (a1, a2, a3) = plt.subplots(1, 3, figsize=(16, 4.6))
    exp3 = max(0, 3 * int(np.log10(np.max(np.abs(plan.states_si[:, :2])) / 1e3) // 3))
    scale = 1e3 * 10.0 ** exp3   # km, 10^3 km or 10^6 km: short tick labels
    unit = "km" if exp3 == 0 else f"$10^{exp3}$ km"
    p = plan.states_si[:, :3] / scale
    a1.plot(p[:, 0], p[:, 1], "--", label="open-loop plan")
    f = r["flown_m"] / scale
    a1.plot(f[:, 0], f[:, 1], label="flown")
    a1.plot(f[-1, 0], f[-1, 1], "r*", label="arrival")
    a1.set_xlabel(f"x [{unit}]")
    a1.set_ylabel(f"y [{unit}]")
    a1.axis("equal")
    a1.legend()
    day = 86400.0
    start = plan.stage_start_s
    thrust = np.linalg.norm(plan.thrust_n, axis=1)
    a2.step(np.append(start, plan.end_s - plan.epoch_s) / day, np.append(thrust, thrust[-1]),
            "--", where="post", label="open-loop plan")
    log = r["thrust_log"]
    a2.step((log[:, 0] - plan.epoch_s) / day, log[:, 1], where="post", label="applied",
            linewidth=0.8)
    a2.set_xlabel("time since departure [d]")
    a2.set_ylabel("thrust [N]")
    a2.legend()
    _deviation_panel(a3, r, plan)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plan_deviation(r: dict, plan) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """|flown - planned| at the plan's nodes the flight passed (the flight grid's times that
    are node times): (days since the plan's epoch, position km, velocity cm/s), each (K,)."""
    nodes = np.append(plan.stage_start_s, plan.end_s - plan.epoch_s) + plan.epoch_s
    t = r["times_s"]
    k = np.minimum(np.searchsorted(t, nodes - 1e-6), len(t) - 1)
    hit = np.abs(t[k] - nodes) < 1e-6
    dr = np.linalg.norm(r["flown_m"][k[hit]] - plan.states_si[hit, :3], axis=1) / 1e3
    dv = np.linalg.norm(r["flown_v_m_s"][k[hit]] - plan.states_si[hit, 3:6], axis=1) * 100
    return (nodes[hit] - plan.epoch_s) / 86400.0, dr, dv


def _deviation_panel(ax, r: dict, plan) -> None:
    """``plan_deviation`` beside each estimate's navigation error (log scales)."""
    days, dr, dv = plan_deviation(r, plan)
    nav = r["nav_error_si"]
    te = (r["times_s"][:len(nav)] - plan.epoch_s) / 86400.0
    ax.plot(te, nav[:, 0] / 1e3, ".", ms=2, color="0.7", label="navigation error, position")
    ax.plot(days, dr, "-", color="tab:blue", label="flown - planned, position")
    ax.set_yscale("log")
    ax.set_ylabel("position [km]")
    ax.set_xlabel("time since departure [d]")
    ax.set_title("deviation from the open-loop plan", fontsize=10)
    av = ax.twinx()
    av.plot(days, dv, "-", color="tab:red", lw=0.8, label="flown - planned, velocity")
    av.set_yscale("log")
    av.set_ylabel("velocity [cm/s]", color="tab:red")
    h1, l1 = ax.get_legend_handles_labels()
    h2, l2 = av.get_legend_handles_labels()
    ax.legend(h1 + h2, l1 + l2, fontsize=7, loc="lower right")


if __name__ == "__main__":
    raise SystemExit(main())
