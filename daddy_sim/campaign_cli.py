"""daddy_campaign: dispersion campaigns of the closed GNC loop, their results files and plots.

    daddy_campaign run [CAMPAIGN.yaml] [--case C] [--runs N] [--first-seed S] [--out F.jsonl]
                       [--executor local|dask] [--jobs J] [--scheduler tcp://HOST:PORT]
    daddy_campaign run --resume F.jsonl        # the seeds not yet in F, same config
    daddy_campaign summary F.jsonl|F.parquet [--json]
    daddy_campaign merge A.jsonl B.jsonl -o C.jsonl
    daddy_campaign export F.jsonl [-o F.parquet]   # or F.parquet -o F.jsonl
    daddy_campaign plot F.jsonl|F.parquet [-o F.png]
    daddy_campaign predict F.jsonl|F.parquet|CAMPAIGN.yaml [--samples N] [--plot P.png]

A campaign file holds the sections of ``campaigns.CampaignConfig`` (any omitted field takes its
default; the defaults are ``make monte-carlo``'s). Every finished run is appended to the results
file at once, so an interrupted campaign resumes where it stopped; when the campaign (or a merge)
ends, the whole file is also written as a Parquet table beside it (``campaign_table``; with
pyarrow, the analysis extra).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import asdict, replace
from pathlib import Path

from .campaign_executors import Executor, check_executor, open_executor
from .campaign_results import (Header, Results, ResultsWriter, format_summary, merge_results,
                               package_version, read_results, summarise, write_results)
from .campaign_table import TABLE_SUFFIX, load_results, table_path, write_table
from .campaigns import (CampaignConfig, CampaignError, check_case, load_config,
                        read_config_data, run_campaign)


def open_loop_header(config: CampaignConfig) -> Header:
    """The header of a new results file: the open-loop optimum the runs start from."""
    from .closed_loop import nominal_planner
    planner, m_open = nominal_planner(config.case, config.guidance.time_budget_s,
                                      config.guidance.arrival_tolerance_m)
    return Header(config, m_open, planner.case.spacecraft.wet_mass_kg)


def execute(writer: ResultsWriter, config: CampaignConfig, executor: Executor, jobs: int,
            scheduler: str = "", out=print, bar: bool = False) -> int:
    """Run the seeds of ``config`` that ``writer``'s file lacks, appending each record as it
    finishes; ``out`` gets the executor's description and a progress line per run, or, with
    ``bar`` (and tqdm installed), a progress bar on stderr with the ETA and the success so far
    replaces the lines of the runs that succeed. Returns the number of runs made."""
    todo = [s for s in config.seeds if s not in writer.recorded]
    if not todo:
        out(f"{writer.path}: all {len(config.seeds)} seeds already recorded")
        return 0
    already = len(config.seeds) - len(todo)
    with open_executor(executor, min(jobs, len(todo)) if not scheduler else jobs,
                       scheduler) as (pool, what):
        out(f"{len(todo)} runs on {what}" + (f" ({already} already in {writer.path})"
                                              if already else "") + f" -> {writer.path}")
        progress = _progress_bar(len(config.seeds), already) if bar else None
        t0, ok = time.perf_counter(), 0
        for i, rec in enumerate(run_campaign(config, todo, pool), 1):
            writer.append(rec)
            ok += rec.success
            if progress is not None:
                if not rec.success:
                    progress.write(rec.line())
                progress.set_postfix_str(f"success {ok}/{i}", refresh=False)
                progress.update()
                continue
            eta = (time.perf_counter() - t0) / i * (len(todo) - i)
            out(f"[{already + i}/{len(config.seeds)}] {rec.line()} | success {ok}/{i} "
                f"| ETA {_duration(eta)}")
        if progress is not None:
            progress.close()
    return len(todo)


def _progress_bar(total: int, already: int):
    """A tqdm bar on stderr, or None without tqdm (the campaigns extra)."""
    import shutil
    try:
        from tqdm import tqdm
    except ImportError:
        return None
    # (a terminal that reports no size, e.g. script(1)'s, gets 100 x 24: tqdm hides a bar
    # on a terminal of no rows)
    size = shutil.get_terminal_size((100, 24))
    return tqdm(total=total, initial=already, unit="run", smoothing=0.1, ncols=size.columns,
                nrows=size.lines)


def _duration(s: float) -> str:
    s = int(round(s))
    return f"{s // 3600}h{s % 3600 // 60:02d}m" if s >= 3600 else f"{s // 60}m{s % 60:02d}s"


def _config_from_args(args, base: CampaignConfig | None = None) -> CampaignConfig:
    """The campaign file (else ``base``, else the defaults) with the command line's case and
    seeds; the case's own defaults (its ``closed_loop`` section) fill what the file leaves
    out."""
    if args.case:   # (read as written: the case's defaults fill what the file leaves out)
        check_case(args.case, "--case")
        data = read_config_data(args.config) if args.config else (
            base.to_dict() if base else {})
        config = CampaignConfig.from_dict({**data, "case": args.case},
                                          where=args.config or "--case")
    else:
        config = load_config(args.config) if args.config else (base or CampaignConfig())
    if args.runs is not None or args.first_seed is not None:
        first = args.first_seed if args.first_seed is not None else config.seeds[0]
        count = args.runs if args.runs is not None else len(config.seeds)
        if count < 1:
            raise CampaignError(f"--runs: must be at least 1, got {count}")
        config = replace(config, seeds=tuple(range(first, first + count)))
    return config


def _cmd_run(args) -> int:
    check_executor(Executor(args.executor), args.jobs, args.scheduler)
    if args.resume:
        if args.out or args.overwrite:
            raise CampaignError("--resume: appends to its own file (no --out, --overwrite)")
        writer = ResultsWriter.resume(args.resume)
        config = _config_from_args(args, base=writer.header.config)
        if config.experiment() != writer.header.config.experiment():
            raise CampaignError(f"--resume {args.resume}: the file holds another experiment "
                                "than the campaign given (merge files of one experiment only)")
        if writer.header.version != (v := package_version()):
            print(f"note: {args.resume} was started by daddy_ros {writer.header.version}, this "
                  f"is {v}", flush=True)
    else:
        config = _config_from_args(args)
        out = args.out or f"out/campaign-{config.case}.jsonl"
        header = open_loop_header(config)
        writer = ResultsWriter.create(out, header, overwrite=args.overwrite)
    results = run_and_report(writer, config, Executor(args.executor), args.jobs,
                             args.scheduler)
    if results is None:
        return 130
    _table_beside(results, writer.path)
    if args.plot:
        _plot(results, args.plot)
    return 0


def run_and_report(writer: ResultsWriter, config: CampaignConfig, executor: Executor,
                   jobs: int, scheduler: str = "") -> Results | None:
    """``execute`` with its progress on stdout, then the summary table of the whole results
    file (closes ``writer``). Ctrl-C stops it with every finished run on disk and says how to
    resume: None then."""
    with writer:
        try:
            execute(writer, config, executor, jobs, scheduler,
                    out=lambda s: print(s, flush=True), bar=sys.stderr.isatty())
        except KeyboardInterrupt:
            print(f"\ninterrupted: {len(writer.recorded)} runs in {writer.path}; continue with "
                  f"daddy_campaign run --resume {writer.path}", flush=True)
            return None
    results = read_results(writer.path)
    print()
    print(format_summary(summarise(results), results.header))
    return results


def _table_beside(results: Results, path) -> None:
    """The Parquet table of a JSONL results file, beside it; a note without pyarrow."""
    try:
        print(f"table: {write_table(results, table_path(path))}")
    except CampaignError as exc:
        print(f"table skipped: {exc}")


def _cmd_summary(args) -> int:
    results = load_results(args.file)
    s = summarise(results)
    if args.json:
        print(json.dumps(_jsonable(asdict(s)), indent=1))
    else:
        print(format_summary(s, results.header))
        if results.partial_lines:
            print("(a partial last line, an interrupted write, was ignored)")
    return 0


def _jsonable(x):
    if isinstance(x, float) and math.isnan(x):
        return None
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    return x


def _cmd_merge(args) -> int:
    results, dropped = merge_results(args.files, args.output, overwrite=args.overwrite)
    print(f"{args.output}: {len(results.records)} runs from {len(args.files)} files"
          + (f" ({dropped} duplicate seeds kept once)" if dropped else ""))
    _table_beside(results, args.output)
    return 0


def _cmd_export(args) -> int:
    """JSONL -> Parquet table (default: beside it), or a table back to JSONL (-o)."""
    src = Path(args.file)
    results = load_results(src)
    if src.suffix == TABLE_SUFFIX:
        if not args.output:
            raise CampaignError("export: -o F.jsonl, where to write the table's runs")
        write_results(results, args.output, overwrite=args.overwrite)
        dst = args.output
    else:
        dst = args.output or table_path(src)
        if Path(dst).suffix != TABLE_SUFFIX:
            raise CampaignError(f"export -o {dst}: a table is written as {TABLE_SUFFIX}")
        if Path(dst).exists() and not args.overwrite:
            raise CampaignError(f"export -o {dst}: exists (--overwrite to replace it)")
        write_table(results, dst)
    print(f"{dst}: {len(results.records)} runs")
    return 0


def _cmd_plot(args) -> int:
    results = load_results(args.file)
    return _plot(results, args.output or str(Path(args.file).with_suffix(".png")))


def _cmd_predict(args) -> int:
    """The terminal dispersion predicted on the linearised closed loop; beside the runs of a
    results file (its experiment's config), or of a campaign file alone."""
    import numpy as np

    from .campaign_prediction import AXES, compare, format_comparison, plot_comparison, predict
    source = Path(args.source)
    if source.suffix in (".jsonl", TABLE_SUFFIX):
        results = load_results(source)
        config = results.header.config
        runs = np.array([r.deviation_si for r in results.records if len(r.deviation_si) == 6])
        cpu = sum(r.cpu_s for r in results.records)
    else:
        config, runs, cpu = load_config(source), np.zeros((0, 6)), 0.0
    prediction = predict(config, samples=args.samples, seed=args.seed)
    if len(runs) >= 2:
        print(format_comparison(compare(prediction, runs, cpu)))
    else:
        std = np.sqrt(np.diag(prediction.cov_si))
        print(f"terminal deviation predicted for {config.case} (linearised closed loop, "
              f"{args.samples} samples, {prediction.cpu_s:.1f} s CPU):")
        for axis, m, sd in zip(AXES, prediction.mean_si, std):
            print(f"  {axis:10s} mean {m:12.6g}  std {sd:12.6g}")
        if len(runs):
            print(f"({len(runs)} run with a terminal deviation in {source}: too few to compare)")
    if args.plot:
        try:
            plot_comparison(prediction, runs, args.plot)
        except ImportError:
            print("plot skipped: matplotlib not installed (pip install 'daddy_ros[plots]')")
            return 1
        print(f"plot: {args.plot}")
    return 0


def _plot(results: Results, path: str) -> int:
    from .campaign_plot import plot_campaign
    try:
        plot_campaign(results, path)
    except ImportError:
        print("plot skipped: matplotlib not installed (pip install 'daddy_ros[plots]')")
        return 1
    print(f"plot: {path}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="daddy_campaign", description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run a campaign (or the rest of one: --resume)")
    run.add_argument("config", nargs="?", help="campaign file (.json, .yaml); default: the "
                                               "make monte-carlo campaign")
    run.add_argument("--case", help="the catalogue case (overrides the file's)")
    run.add_argument("--runs", type=int, help="seeds first-seed .. first-seed + runs - 1")
    run.add_argument("--first-seed", type=int)
    run.add_argument("--out", help="results file (default out/campaign-CASE.jsonl)")
    run.add_argument("--overwrite", action="store_true", help="replace an existing --out")
    run.add_argument("--resume", metavar="FILE", help="continue FILE: run its seeds not yet "
                                                      "recorded")
    run.add_argument("--executor", choices=[e.value for e in Executor], default="local")
    run.add_argument("--jobs", type=int, default=cores(),
                     help="worker processes (default: one per core)")
    run.add_argument("--scheduler", default="", metavar="tcp://HOST:PORT",
                     help="submit to this existing Dask cluster (with --executor dask)")
    run.add_argument("--plot", metavar="PNG", help="also plot the results")
    run.set_defaults(func=_cmd_run)
    sm = sub.add_parser("summary", help="summary table of a results file")
    sm.add_argument("file")
    sm.add_argument("--json", action="store_true", help="as JSON")
    sm.set_defaults(func=_cmd_summary)
    mg = sub.add_parser("merge", help="merge results files of one experiment")
    mg.add_argument("files", nargs="+")
    mg.add_argument("-o", "--output", required=True)
    mg.add_argument("--overwrite", action="store_true")
    mg.set_defaults(func=_cmd_merge)
    ex = sub.add_parser("export", help="a results file as a Parquet table (or a table back "
                                       "to JSON Lines)")
    ex.add_argument("file", help="F.jsonl, or F.parquet")
    ex.add_argument("-o", "--output", help="F.parquet (default: beside F.jsonl), or F.jsonl")
    ex.add_argument("--overwrite", action="store_true")
    ex.set_defaults(func=_cmd_export)
    pl = sub.add_parser("plot", help="PNG of a results file: miss scatter, propellant, latency, "
                                     "terminal deviations with their ellipses")
    pl.add_argument("file")
    pl.add_argument("-o", "--output", help="PNG (default: the results file's name .png)")
    pl.set_defaults(func=_cmd_plot)
    pr = sub.add_parser("predict", help="the terminal dispersion predicted on the linearised "
                                        "closed loop, beside a results file's runs")
    pr.add_argument("source", help="a results file (.jsonl or .parquet: compared with its "
                                   "runs) or a campaign file")
    pr.add_argument("--samples", type=int, default=20_000,
                    help="draws of the linearised loop (default 20000)")
    pr.add_argument("--seed", type=int, default=0)
    pr.add_argument("--plot", metavar="PNG", help="the runs and both covariances' ellipses")
    pr.set_defaults(func=_cmd_predict)
    return ap


def cores() -> int:
    """The cores this process may use: the default number of campaign workers."""
    import os
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (
        os.cpu_count() or 1)


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except CampaignError as exc:
        print(f"daddy_campaign: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
