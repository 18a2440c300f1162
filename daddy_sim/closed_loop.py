"""The closed GNC loop without the ROS graph (ROS-free): a truth simulator flown against a link
to guidance, in-process (``DirectLink``: the node's re-plan policy and planner, called directly)
or over topics (``demo.RosLink``). ``fly`` runs one transfer; the demo, the campaigns and the
reliability campaign drive it."""
from __future__ import annotations

import time

import numpy as np

from daddy_core.errors import DaddyError

from daddy_ros.checks import InputRejected
from daddy_ros.config import TriggerConfig, bundled_plan
from daddy_ros.feedback import FeedbackLaws
from daddy_ros.planner import GuidancePlanner
from daddy_ros.self_trigger import Reason, ReplanTrigger
from .sim import T0_S, TruthSim


class DirectLink:
    """Guidance called in-process (Monte Carlo mode): the node's re-plan policy
    (``ReplanTrigger``) and planner, without the graph. With ``self_replan`` off, as in the
    node, nothing re-plans: the nominal plan is flown open loop."""

    def __init__(self, planner: GuidancePlanner, policy: TriggerConfig):
        self.planner = planner
        self.trigger = ReplanTrigger.for_planner(planner, policy)
        self.laws = FeedbackLaws.for_planner(planner, policy)
        self.served: list = []   # the stage-boundary re-plans a feedback law served instead

    def estimate(self, pos, vel, mass, t_s, rid):
        """An estimate, as the node takes it: (reason, level, latency s) of the re-plan it
        triggered, or None (also when a feedback law served it: ``served``)."""
        if self.trigger is None:
            return None
        plan = self.planner.plan
        reason = self.trigger.observe(t_s, pos, vel, mass, plan)
        if reason is None:
            return None
        self.trigger.replanned(t_s, pos, vel, mass)
        if reason is Reason.STAGE and self.laws is not None:
            served = self.laws.serve(plan, t_s, pos, vel, mass)
            if served is not None:
                self.served.append(served)
                return None
        t0 = time.perf_counter()
        try:
            level = self.planner.replan(pos, vel, mass, t_s, rid, now_s=t_s).level
        except InputRejected as exc:
            level = f"ERROR {exc}"
        return reason, level, time.perf_counter() - t0

    def thrust_at(self, t_s, pos, vel, mass):
        plan = self.planner.plan
        return plan.thrust_at(t_s) if plan else np.zeros(3)

    def truth(self, pos, vel, mass, t_s) -> None:
        """The simulator's true state (in-process: nobody to tell)."""

    def stage_starts(self) -> np.ndarray:
        plan = self.planner.plan
        return plan.start_times_s if plan else np.zeros(0)


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
    times (``flown_m``, (K, 3) m, and ``flown_v_m_s``, at ``times_s``, (K,) s on the mission
    clock), each
    estimate's navigation error (``nav_error_si``: (K - 1, 2) |estimate - truth| in position m
    and velocity m/s) and the thrust actually applied (``thrust_log``: (t_s, |thrust| N) from
    each piece on)."""
    N = planner.base_problem.N
    dt_stage = sim.tof_s / N
    latencies, levels, thrust_log = [], [], []
    true_pos, true_vel, _ = sim.truth_si()
    flown, flown_v, times, nav = [true_pos], [true_vel], [sim.t_s], []
    triggered = 0
    link.truth(*sim.truth_si(), sim.t_s)
    link.estimate(*sim.estimate_si(), sim.t_s, "start")   # starts the policy's prediction
    for j, (t0, t1) in enumerate(flight_steps(
            sim.t_s, N, dt_stage, substeps, policy.arrival_stages,
            final_substeps or substeps, policy.arrival_min_step)):
        pos, vel, mass = sim.estimate_si()   # (of the truth at t0: the last flown state)
        nav.append((np.linalg.norm(pos - flown[-1]), np.linalg.norm(vel - flown_v[-1])))
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
            link.truth(*sim.truth_si(), sim.t_s)
        true_pos, true_vel, _ = sim.truth_si()
        flown.append(true_pos)
        flown_v.append(true_vel)
        times.append(sim.t_s)
    miss_r, miss_v = sim.miss()
    m_final = sim.truth_si()[2]
    return {"miss_km": miss_r / 1e3, "miss_cm_s": miss_v * 100, "final_mass_kg": m_final,
            "deviation_si": sim.deviation_si(),
            "replans": len(latencies), "triggered": triggered,
            "laws_served": len(getattr(link, "served", ())),
            "law_eval_ms": [1e3 * s.evaluation_s for s in getattr(link, "served", ())],
            "latency_ms": [1e3 * x for x in latencies],
            "levels": levels, "flown_m": np.array(flown),
            "flown_v_m_s": np.array(flown_v), "times_s": np.array(times),
            "nav_error_si": np.array(nav), "thrust_log": np.array(thrust_log)}


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
            raise DaddyError(f"{case}: open-loop solve failed: {out.reason}")
        plan = out.plan
    return planner, float(plan.states_si[-1, 6])
