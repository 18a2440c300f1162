"""A campaign's results as a table: one row per run, flat columns, written as Parquet.

``COLUMNS`` is the one list of the table's columns (name, unit, meaning); docs/campaigns.md
shows it and a test holds the two together. Terminal states are in the case's own frame (the
rotating frame of a CR3BP case, the inertial frame of the central body otherwise) in SI; the
deviations also in the target's local RTN frame:

    R = r_t / |r_t|,   N = (r_t x v_t) / |r_t x v_t|,   T = N x R

with r_t, v_t the case's target state about the frame's origin (the barycentre of a CR3BP
system, the central body's centre otherwise). Cases that arrive on an orbit rather than at a
state (staged in angle) have no terminal-state columns (NaN).

The Parquet file (pyarrow, the ``analysis`` extra) carries the results header as file metadata
(key ``daddy.campaign.header``: the JSON of the JSONL file's first line) and two list columns,
every re-plan's latency and every served law's evaluation time, so that a table reads back
into the same run records (``read_table``): JSONL -> Parquet -> JSONL round-trips exactly.
"""
from __future__ import annotations

import functools
import json
import math
import statistics
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from daddy_core.dynamics.models import rtn_basis

from .campaign_results import Header, Results, Spread, read_results
from .campaigns import CampaignError, Dispersion, RunRecord, RunStatus

METADATA_KEY = b"daddy.campaign.header"
NAN = math.nan
AXES = ("x", "y", "z")
RTN = ("r", "t", "n")


@dataclass(frozen=True)
class Column:
    name: str
    unit: str
    meaning: str


COLUMNS: tuple[Column, ...] = (
    Column("seed", "", "the run's seed (its navigation, execution and dispersion draws)"),
    Column("status", "", "completed, or failed (raised; see error)"),
    Column("success", "", "met the campaign's success criteria"),
    Column("miss_km", "km", "terminal position miss"),
    Column("miss_cm_s", "cm/s", "terminal velocity miss"),
    Column("final_mass_kg", "kg", "mass at arrival"),
    Column("propellant_kg", "kg", "propellant spent"),
    Column("propellant_excess_kg", "kg", "propellant minus the open-loop optimum's"),
    *(Column(f"{a}_m", "m", f"terminal position, {a} (case frame)") for a in AXES),
    *(Column(f"v{a}_m_s", "m/s", f"terminal velocity, {a} (case frame)") for a in AXES),
    *(Column(f"d{a}_m", "m", f"terminal position minus target's, {a} (case frame)")
      for a in AXES),
    *(Column(f"dv{a}_m_s", "m/s", f"terminal velocity minus target's, {a} (case frame)")
      for a in AXES),
    *(Column(f"d{a}_rtn_m", "m", f"terminal position deviation, {a.upper()} (target's RTN)")
      for a in RTN),
    *(Column(f"dv{a}_rtn_m_s", "m/s", f"terminal velocity deviation, {a.upper()} (target's RTN)")
      for a in RTN),
    Column("replans", "", "re-plans in the flight"),
    Column("drift_replans", "", "of them triggered by drift (not by the schedule)"),
    Column("latency_ms_median", "ms", "median re-plan wall time"),
    Column("latency_ms_p95", "ms", "95th percentile (nearest rank) of the re-plan wall times"),
    Column("latency_ms_max", "ms", "longest re-plan"),
    Column("laws_served", "", "stage boundaries served by a feedback law instead of a re-plan"),
    Column("law_eval_ms_median", "ms", "median evaluation time of a served law"),
    *(Column(f"initial_d{a}_m", "m", f"drawn departure-state offset, {a} (case frame)")
      for a in AXES),
    *(Column(f"initial_dv{a}_m_s", "m/s", f"drawn departure-velocity offset, {a} (case frame)")
      for a in AXES),
    Column("outage_start_s", "s", "drawn missed-thrust start after departure (NaN: none)"),
    Column("outage_duration_s", "s", "drawn missed-thrust duration (NaN: none)"),
    Column("wall_s", "s", "the run's wall time"),
    Column("cpu_s", "s", "the run's CPU time"),
    Column("worker", "", "host:pid that ran it"),
    Column("error", "", "a failed run's error (last line of its traceback)"),
    Column("latency_ms", "ms", "list: every re-plan's wall time, in flight order"),
    Column("law_eval_ms", "ms", "list: every served law's evaluation time"),
)
NAMES = tuple(c.name for c in COLUMNS)


@functools.lru_cache(maxsize=16)
def target_state_si(case: str) -> tuple | None:
    """(6,) the case's target position [m] and velocity [m/s] in its frame; None for a case
    that arrives on an orbit (staged in angle)."""
    from daddy_core.catalogue import load_case
    c = load_case(case)
    if c.staged_in_angle:
        return None
    return tuple(float(v) for v in c.units.cartesian_si(c.x_target)[:6])


