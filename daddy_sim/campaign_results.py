"""A campaign's results file and its summary (ROS-free).

The file is JSON Lines: a header record (``"type": "header"``: the campaign config, the package
version, the open-loop optimum the runs are judged against), then one ``RunRecord`` per line in
the order the runs finished, each written and flushed as it arrives -- a campaign killed at any
moment leaves every finished run on disk and at most one partial last line, which reading
ignores and resuming trims. Resuming skips the seeds already recorded; files of the same
experiment (config without the seeds, same package version) merge.
"""
from __future__ import annotations

import json
import math
import statistics
from dataclasses import dataclass, field, replace
from datetime import datetime, timezone
from pathlib import Path

from .campaigns import CampaignConfig, CampaignError, RunRecord, RunStatus

FORMAT = 1
Z_95 = 1.959963984540054   # two-sided 95 % normal quantile


def package_version() -> str:
    from importlib.metadata import PackageNotFoundError, version
    try:
        return version("daddy_ros")
    except PackageNotFoundError:
        return "unknown"


@dataclass(frozen=True)
class Header:
    """What every run of the file shares."""

    config: CampaignConfig
    open_loop_final_mass_kg: float
    wet_mass_kg: float
    version: str = field(default_factory=package_version)
    created_utc: str = field(default_factory=lambda: datetime.now(timezone.utc)
                             .isoformat(timespec="seconds"))

    @property
    def propellant_open_loop_kg(self) -> float:
        return self.wet_mass_kg - self.open_loop_final_mass_kg

    def to_json(self) -> dict:
        return {"type": "header", "format": FORMAT, "package": "daddy_ros",
                "version": self.version, "created_utc": self.created_utc,
                "open_loop_final_mass_kg": self.open_loop_final_mass_kg,
                "wet_mass_kg": self.wet_mass_kg, "config": self.config.to_dict()}

    @classmethod
    def from_json(cls, d: dict, where: str) -> "Header":
        if d.get("type") != "header":
            raise CampaignError(f"{where}: the first line is not a campaign header")
        if d.get("format") != FORMAT:
            raise CampaignError(f"{where}: results format {d.get('format')!r}, this version "
                                f"reads {FORMAT}")
        try:
            return cls(CampaignConfig.from_dict(d["config"], where=f"{where}: config"),
                       float(d["open_loop_final_mass_kg"]), float(d["wet_mass_kg"]),
                       str(d.get("version", "unknown")), str(d.get("created_utc", "")))
        except KeyError as exc:
            raise CampaignError(f"{where}: header field {exc.args[0]} missing") from None


@dataclass(frozen=True)
class Results:
    """A results file read back: its header and its runs (file order)."""

    header: Header
    records: tuple
    partial_lines: int = 0   # a last line cut off by an interrupted write (ignored)

    @property
    def seeds(self) -> set:
        return {r.seed for r in self.records}


def read_results(path) -> Results:
    """Raises CampaignError naming the file and line of anything unreadable."""
    p = Path(path)
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise CampaignError(f"results file {p}: {exc.strerror}") from None
    lines = raw.split(b"\n")
    partial = 0 if raw.endswith(b"\n") or not raw else 1
    lines = lines[:-1]   # the empty string after the last newline, or the partial last line
    if not lines:
        raise CampaignError(f"results file {p}: no header (empty file)")
    header, records = None, []
    for no, line in enumerate(lines, 1):
        where = f"{p}:{no}"
        try:
            d = json.loads(line)
        except json.JSONDecodeError as exc:
            raise CampaignError(f"{where}: not JSON ({exc.msg})") from None
        if no == 1:
            header = Header.from_json(d, where)
            continue
        if d.get("type") != "run":
            raise CampaignError(f"{where}: expected a run record, got type {d.get('type')!r}")
        try:
            records.append(RunRecord.from_json(d))
        except (KeyError, ValueError, TypeError) as exc:
            raise CampaignError(f"{where}: bad run record ({exc})") from None
    return Results(header, tuple(records), partial)


