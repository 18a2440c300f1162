"""Dispersion campaigns (ROS-free): many closed-loop runs of one transfer under drawn
navigation, execution and initial-state errors and missed-thrust events, each an independent
task for any ``concurrent.futures`` executor (a process pool, or Dask's ``Client.get_executor``
on a cluster: ``campaign_executors``).

A campaign is data: ``CampaignConfig``, read from a JSON or YAML file whose sections are the
dataclasses below (``CampaignConfig.from_dict`` names the field of every error; the defaults
reproduce ``make monte-carlo``). ``run_one(config, seed)`` flies one transfer with the node's
re-plan policy and planner called in-process (``closed_loop.DirectLink``) and always returns a
``RunRecord`` -- a run that raises is a failed record with the error's text, never a lost
campaign. ``run_campaign`` streams the records as they finish; ``campaign_results`` writes them
to a JSON Lines file and summarises it.

Random streams: the navigation and execution errors of a run come from ``TruthSim``'s stream
of ``seed`` (as in every earlier Monte Carlo: the same seed flies the same errors), the
initial-state and missed-thrust draws from a second stream of the same seed, so adding a
dispersion leaves the others' draws unchanged.
"""
from __future__ import annotations

import concurrent.futures
import enum
import json
import math
import os
import socket
import statistics
import time
import traceback
from dataclasses import MISSING, asdict, dataclass, fields
from pathlib import Path

import numpy as np

from daddy_core.catalogue import load_case
from daddy_core.dynamics.units import CARTESIAN_SYSTEMS
from daddy_core.errors import DaddyError

from daddy_ros.config import TriggerConfig, option
from .sim import T0_S, Errors, TruthSim


class CampaignError(DaddyError):
    """A campaign file, results file or executor request that cannot be used; the message
    names the field."""


# ---------------------------------------------------------------------------------------------
# The campaign file's sections


@dataclass(frozen=True)
class Navigation:
    """Navigation errors on every published estimate, 1 sigma per axis."""

    position_m: float = option(Errors.nav_pos_m, "position [m]", bounds=(0.0, 1e12))
    velocity_m_s: float = option(Errors.nav_vel_m_s, "velocity [m/s]", bounds=(0.0, 1e6))


@dataclass(frozen=True)
class Execution:
    """Thrust execution errors on every flown piece, 1 sigma."""

    magnitude: float = option(Errors.exec_mag, "relative thrust magnitude", bounds=(0.0, 1.0))
    pointing_deg: float = option(Errors.exec_point_deg, "pointing [deg]", bounds=(0.0, 180.0))


@dataclass(frozen=True)
class InitialState:
    """Dispersion of the true departure state about the case's, 1 sigma per axis (guidance
    starts from the nominal plan and sees it in the first estimates)."""

    position_m: float = option(0.0, "position [m]", bounds=(0.0, 1e12))
    velocity_m_s: float = option(0.0, "velocity [m/s]", bounds=(0.0, 1e6))


@dataclass(frozen=True)
class MissedThrust:
    """An engine outage in a run, with this probability: the engine does not fire for
    ``duration_hours`` from a start drawn uniformly in ``start_fraction`` of the time of
    flight; guidance is not told (it sees the drift). A range [low, high] is drawn uniformly,
    a single number is fixed."""

    probability: float = option(0.0, "chance of one outage per run", bounds=(0.0, 1.0))
    start_fraction: tuple = option((0.1, 0.9), "outage start, fraction of the time of flight",
                                   bounds=(0.0, 1.0))
    duration_hours: tuple = option((24.0, 24.0), "outage duration [h]", bounds=(0.0, 1e6))


