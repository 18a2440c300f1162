"""Campaign executors side by side: the same closed-loop campaign through the process pool and
a loopback Dask LocalCluster (same worker count), interleaved, plus the per-run overhead of
each executor measured with a task that does nothing but return a full-size run record.

    python bench/bench_campaign.py [--case halo_l2_l1] [--runs 20] [--workers 2] [--rounds 1]

Prints, per round, the wall time of the campaign from submission to its last record (executor
start-up included, and without it), the ratio Dask / pool, whether the two executors' records
agree for every seed (everything but timings and worker names), and the overhead: a round trip
of one empty task on idle workers, and the worker time per task when a queue of them runs.
"""
from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from daddy_sim.campaign_executors import Executor, open_executor  # noqa: E402
from daddy_sim.campaigns import (CampaignConfig, Dispersion, RunRecord, RunStatus,  # noqa: E402
                                 run_campaign)


def empty_run(seed: int) -> RunRecord:
    """What a run returns, without the run: 180 latencies, a dispersion (~4 kB of JSON)."""
    return RunRecord(seed=seed, status=RunStatus.COMPLETED, success=True, miss_km=0.1,
                     miss_cm_s=0.1, final_mass_kg=973.0, propellant_kg=27.0, replans=180,
                     latency_ms=tuple(50.0 + i for i in range(180)),
                     dispersion=Dispersion(), worker=f"{platform.node()}:{os.getpid()}")


def campaign(kind: Executor, config: CampaignConfig, workers: int) -> tuple[dict, float, float]:
    """(records by seed, wall s with executor start-up, wall s of the runs alone)."""
    t0 = time.perf_counter()
    with open_executor(kind, workers) as (pool, _):
        t1 = time.perf_counter()
        recs = {r.seed: r for r in run_campaign(config, config.seeds, pool)}
        t2 = time.perf_counter()
    return recs, t2 - t0, t2 - t1


def overhead(kind: Executor, workers: int, tasks: int) -> tuple[float, float]:
    """(median round trip of one empty task on idle workers [ms], worker time per empty task
    in a queue of ``tasks`` [ms])."""
    with open_executor(kind, workers) as (pool, _):
        for f in [pool.submit(empty_run, i) for i in range(2 * workers)]:   # warm every worker
            f.result()
        trips = []
        for i in range(30):
            t = time.perf_counter()
            pool.submit(empty_run, i).result()
            trips.append(time.perf_counter() - t)
        t = time.perf_counter()
        for f in [pool.submit(empty_run, i) for i in range(tasks)]:
            f.result()
        queue = time.perf_counter() - t
    return 1e3 * statistics.median(trips), 1e3 * queue * workers / tasks


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", default="halo_l2_l1")
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--tasks", type=int, default=400, help="empty tasks for the overhead")
    args = ap.parse_args()
    try:
        import distributed
    except ImportError:
        print("bench_campaign needs the campaigns extra (Dask)")
        return 1
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"Python {platform.python_version()}, distributed {distributed.__version__}; "
          f"{args.case}, {args.runs} runs, {args.workers} workers")
    for kind in Executor:
        trip, per_task = overhead(kind, args.workers, args.tasks)
        print(f"overhead {kind.value:5s}: round trip of an empty run {trip:6.2f} ms, worker "
              f"time per empty run in a queue {per_task:6.2f} ms")
    config = CampaignConfig.from_dict({"case": args.case,
                                       "seeds": {"first": 1, "count": args.runs}})
    for rnd in range(1, args.rounds + 1):
        out = {}
        order = list(Executor) if rnd % 2 else list(reversed(Executor))
        for kind in order:
            out[kind] = campaign(kind, config, args.workers)
            recs, total, runs = out[kind]
            print(f"round {rnd} {kind.value:5s}: {total:7.1f} s with start-up, {runs:7.1f} s "
                  f"runs, {sum(r.success for r in recs.values())}/{len(recs)} succeeded",
                  flush=True)
        (rp, tp, up), (rd, td, ud) = out[Executor.LOCAL], out[Executor.DASK]
        same = sum(rp[s].outcome() == rd[s].outcome() for s in rp)
        print(f"round {rnd}: dask / pool wall {td / tp:.3f} (runs alone {ud / up:.3f}); "
              f"records identical for {same}/{len(rp)} seeds; dask overhead per run "
              f"{(ud - up) / len(rp) * args.workers * 1e3:+.0f} ms of worker time")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