def columns(results: Results) -> dict[str, list]:
    """The table as columns (``NAMES`` order), one entry per run in file order."""
    target = target_state_si(results.header.config.case)
    # (rows R, T, N: the transpose of rtn_basis's columns)
    basis = rtn_basis(target[:3], target[3:6]).T if target is not None else None
    ref = results.header.propellant_open_loop_kg
    cols: dict[str, list] = {n: [] for n in NAMES}
    for r in results.records:
        dev = np.array(r.deviation_si) if len(r.deviation_si) == 6 else np.full(6, NAN)
        state = np.array(target) + dev if target is not None else np.full(6, NAN)
        local = (np.concatenate([basis @ dev[:3], basis @ dev[3:]]) if basis is not None
                 else np.full(6, NAN))
        disp = r.dispersion
        offset = disp.initial_offset_si if disp else (NAN,) * 6
        outage = disp.outage_s if disp and disp.outage_s else (NAN, NAN)
        row = {
            "seed": r.seed, "status": r.status.value, "success": r.success,
            "miss_km": r.miss_km, "miss_cm_s": r.miss_cm_s, "final_mass_kg": r.final_mass_kg,
            "propellant_kg": r.propellant_kg, "propellant_excess_kg": r.propellant_kg - ref,
            "replans": r.replans, "drift_replans": r.drift_replans,
            "latency_ms_median": r.latency_ms_median, "latency_ms_p95": Spread.of(r.latency_ms).p95,
            "latency_ms_max": r.latency_ms_max, "laws_served": r.laws_served,
            "law_eval_ms_median": (statistics.median(r.law_eval_ms) if r.law_eval_ms
                                   else NAN),
            "outage_start_s": outage[0], "outage_duration_s": outage[1],
            "wall_s": r.wall_s, "cpu_s": r.cpu_s, "worker": r.worker, "error": r.error,
            "latency_ms": list(r.latency_ms), "law_eval_ms": list(r.law_eval_ms)}
        for i, a in enumerate(AXES):
            row[f"{a}_m"], row[f"v{a}_m_s"] = state[i], state[3 + i]
            row[f"d{a}_m"], row[f"dv{a}_m_s"] = dev[i], dev[3 + i]
            row[f"initial_d{a}_m"], row[f"initial_dv{a}_m_s"] = offset[i], offset[3 + i]
        for i, a in enumerate(RTN):
            row[f"d{a}_rtn_m"], row[f"dv{a}_rtn_m_s"] = local[i], local[3 + i]
        for n in NAMES:
            cols[n].append(float(row[n]) if isinstance(row[n], np.floating) else row[n])
    return cols


def _pyarrow():
    try:
        import pyarrow
        import pyarrow.parquet
    except ImportError:
        raise CampaignError("Parquet needs pyarrow (the analysis extra: pip install "
                            "'daddy_ros[analysis]'; make test installs it)") from None
    return pyarrow


def _schema(pa):
    kinds = {"seed": pa.int64(), "status": pa.string(), "success": pa.bool_(),
             "replans": pa.int64(), "drift_replans": pa.int64(),
             "laws_served": pa.int64(), "worker": pa.string(), "error": pa.string(),
             "latency_ms": pa.list_(pa.float64()), "law_eval_ms": pa.list_(pa.float64())}
    return pa.schema([pa.field(c.name, kinds.get(c.name, pa.float64()),
                               metadata={b"unit": c.unit.encode(),
                                         b"meaning": c.meaning.encode()})
                      for c in COLUMNS])


def write_table(results: Results, path) -> Path:
    """Write ``results`` as a Parquet file (the header in its metadata). Raises
    CampaignError without pyarrow."""
    pa = _pyarrow()
    schema = _schema(pa).with_metadata(
        {METADATA_KEY: json.dumps(results.header.to_json()).encode()})
    table = pa.Table.from_pydict(columns(results), schema=schema)
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    pa.parquet.write_table(table, p)
    return p


def read_table(path) -> Results:
    """A Parquet file written by ``write_table`` read back into run records."""
    pa = _pyarrow()
    p = Path(path)
    try:
        table = pa.parquet.read_table(p)
    except (OSError, pa.ArrowException) as exc:
        raise CampaignError(f"results table {p}: {exc}") from None
    meta = table.schema.metadata or {}
    if METADATA_KEY not in meta:
        raise CampaignError(f"results table {p}: no campaign header in its metadata (not "
                            "written by daddy_campaign)")
    missing = [n for n in NAMES if n not in table.column_names]
    if missing:
        raise CampaignError(f"results table {p}: columns missing: {', '.join(missing)}")
    header = Header.from_json(json.loads(meta[METADATA_KEY]), f"{p}: metadata")
    return Results(header, tuple(_record(row) for row in table.to_pylist()))


def _record(row: dict) -> RunRecord:
    f = (lambda v: NAN if v is None else float(v))
    dev = tuple(f(row[f"d{a}_m"]) for a in AXES) + tuple(f(row[f"dv{a}_m_s"]) for a in AXES)
    offset = (tuple(f(row[f"initial_d{a}_m"]) for a in AXES)
              + tuple(f(row[f"initial_dv{a}_m_s"]) for a in AXES))
    outage = (f(row["outage_start_s"]), f(row["outage_duration_s"]))
    dispersion = None if any(map(math.isnan, offset)) else Dispersion(
        offset, None if any(map(math.isnan, outage)) else outage)
    return RunRecord(
        seed=int(row["seed"]), status=RunStatus(row["status"]), success=bool(row["success"]),
        miss_km=f(row["miss_km"]), miss_cm_s=f(row["miss_cm_s"]),
        final_mass_kg=f(row["final_mass_kg"]), propellant_kg=f(row["propellant_kg"]),
        replans=int(row["replans"]), drift_replans=int(row["drift_replans"]),
        latency_ms=tuple(row["latency_ms"] or ()),
        deviation_si=() if any(map(math.isnan, dev)) else dev,
        laws_served=int(row["laws_served"]), law_eval_ms=tuple(row["law_eval_ms"] or ()),
        wall_s=f(row["wall_s"]), cpu_s=f(row["cpu_s"]), dispersion=dispersion,
        error=row["error"] or "", worker=row["worker"] or "")


TABLE_SUFFIX = ".parquet"


def load_results(path) -> Results:
    """A results file of either kind: JSON Lines, or a Parquet table (by its suffix)."""
    return read_table(path) if Path(path).suffix == TABLE_SUFFIX else read_results(path)


def table_path(results_path) -> Path:
    """Where a JSONL results file's table goes: beside it, ``.parquet``."""
    return Path(results_path).with_suffix(TABLE_SUFFIX)