@dataclass(frozen=True)
class Guidance(TriggerConfig):
    """The node's re-plan policy (``TriggerConfig``, the node's own parameters and defaults)
    and the planner settings a campaign varies."""

    arrival_tolerance_m: float = option(300.0, "terminal position tolerance of the arrival "
                                               "phase [m] (node parameter arrival_tolerance_m)",
                                        bounds=(0.0, 1e9))
    time_budget_s: float = option(60.0, "wall-clock budget of one re-optimisation [s]",
                                  bounds=(1e-3, 86_400.0))

    @property
    def policy(self) -> TriggerConfig:
        return TriggerConfig(**{f.name: getattr(self, f.name) for f in fields(TriggerConfig)})


@dataclass(frozen=True)
class Simulation:
    """The closed loop's time grid (``closed_loop.flight_steps``)."""

    substeps: int = option(2, "estimates per stage", bounds=(1, 10_000))
    final_substeps: int = option(8, "estimates per stage in the arrival phase",
                                 bounds=(1, 10_000))


@dataclass(frozen=True)
class Success:
    """A run succeeds when it arrives within both miss limits and spends no more than this
    fraction of propellant above or below the open-loop optimum."""

    miss_km: float = option(1.0, "terminal position miss limit [km]", bounds=(0.0, 1e12))
    miss_cm_s: float = option(1.0, "terminal velocity miss limit [cm/s]", bounds=(0.0, 1e12))
    propellant_fraction: float = option(0.01, "propellant deviation limit, fraction of the "
                                              "open-loop optimum's", bounds=(0.0, 1e6))

    def met(self, miss_km: float, miss_cm_s: float, propellant_kg: float,
            propellant_open_loop_kg: float) -> bool:
        return (miss_km <= self.miss_km and miss_cm_s <= self.miss_cm_s
                and abs(propellant_kg - propellant_open_loop_kg)
                <= self.propellant_fraction * propellant_open_loop_kg)


_SECTIONS = {"navigation": Navigation, "execution": Execution, "initial_state": InitialState,
             "missed_thrust": MissedThrust, "guidance": Guidance, "simulation": Simulation,
             "success": Success}


@dataclass(frozen=True)
class CampaignConfig:
    """A whole campaign: the case, the seeds and one instance of each section."""

    case: str = "halo_l2_l1"
    seeds: tuple = tuple(range(1, 101))
    navigation: Navigation = Navigation()
    execution: Execution = Execution()
    initial_state: InitialState = InitialState()
    missed_thrust: MissedThrust = MissedThrust()
    guidance: Guidance = Guidance()
    simulation: Simulation = Simulation()
    success: Success = Success()

    @property
    def errors(self) -> Errors:
        return Errors(self.navigation.position_m, self.navigation.velocity_m_s,
                      self.execution.magnitude, self.execution.pointing_deg)

    def to_dict(self) -> dict:
        """The campaign file's form (seeds as {first, count} when consecutive)."""
        d = {"case": self.case, "seeds": _seeds_to_data(self.seeds)}
        for name in _SECTIONS:
            d[name] = {k: list(v) if isinstance(v, tuple) else v
                       for k, v in asdict(getattr(self, name)).items()}
        return d

    def experiment(self) -> dict:
        """Everything but the seeds: what two results files must share to be merged."""
        d = self.to_dict()
        d.pop("seeds")
        return d

    @classmethod
    def from_dict(cls, data, where: str = "campaign") -> "CampaignConfig":
        """A validated config from the file's form; missing fields take their defaults.
        Raises CampaignError naming the field ("campaign.guidance.time_budget_s: ...")."""
        if not isinstance(data, dict):
            raise CampaignError(f"{where}: expected a mapping with the keys case, seeds, "
                                f"{', '.join(_SECTIONS)}; got {type(data).__name__}")
        known = ("case", "seeds", *_SECTIONS)
        for key in data:
            if key not in known:
                raise CampaignError(f"{where}.{key}: unknown field (known: {', '.join(known)})")
        case = data.get("case", cls.case)
        mission = check_case(case, f"{where}.case").closed_loop   # its own section defaults
        for name in mission:
            if name not in _SECTIONS:
                raise CampaignError(f"case {case!r}: closed_loop.{name}: unknown section "
                                    f"(known: {', '.join(_SECTIONS)})")
        kw = {}
        for name, sec in _SECTIONS.items():
            given = data.get(name, {})
            if not isinstance(given, dict):
                raise CampaignError(f"{where}.{name}: expected a mapping, got "
                                    f"{type(given).__name__}")
            if name in mission:   # the case's values, each field the file gives overriding
                _section(sec, mission[name], f"case {case!r}: closed_loop.{name}")
            if name in data or name in mission:
                kw[name] = _section(sec, {**mission.get(name, {}), **given}, f"{where}.{name}")
        if "seeds" in data:
            kw["seeds"] = _seeds_from_data(data["seeds"], f"{where}.seeds")
        return cls(case=case, **kw)


