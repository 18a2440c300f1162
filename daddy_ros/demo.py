"""Closed-loop GNC demo: a truth simulator and the guidance node over real ROS 2 topics.

    gnc_demo [--case halo_l2_l1|earth_mars] [--replan-every K] [--plot FILE] [--seed S]
    gnc_demo --runs 100            # Monte Carlo, same guidance logic called directly (no graph)

The simulator is a thin client: it publishes noisy state and mass estimates on its time grid
and flies the schedule it receives with execution errors. The node decides the re-plans itself
(``self_trigger``: every K stages, on drift from its prediction, on every estimate of the
arrival phase); the Monte Carlo runs the same policy in-process. It reports the terminal miss,
the propellant against the open-loop optimum, the number of re-optimisations and their latency.
"""
from __future__ import annotations

import argparse
import concurrent.futures
import os
import statistics
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

from .checks import InputRejected
from .config import TriggerConfig, bundled_plan
from .plan import Level
from .planner import GuidancePlanner
from .self_trigger import Reason, ReplanTrigger
from .sim import T0_S, Errors, TruthSim


class DirectLink:
    """Guidance called in-process (Monte Carlo mode): the node's re-plan policy
    (``ReplanTrigger``) and planner, without the graph."""

    def __init__(self, planner: GuidancePlanner, policy: TriggerConfig):
        self.planner = planner
        self.trigger = ReplanTrigger.for_planner(planner, policy)

    def estimate(self, pos, vel, mass, t_s, rid):
        """An estimate, as the node takes it: (reason, level, latency s) of the re-plan it
        triggered, or None."""
        reason = self.trigger.observe(t_s, pos, vel, mass, self.planner.plan)
        if reason is None:
            return None
        self.trigger.replanned(t_s, pos, vel, mass)
        t0 = time.perf_counter()
        try:
            level = self.planner.replan(pos, vel, mass, t_s, rid, now_s=t_s).level
        except InputRejected as exc:
            level = f"ERROR {exc}"
        return reason, level, time.perf_counter() - t0

    def thrust_at(self, t_s, pos, vel, mass):
        plan = self.planner.plan
        return plan.thrust_at(t_s) if plan else np.zeros(3)

    def stage_starts(self) -> np.ndarray:
        plan = self.planner.plan
        return plan.start_times_s if plan else np.zeros(0)


_LEVEL_OF = {0: Level.OK, 1: Level.WARN, 2: Level.ERROR}   # DiagnosticStatus level -> Level

# a thrust command later than this after its estimate was withheld for a re-plan (a solve takes
# tens of milliseconds at least; an immediate command, ~2 ms: bench/bench_intake.py)
SELF_REPLAN_HINT_S = 0.02


class RosLink:
    """Guidance over ROS 2 topics (``client.GuidanceClient``): the GNC side of the loop
    (estimates out; thrust commands, schedules and diagnostics in)."""

    def __init__(self, frame_id: str, timeout_s: float):
        from .client import GuidanceClient
        from .conversions import stamp_to_s
        self._stamp_s = stamp_to_s
        self.client = GuidanceClient(frame_id, name="daddy_gnc_sim")
        self.node = self.client.node
        self.timeout_s = timeout_s

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
        n_diags = len(c.diags)
        t0 = time.perf_counter()
        self.publish_estimate(pos, vel, mass, t_s)
        if not c.wait_for(lambda: self._thrust_for(t_s), self.timeout_s):
            return (None, f"ERROR no thrust command for the estimate at {t_s:.3f} s",
                    time.perf_counter() - t0)
        lat = time.perf_counter() - t0
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

    def _self_replan(self, t_s, after: int):
        """(request id, (level, message, values)) of a self-triggered re-plan that started from
        the estimate at t_s, among the diagnostics from index ``after`` on."""
        from .client import status_of
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