class ResultsWriter:
    """Appends run records to a results file, one flushed line each.

    ``ResultsWriter.create(path, header)`` starts a file (refusing to replace one unless
    ``overwrite``); ``ResultsWriter.resume(path)`` continues one after trimming a partial last
    line, and knows the seeds it holds.
    """

    def __init__(self, path: Path, header: Header, recorded: set):
        self.path, self.header, self.recorded = path, header, recorded
        self._f = open(path, "a", encoding="utf-8")

    @classmethod
    def create(cls, path, header: Header, overwrite: bool = False) -> "ResultsWriter":
        p = Path(path)
        if p.exists() and not overwrite:
            raise CampaignError(f"results file {p} exists: resume it with --resume {p}, or "
                                "choose another --out")
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(json.dumps(header.to_json()) + "\n", encoding="utf-8")
        return cls(p, header, set())

    @classmethod
    def resume(cls, path) -> "ResultsWriter":
        p = Path(path)
        res = read_results(p)
        if res.partial_lines:
            raw = p.read_bytes()
            with open(p, "r+b") as f:
                f.truncate(raw.rfind(b"\n") + 1)
        return cls(p, res.header, res.seeds)

    def append(self, record: RunRecord) -> None:
        self._f.write(json.dumps(record.to_json()) + "\n")
        self._f.flush()
        self.recorded.add(record.seed)

    def close(self) -> None:
        self._f.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def merge_results(paths, out, overwrite: bool = False) -> tuple[Results, int]:
    """Write the runs of several results files of one experiment to ``out`` (the first file's
    header, the union of the seeds; a seed in more than one file keeps its first record).
    Returns the merged results and the number of duplicate seeds dropped."""
    parts = [read_results(p) for p in paths]
    first = parts[0]
    for p, r in zip(paths[1:], parts[1:]):
        if r.header.config.experiment() != first.header.config.experiment():
            diff = _differences(first.header.config.experiment(), r.header.config.experiment())
            raise CampaignError(f"{p}: not the same experiment as {paths[0]} ({diff})")
        if r.header.version != first.header.version:
            raise CampaignError(f"{p}: made by daddy_ros {r.header.version}, {paths[0]} by "
                                f"{first.header.version}: results of different versions are "
                                "not merged")
    seen, records = set(), []
    for r in parts:
        for rec in r.records:
            if rec.seed not in seen:
                seen.add(rec.seed)
                records.append(rec)
    dropped = sum(len(r.records) for r in parts) - len(records)
    seeds = tuple(sorted(seen))
    header = replace(first.header, config=replace(first.header.config, seeds=seeds))
    merged = Results(header, tuple(records))
    write_results(merged, out, overwrite=overwrite)
    return merged, dropped


def write_results(results: Results, path, overwrite: bool = False) -> None:
    """Write ``results`` as a new JSON Lines results file (refusing to replace one unless
    ``overwrite``)."""
    with ResultsWriter.create(path, results.header, overwrite=overwrite) as w:
        for rec in results.records:
            w.append(rec)


def _differences(a: dict, b: dict, prefix: str = "") -> str:
    for k in sorted(set(a) | set(b)):
        va, vb = a.get(k), b.get(k)
        if isinstance(va, dict) and isinstance(vb, dict):
            d = _differences(va, vb, f"{prefix}{k}.")
            if d:
                return d
        elif va != vb:
            return f"{prefix}{k}: {va!r} vs {vb!r}"
    return ""


# ---------------------------------------------------------------------------------------------
# Summary