def load_config(path) -> CampaignConfig:
    """A campaign file: JSON (``.json``) or YAML (``.yaml``/``.yml``, PyYAML: installed with
    ROS 2 and with the campaigns extra)."""
    return CampaignConfig.from_dict(read_config_data(path), where=Path(path).name)


def read_config_data(path) -> dict:
    """A campaign file's mapping, as written (``load_config`` validates it)."""
    p = Path(path)
    try:
        text = p.read_text()
    except OSError as exc:
        raise CampaignError(f"campaign file {p}: {exc.strerror}") from None
    if p.suffix in (".yaml", ".yml"):
        try:
            import yaml
        except ImportError:
            raise CampaignError(f"campaign file {p}: YAML needs PyYAML (pip install pyyaml, "
                                "or write the campaign as .json)") from None
        try:
            data = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise CampaignError(f"campaign file {p}: not YAML: {exc}") from None
    else:
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise CampaignError(f"campaign file {p}: not JSON: {exc}") from None
    return data if data is not None else {}


def _section(cls, data, where: str):
    """One section from its mapping: known keys only, each value of its default's type within
    the field's bounds."""
    if not isinstance(data, dict):
        raise CampaignError(f"{where}: expected a mapping, got {type(data).__name__}")
    by_name = {f.name: f for f in fields(cls)}
    kw = {}
    for key, value in data.items():
        f = by_name.get(key)
        if f is None:
            raise CampaignError(f"{where}.{key}: unknown field (known: {', '.join(by_name)})")
        kw[key] = _value(f, value, f"{where}.{key}")
    return cls(**kw)


def _value(f, v, where: str):
    default = f.default if f.default is not MISSING else None
    lo, hi = f.metadata.get("bounds") or (-math.inf, math.inf)
    if isinstance(default, bool):
        if not isinstance(v, bool):
            raise CampaignError(f"{where}: must be true or false, got {v!r}")
        return v
    if isinstance(default, tuple):   # a range [low, high] or one number
        pair = v if isinstance(v, (list, tuple)) else [v, v]
        if len(pair) != 2:
            raise CampaignError(f"{where}: must be a number or a range [low, high], got {v!r}")
        a, b = (_number(x, lo, hi, where, float) for x in pair)
        if a > b:
            raise CampaignError(f"{where}: range low {a} is above high {b}")
        return (a, b)
    return _number(v, lo, hi, where, int if isinstance(default, int) else float)


def _number(v, lo, hi, where: str, kind):
    ok = isinstance(v, int) if kind is int else isinstance(v, (int, float))
    if isinstance(v, bool) or not ok or not math.isfinite(v):
        what = "an integer" if kind is int else "a finite number"
        raise CampaignError(f"{where}: must be {what}, got {v!r}")
    if not lo <= v <= hi:
        raise CampaignError(f"{where}: must be in [{lo:g}, {hi:g}], got {v!r}")
    return kind(v)