def flight_steps(t0_s: float, N: int, dt_stage: float, substeps: int, final_stages: int,
                 final_substeps: int, final_min_step: float):
    """The closed loop's time grid, the times of its estimates: (start s, end s) per step.

    Stages are flown in ``substeps`` steps; the last ``final_stages`` in steps of a stage /
    ``final_substeps``, and the remaining time is halved from there on down to
    ``final_min_step`` (a fraction of a stage): the arrival phase, where the node re-plans at
    every estimate (``self_trigger``), so the last open-loop interval is short.
    """
    for stage in range(N - final_stages):
        for i in range(substeps):
            yield (t0_s + (stage + i / substeps) * dt_stage,
                   t0_s + (stage + (i + 1) / substeps) * dt_stage)
    t, t_end = t0_s + (N - final_stages) * dt_stage, t0_s + N * dt_stage
    fine, shortest = dt_stage / final_substeps, final_min_step * dt_stage
    while t_end - t > shortest * (1 + 1e-9):
        rem = t_end - t
        step = fine if rem > 2 * fine * (1 + 1e-9) else rem / 2
        yield t, t + step
        t += step
    yield t, t_end


def fly(link, sim: TruthSim, planner: GuidancePlanner, policy: TriggerConfig, substeps: int,
        final_substeps: int = 0, progress=None) -> dict:
    """Run the closed loop to the end of the transfer: an estimate to ``link`` at each step of
    ``flight_steps`` (its arrival phase from ``policy``), which re-plans where ``policy`` says
    (in the node, or in-process for a ``DirectLink``); the schedule is flown piecewise constant
    between its stage starts. Returns the run's figures, the flown positions at the grid's
    times (``flown_m``, (K, 3) m) and the thrust actually applied (``thrust_log``: (t_s,
    |thrust| N) from each piece on)."""
    N = planner.base_problem.N
    dt_stage = sim.tof_s / N
    latencies, levels, flown, thrust_log = [], [], [sim.truth_si()[0]], []
    triggered = 0
    link.estimate(*sim.estimate_si(), sim.t_s, "start")   # starts the policy's prediction
    for j, (t0, t1) in enumerate(flight_steps(
            sim.t_s, N, dt_stage, substeps, policy.arrival_stages,
            final_substeps or substeps, policy.arrival_min_step)):
        pos, vel, mass = sim.estimate_si()
        out = link.estimate(pos, vel, mass, t0, f"r{j}")
        if out is not None:
            reason, level, lat = out
            latencies.append(lat)
            levels.append(level)
            triggered += reason == Reason.DRIFT
            if progress:
                progress(f"  t = {(t0 - sim.t0_s) / 86400:7.3f} d  stage "
                         f"{int((t0 - sim.t0_s) / dt_stage + 1e-9):3d}/{N}  replan {level:5s} "
                         f"{lat * 1e3:8.1f} ms  ({reason})")
        starts = link.stage_starts()
        cuts = [t0, *starts[(starts > t0 + 1e-6) & (starts < t1 - 1e-6)], t1]
        for a, b in zip(cuts[:-1], cuts[1:]):
            thrust = link.thrust_at(a, pos, vel, mass)
            applied = sim.apply(thrust, b - a)
            thrust_log.append((a, float(np.linalg.norm(applied))))
        flown.append(sim.truth_si()[0])
    miss_r, miss_v = sim.miss()
    m_final = sim.truth_si()[2]
    return {"miss_km": miss_r / 1e3, "miss_cm_s": miss_v * 100, "final_mass_kg": m_final,
            "replans": len(latencies), "triggered": triggered,
            "latency_ms": [1e3 * x for x in latencies],
            "levels": levels, "flown_m": np.array(flown), "thrust_log": np.array(thrust_log)}


def nominal_planner(case: str, time_budget_s: float,
                    arrival_tolerance_m: float = 0.0) -> tuple[GuidancePlanner, float]:
    """A planner holding the open-loop optimum at T0 (bundled plan or a cold solve)."""
    planner = GuidancePlanner(case, time_budget_s=time_budget_s,
                              arrival_tolerance_m=arrival_tolerance_m)
    plan_file = bundled_plan(case)
    sim = TruthSim(case, t0_s=T0_S)
    if plan_file is not None:
        plan = planner.load_plan(plan_file, T0_S)
    else:
        p, v, m = sim.truth_si()
        out = planner.replan(p, v, m, T0_S, "nominal", cold=True)
        if not out.ok:
            raise SystemExit(f"open-loop solve failed: {out.reason}")
        plan = out.plan
    return planner, float(plan.states_si[-1, 6])