def wilson_interval(k: int, n: int, z: float = Z_95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion k/n (95 % by default); (0, 1) for n = 0.
    Unlike the normal approximation it stays inside [0, 1] and is informative at k = n."""
    if n == 0:
        return 0.0, 1.0
    p = k / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    # at k = 0 (k = n) the lower (upper) bound is exactly 0 (1); the formula gives it to
    # round-off
    return (0.0 if k == 0 else max(0.0, centre - half),
            1.0 if k == n else min(1.0, centre + half))


@dataclass(frozen=True)
class Spread:
    """Median, 95th percentile and maximum of a sample (NaN when empty)."""

    median: float
    p95: float
    max: float

    @classmethod
    def of(cls, xs) -> "Spread":
        xs = sorted(x for x in xs if not math.isnan(x))
        if not xs:
            return cls(math.nan, math.nan, math.nan)
        # nearest-rank percentile: a value that occurred
        return cls(statistics.median(xs), xs[max(0, math.ceil(0.95 * len(xs)) - 1)], xs[-1])


@dataclass(frozen=True)
class Summary:
    runs: int
    completed: int
    failed: int
    success: int
    success_rate: float
    success_wilson_95: tuple
    miss_km: Spread
    miss_cm_s: Spread
    propellant_kg: Spread
    propellant_open_loop_kg: float
    latency_ms: Spread          # every re-plan of every completed run
    replans_per_run: float
    laws_per_run: float         # stage boundaries served by feedback laws instead
    law_eval_ms: Spread         # every served law's evaluation
    cpu_s_per_run: float
    errors: tuple               # (error text, count), most frequent first


def summarise(results: Results) -> Summary:
    recs = results.records
    done = [r for r in recs if r.status is RunStatus.COMPLETED]
    k = sum(r.success for r in recs)
    errors: dict[str, int] = {}
    for r in recs:
        if r.status is RunStatus.FAILED:
            errors[r.error] = errors.get(r.error, 0) + 1
    return Summary(
        runs=len(recs), completed=len(done), failed=len(recs) - len(done), success=k,
        success_rate=k / len(recs) if recs else math.nan,
        success_wilson_95=wilson_interval(k, len(recs)),
        miss_km=Spread.of(r.miss_km for r in done),
        miss_cm_s=Spread.of(r.miss_cm_s for r in done),
        propellant_kg=Spread.of(r.propellant_kg for r in done),
        propellant_open_loop_kg=results.header.propellant_open_loop_kg,
        latency_ms=Spread.of(x for r in done for x in r.latency_ms),
        replans_per_run=statistics.mean(r.replans for r in done) if done else math.nan,
        laws_per_run=statistics.mean(r.laws_served for r in done) if done else math.nan,
        law_eval_ms=Spread.of(x for r in done for x in r.law_eval_ms),
        cpu_s_per_run=statistics.mean(r.cpu_s for r in recs) if recs else math.nan,
        errors=tuple(sorted(errors.items(), key=lambda kv: -kv[1])))


def format_summary(s: Summary, header: Header) -> str:
    """The summary as a table (text)."""
    c = header.config
    crit = c.success
    lo, hi = s.success_wilson_95
    rows = [
        f"campaign: {c.case}, {s.runs} runs ({s.completed} completed, {s.failed} failed), "
        f"daddy_ros {header.version}",
        f"success (<= {crit.miss_km:g} km, <= {crit.miss_cm_s:g} cm/s, propellant within "
        f"{crit.propellant_fraction:.0%}): {s.success}/{s.runs} = {s.success_rate:.1%} "
        f"(95 % Wilson interval {lo:.1%} - {hi:.1%})",
        "",
        f"{'':28s}{'median':>12s}{'p95':>12s}{'max':>12s}",
    ]
    for name, sp, fmt in (("terminal miss [km]", s.miss_km, ".3f"),
                          ("terminal miss [cm/s]", s.miss_cm_s, ".3f"),
                          ("propellant [kg]", s.propellant_kg, ".3f"),
                          ("re-plan latency [ms]", s.latency_ms, ".1f")):
        rows.append(f"{name:28s}" + "".join(f"{v:>12{fmt}}" for v in
                                            (sp.median, sp.p95, sp.max)))
    rows += ["", f"propellant of the open-loop optimum: {s.propellant_open_loop_kg:.3f} kg",
             f"re-plans per run: {s.replans_per_run:.1f}; CPU per run: {s.cpu_s_per_run:.1f} s"]
    if s.laws_per_run:
        rows.append(f"stage boundaries served by feedback laws per run: {s.laws_per_run:.1f} "
                    f"(evaluation median {1e3 * s.law_eval_ms.median:.0f} us, max "
                    f"{1e3 * s.law_eval_ms.max:.0f} us)")
    for text, n in s.errors:
        rows.append(f"failed x{n}: {text}")
    return "\n".join(rows)