def _seeds_from_data(v, where: str) -> tuple:
    if isinstance(v, dict):
        unknown = set(v) - {"first", "count"}
        if unknown:
            raise CampaignError(f"{where}.{sorted(unknown)[0]}: unknown field (known: first, "
                                "count)")
        first = _number(v.get("first", 1), 0, 2**63, f"{where}.first", int)
        count = _number(v.get("count", 100), 1, 10**9, f"{where}.count", int)
        return tuple(range(first, first + count))
    if isinstance(v, list) and v:
        seeds = tuple(_number(s, 0, 2**63, f"{where}[{i}]", int) for i, s in enumerate(v))
        if len(set(seeds)) != len(seeds):
            raise CampaignError(f"{where}: a seed is listed twice")
        return seeds
    raise CampaignError(f"{where}: must be {{first, count}} or a non-empty list of integers, "
                        f"got {v!r}")


def _seeds_to_data(seeds: tuple):
    if seeds and seeds == tuple(range(seeds[0], seeds[0] + len(seeds))):
        return {"first": seeds[0], "count": len(seeds)}
    return list(seeds)


def check_case(name, where: str):
    """A catalogue case (or case file) the truth simulator can fly: Cartesian states with a
    spacecraft; returns it loaded (``catalogue.Case``)."""
    if not isinstance(name, str):
        raise CampaignError(f"{where}: must be a case name, got {name!r}")
    try:
        case = load_case(name)
    except DaddyError as exc:
        raise CampaignError(f"{where}: {exc}") from None
    if case.spacecraft is None or case.units.name not in CARTESIAN_SYSTEMS:
        raise CampaignError(f"{where}: {name!r} cannot be flown by the closed loop (it needs "
                            "Cartesian states and a spacecraft)")
    return case


# ---------------------------------------------------------------------------------------------
# One run


class RunStatus(str, enum.Enum):
    COMPLETED = "completed"   # flown to the end; ``success`` says whether it met the criteria
    FAILED = "failed"         # raised (``error`` has the last line of its traceback)

    __str__ = str.__str__


@dataclass(frozen=True)
class Dispersion:
    """The per-run draws beside the navigation and execution errors (module docstring)."""

    initial_offset_si: tuple = (0.0,) * 6          # (6,) departure state - case's [m, m/s]
    outage_s: tuple | None = None                  # (start after departure, duration) [s]

    @classmethod
    def draw(cls, config: CampaignConfig, seed: int, tof_s: float) -> "Dispersion":
        rng = np.random.default_rng([seed, 1])
        ini, mt = config.initial_state, config.missed_thrust
        offset = np.concatenate([rng.normal(scale=ini.position_m, size=3),
                                 rng.normal(scale=ini.velocity_m_s, size=3)])
        happens = rng.random() < mt.probability
        start = rng.uniform(*mt.start_fraction) * tof_s
        duration = rng.uniform(*mt.duration_hours) * 3600.0
        return cls(tuple(float(x) for x in offset),
                   (float(start), float(duration)) if happens else None)

    def to_dict(self) -> dict:
        return {"initial_position_m": list(self.initial_offset_si[:3]),
                "initial_velocity_m_s": list(self.initial_offset_si[3:]),
                "missed_thrust_s": list(self.outage_s) if self.outage_s else None}

    @classmethod
    def from_dict(cls, d: dict) -> "Dispersion":
        out = d.get("missed_thrust_s")
        return cls(tuple(d["initial_position_m"]) + tuple(d["initial_velocity_m_s"]),
                   tuple(out) if out else None)