def summarise(runs: list[dict], m_open: float, m0: float) -> dict:
    prop_open = m0 - m_open
    ok = [r for r in runs if r["miss_km"] <= 1.0 and r["miss_cm_s"] <= 1.0
          and abs((m0 - r["final_mass_kg"]) - prop_open) <= 0.01 * prop_open]
    lat = [x for r in runs for x in r["latency_ms"]]
    return {"runs": len(runs), "success": len(ok), "success_rate": len(ok) / max(len(runs), 1),
            "miss_km_median": statistics.median(r["miss_km"] for r in runs),
            "miss_km_max": max(r["miss_km"] for r in runs),
            "miss_cm_s_median": statistics.median(r["miss_cm_s"] for r in runs),
            "miss_cm_s_max": max(r["miss_cm_s"] for r in runs),
            "propellant_open_loop_kg": prop_open,
            "propellant_median_kg": statistics.median(m0 - r["final_mass_kg"] for r in runs),
            "latency_ms_median": statistics.median(lat) if lat else float("nan"),
            "latency_ms_max": max(lat) if lat else float("nan"),
            "replans_per_run": statistics.mean(r["replans"] for r in runs)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="gnc_demo", description=__doc__.splitlines()[0])
    ap.add_argument("--case", default="halo_l2_l1", choices=["halo_l2_l1", "earth_mars", "dro_dro"])
    ap.add_argument("--runs", type=int, default=0, help="Monte Carlo runs without the ROS graph")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1,
                    help="Monte Carlo runs in parallel worker processes (default: one per core)")
    policy = TriggerConfig()   # the node's defaults
    ap.add_argument("--replan-every", type=int, default=policy.replan_every_stages,
                    help="stages between the node's re-optimisations (0: every 5 %% of the "
                         "stages; node parameter replan_every_stages)")
    ap.add_argument("--substeps", type=int, default=2, help="simulation steps per stage")
    ap.add_argument("--final-stages", type=int, default=policy.arrival_stages,
                    help="the arrival phase, where every estimate re-plans (arrival_stages)")
    ap.add_argument("--final-substeps", type=int, default=8,
                    help="simulation steps (estimates) per stage in the arrival phase")
    ap.add_argument("--final-min-step", type=float, default=policy.arrival_min_step,
                    help="shortest final step (fraction of a stage): the remaining time is "
                         "halved at each estimate down to it (arrival_min_step)")
    ap.add_argument("--trigger-km", type=float, default=policy.trigger_position_m / 1e3,
                    help="the node also re-plans when the estimate drifts this far from its "
                         "prediction (0: off; trigger_position_m)")
    ap.add_argument("--trigger-cm-s", type=float, default=policy.trigger_velocity_m_s * 100,
                    help="... or this fast (0: off; trigger_velocity_m_s)")
    ap.add_argument("--arrival-tolerance-km", type=float, default=0.3,
                    help="in the arrival phase the guidance targets the velocity exactly and the "
                         "position within this distance (node parameter arrival_tolerance_m)")
    ap.add_argument("--time-budget", type=float, default=60.0)
    ap.add_argument("--no-errors", action="store_true", help="perfect navigation and execution")
    ap.add_argument("--plot", default="out/gnc_demo.png", help="PNG of flown vs planned")
    ap.add_argument("--record", metavar="FILE.mcap", default="",
                    help="record every topic of the ROS run to an MCAP file (the record extra)")
    args = ap.parse_args(argv)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"  # the demo stays on loopback
    errors = Errors(0, 0, 0, 0) if args.no_errors else Errors()
    print(f"closed-loop GNC demo: {args.case}, navigation errors {errors.nav_pos_m} m / "
          f"{errors.nav_vel_m_s * 1e3} mm/s, execution errors {errors.exec_mag:.0%} / "
          f"{errors.exec_point_deg} deg (1 sigma)", flush=True)
    planner, m_open = nominal_planner(args.case, args.time_budget, args.arrival_tolerance_km * 1e3)
    args.replan_every = args.replan_every or max(1, planner.base_problem.N // 20)
    m0 = planner.case.spacecraft.wet_mass_kg
    print(f"open-loop optimum: final mass {m_open:.3f} kg", flush=True)
    if args.runs:
        runs = []
        seeds = [args.seed + i for i in range(args.runs)]
        jobs = max(1, min(args.jobs, args.runs))
        with concurrent.futures.ProcessPoolExecutor(jobs) as pool:
            for i, r in enumerate(pool.map(_monte_carlo_run, [(args, errors, s) for s in seeds])):
                runs.append(r)
                print(f"run {i + 1:3d} seed {seeds[i]}: miss {r['miss_km']:.3f} km "
                      f"{r['miss_cm_s']:.2f} cm/s, final mass {r['final_mass_kg']:.3f} kg, "
                      f"{r['replans']} replans ({r['triggered']} on drift)", flush=True)
        _print_summary(summarise(runs, m_open, m0))
        return 0
    return _ros_demo(args, planner, errors, m_open, m0)


def _monte_carlo_run(job) -> dict:
    """One closed-loop run without the ROS graph (a worker process of the Monte Carlo)."""
    args, errors, seed = job
    pl, _ = nominal_planner(args.case, args.time_budget, args.arrival_tolerance_km * 1e3)
    sim = TruthSim(args.case, errors, seed=seed, t0_s=T0_S)
    settings = _loop_settings(args)
    r = fly(DirectLink(pl, settings["policy"]), sim, pl, **settings)
    r.pop("flown_m")
    r.pop("thrust_log")
    return r


def _loop_settings(args) -> dict:
    """fly()'s time grid and the node's re-plan policy from the command line."""
    policy = TriggerConfig(replan_every_stages=args.replan_every,
                           trigger_position_m=args.trigger_km * 1e3,
                           trigger_velocity_m_s=args.trigger_cm_s / 100,
                           arrival_stages=args.final_stages,
                           arrival_min_step=args.final_min_step)
    return {"policy": policy, "substeps": args.substeps, "final_substeps": args.final_substeps}


def _ros_demo(args, planner, errors, m_open, m0) -> int:
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    from .guidance_node import GuidanceNode
    from .spin import SpinThread
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    settings = _loop_settings(args)
    guidance = GuidanceNode(scenario=args.case, time_budget_s=args.time_budget,
                            arrival_tolerance_m=args.arrival_tolerance_km * 1e3,
                            **asdict(settings["policy"]))
    recorder = None
    if args.record:   # before anything is published: the recorder sees the whole run
        from .recording import McapRecorder
        recorder = McapRecorder(args.record, guidance.interface_topics())
    guidance.adopt_plan(planner.plan)            # the nominal plan, anchored at T0
    link = RosLink(guidance.frame_id, timeout_s=3 * args.time_budget + 30)
    spinner = SpinThread(guidance)
    try:
        if not link.wait_connected():
            print("ROS graph did not connect on loopback", flush=True)
            return 1
        sim = TruthSim(args.case, errors, seed=args.seed, t0_s=T0_S)
        r = fly(link, sim, guidance.planner, progress=lambda s: print(s, flush=True),
                **settings)
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
    s = summarise([r], m_open, m0)
    _print_summary(s)
    print(f"re-optimisations: {r['replans']} ({sum(1 for x in r['levels'] if x == 'OK')} OK), "
          f"coalesced triggers: {guidance.coalesced}")
    if args.plot:
        try:
            plot_closed_loop(r, planner.plan, args.plot)
            print(f"plot: {args.plot}")
        except ImportError:
            print("plot skipped: matplotlib not installed (the plots extra; make demo installs it)")
    return 0


def _print_summary(s: dict) -> None:
    print(f"terminal miss: {s['miss_km_median']:.3f} km (max {s['miss_km_max']:.3f}), "
          f"{s['miss_cm_s_median']:.3f} cm/s (max {s['miss_cm_s_max']:.3f})")
    print(f"propellant: {s['propellant_median_kg']:.3f} kg vs open-loop optimum "
          f"{s['propellant_open_loop_kg']:.3f} kg")
    print(f"re-optimisation latency: median {s['latency_ms_median']:.1f} ms, max "
          f"{s['latency_ms_max']:.1f} ms; {s['replans_per_run']:.1f} per run")
    print(f"success (<= 1 km, <= 1 cm/s, propellant within 1 %): {s['success']}/{s['runs']} "
          f"({s['success_rate']:.0%})")


def plot_closed_loop(r: dict, plan, path) -> None:
    """PNG of a closed-loop run against the open-loop ``plan`` it started from: the flown and
    planned trajectories (x-y, km, the case's frame) and the thrust magnitude actually applied
    (execution errors included) and planned, over days since departure.

    Raises ImportError without matplotlib (the plots extra)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.5))
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
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(main())