@dataclass(frozen=True)
class RunRecord:
    """One run's outcome (SI and the units in the names). A failed run has the error's text
    and no flight figures (NaN)."""

    seed: int
    status: RunStatus
    success: bool = False
    miss_km: float = math.nan
    miss_cm_s: float = math.nan
    final_mass_kg: float = math.nan
    propellant_kg: float = math.nan
    replans: int = 0
    drift_replans: int = 0
    latency_ms: tuple = ()                 # every re-plan's wall time, in flight order
    deviation_si: tuple = ()               # the terminal position [m] and velocity [m/s] off target
    laws_served: int = 0                   # stage boundaries a feedback law served (no re-plan)
    law_eval_ms: tuple = ()                # each served law's evaluation time
    wall_s: float = 0.0
    cpu_s: float = 0.0
    dispersion: Dispersion | None = None
    error: str = ""
    worker: str = ""                       # host:pid that ran it

    def outcome(self) -> tuple:
        """What the run did, without what it cost or where it ran (timings, latencies, worker):
        equal for the same config and seed on any executor."""
        return (self.seed, self.status, self.success, self.miss_km, self.miss_cm_s,
                self.final_mass_kg, self.propellant_kg, self.replans, self.drift_replans,
                self.laws_served, self.dispersion, self.error)

    @property
    def latency_ms_median(self) -> float:
        return statistics.median(self.latency_ms) if self.latency_ms else math.nan

    @property
    def latency_ms_max(self) -> float:
        return max(self.latency_ms) if self.latency_ms else math.nan

    def line(self) -> str:
        """One line for a progress log."""
        if self.status is RunStatus.FAILED:
            return f"seed {self.seed}: FAILED {self.error}"
        outage = self.dispersion.outage_s if self.dispersion else None
        return (f"seed {self.seed}: miss {self.miss_km:.3f} km {self.miss_cm_s:.2f} cm/s, "
                f"propellant {self.propellant_kg:.3f} kg, {self.replans} re-plans "
                f"({self.drift_replans} on drift)"
                + (f", {self.laws_served} by feedback laws" if self.laws_served else "")
                + (f", outage {outage[1] / 3600:.1f} h" if outage else ""))

    def to_json(self) -> dict:
        """The results file's record (NaN as null; the latency statistics included for
        readers of the file, recomputed from the list when read back)."""
        d = {"type": "run", "seed": self.seed, "status": self.status.value,
             "success": self.success}
        for k in ("miss_km", "miss_cm_s", "final_mass_kg", "propellant_kg"):
            v = getattr(self, k)
            d[k] = None if math.isnan(v) else v
        d.update(replans=self.replans, drift_replans=self.drift_replans,
                 latency_ms_median=_or_none(self.latency_ms_median),
                 latency_ms_max=_or_none(self.latency_ms_max),
                 latency_ms=[round(x, 3) for x in self.latency_ms],
                 deviation_si=[float(x) for x in self.deviation_si],
                 laws_served=self.laws_served,
                 law_eval_ms=[round(x, 5) for x in self.law_eval_ms],
                 wall_s=round(self.wall_s, 3), cpu_s=round(self.cpu_s, 3),
                 dispersion=self.dispersion.to_dict() if self.dispersion else None,
                 error=self.error, worker=self.worker)
        return d

    @classmethod
    def from_json(cls, d: dict) -> "RunRecord":
        nan = (lambda v: math.nan if v is None else float(v))
        return cls(seed=int(d["seed"]), status=RunStatus(d["status"]),
                   success=bool(d["success"]), miss_km=nan(d.get("miss_km")),
                   miss_cm_s=nan(d.get("miss_cm_s")), final_mass_kg=nan(d.get("final_mass_kg")),
                   propellant_kg=nan(d.get("propellant_kg")), replans=int(d.get("replans", 0)),
                   drift_replans=int(d.get("drift_replans", 0)),
                   latency_ms=tuple(float(x) for x in d.get("latency_ms", ())),
                   deviation_si=tuple(float(x) for x in d.get("deviation_si") or ()),
                   laws_served=int(d.get("laws_served", 0)),
                   law_eval_ms=tuple(float(x) for x in d.get("law_eval_ms", ())),
                   wall_s=float(d.get("wall_s", 0.0)), cpu_s=float(d.get("cpu_s", 0.0)),
                   dispersion=(Dispersion.from_dict(d["dispersion"])
                               if d.get("dispersion") else None),
                   error=str(d.get("error", "")), worker=str(d.get("worker", "")))

    @classmethod
    def failed(cls, seed: int, error: str, **kw) -> "RunRecord":
        return cls(seed=seed, status=RunStatus.FAILED, error=error, **kw)


def _or_none(v: float):
    return None if math.isnan(v) else v


def error_text(exc: BaseException) -> str:
    """The last line of an exception's traceback ("ValueError: ...")."""
    return traceback.format_exception_only(type(exc), exc)[-1].strip()


def flight_record(config: CampaignConfig, seed: int, flight: dict,
                  propellant_open_loop_kg: float, wet_mass_kg: float,
                  dispersion: Dispersion | None = None, **kw) -> RunRecord:
    """The record of a completed ``closed_loop.fly`` (its result dict), judged by the
    campaign's success criteria; ``kw``: wall_s, cpu_s, worker."""
    propellant = wet_mass_kg - flight["final_mass_kg"]
    return RunRecord(
        seed=seed, status=RunStatus.COMPLETED,
        success=config.success.met(flight["miss_km"], flight["miss_cm_s"], propellant,
                                   propellant_open_loop_kg),
        miss_km=flight["miss_km"], miss_cm_s=flight["miss_cm_s"],
        final_mass_kg=flight["final_mass_kg"], propellant_kg=propellant,
        replans=flight["replans"], drift_replans=flight["triggered"],
        latency_ms=tuple(flight["latency_ms"]), laws_served=flight["laws_served"],
        deviation_si=tuple(float(x) for x in flight["deviation_si"]),
        law_eval_ms=tuple(flight["law_eval_ms"]), dispersion=dispersion, **kw)


def run_one(config: CampaignConfig, seed: int) -> RunRecord:
    """One closed-loop transfer with this seed's draws (module docstring). Never raises for
    what happens inside the run: a failure is a record."""
    from .closed_loop import DirectLink, fly, nominal_planner
    t_wall, t_cpu = time.perf_counter(), time.process_time()
    worker = f"{socket.gethostname()}:{os.getpid()}"
    dispersion = None
    try:
        g = config.guidance
        planner, m_open = nominal_planner(config.case, g.time_budget_s, g.arrival_tolerance_m)
        case = planner.case
        dispersion = Dispersion.draw(config, seed, case.tof * case.units.tu_s)
        outage = dispersion.outage_s
        sim = TruthSim(config.case, config.errors, seed=seed, t0_s=T0_S,
                       initial_offset_si=np.array(dispersion.initial_offset_si),
                       outage_s=(T0_S + outage[0], T0_S + outage[0] + outage[1])
                       if outage else None)
        r = fly(DirectLink(planner, g.policy), sim, planner, g.policy,
                config.simulation.substeps, config.simulation.final_substeps)
        m0 = case.spacecraft.wet_mass_kg
        return flight_record(config, seed, r, m0 - m_open, m0, dispersion,
                             wall_s=time.perf_counter() - t_wall,
                             cpu_s=time.process_time() - t_cpu, worker=worker)
    except Exception as exc:   # noqa: BLE001 -- every failure of a run is recorded, not raised
        return RunRecord.failed(seed, error_text(exc), dispersion=dispersion,
                                wall_s=time.perf_counter() - t_wall,
                                cpu_s=time.process_time() - t_cpu, worker=worker)


def run_campaign(config: CampaignConfig, seeds, executor: concurrent.futures.Executor):
    """Submit one ``run_one`` per seed to ``executor`` and yield each ``RunRecord`` as it
    finishes (completion order). A task the executor itself lost (a worker process killed,
    a cluster gone) is yielded as a failed record too. Closing the iterator early cancels the
    runs not yet started."""
    futures = {executor.submit(run_one, config, s): s for s in seeds}
    try:
        for fut in concurrent.futures.as_completed(futures):
            try:
                yield fut.result()
            except Exception as exc:   # noqa: BLE001 -- the executor's failure, recorded
                yield RunRecord.failed(futures[fut], f"executor: {error_text(exc)}")
    finally:
        for fut in futures:
            fut.cancel()
