"""Where a campaign's runs execute: a ``concurrent.futures`` executor for ``run_campaign``.

- ``Executor.LOCAL``: a process pool on this machine (the default).
- ``Executor.DASK``: a Dask ``LocalCluster`` on this machine, or, with a scheduler address,
  an existing Dask cluster whose workers have daddy installed. Dask is the campaigns extra
  (``pip install '.[campaigns]'``); it is imported only here, only when asked for.

Every worker runs one run at a time with single-threaded BLAS (a run is a sequence of small
dense solves; more threads per worker only contend for the cores the other workers use).
A ``LocalCluster`` listens on loopback only: scheduler, workers, nannies and dashboard bind to
127.0.0.1 on ports the OS picks (a fixed port would collide between parallel campaigns, and
Dask's default dashboard address listens on every interface).
"""
from __future__ import annotations

import concurrent.futures
import enum
import logging
import multiprocessing
import os
from contextlib import contextmanager

from .campaigns import CampaignError

SINGLE_THREAD_BLAS = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1",
                      "MKL_NUM_THREADS": "1"}
INSTALL_HINT = ("--executor dask needs Dask, the campaigns extra: pip install "
                "'daddy_ros[campaigns]' (in this repository: .venv/bin/pip install -c "
                "requirements/pins.txt -r requirements/campaigns.txt)")


# Dask settings for a campaign's LocalCluster. A run is ~25 s of pure Python, so the
# cluster's periodic housekeeping is paid for in GIL hand-overs and in CPU the runs would use
# (on the 2-core machine the scheduler and nannies in this process took 8 s of CPU per 100 s
# of a 2-worker campaign, and the workers ~5 % more CPU per run than pool workers): the
# event-loop tick (20 ms) and the memory and system monitors (100 / 500 ms) run less often,
# and the statistical profiler (a stack sample of the running task every 10 ms) is off.
# Workers of an existing cluster take their own config (`docs/campaigns.md`).
WORKER_CONFIG = {"distributed.worker.profile.enabled": False,
                 "distributed.admin.tick.interval": "1s",
                 "distributed.worker.memory.monitor-interval": "1s",
                 "distributed.admin.system-monitor.interval": "2s"}


class Executor(str, enum.Enum):
    LOCAL = "local"
    DASK = "dask"

    __str__ = str.__str__


def check_executor(kind: Executor, jobs: int, scheduler: str = "") -> None:
    """The executor options, checked before anything runs (CampaignError names the option)."""
    if scheduler and kind is not Executor.DASK:
        raise CampaignError("--scheduler: an existing cluster is a Dask one (--executor dask)")
    if jobs < 1:
        raise CampaignError(f"--jobs: must be at least 1, got {jobs}")


@contextmanager
def open_executor(kind: Executor, jobs: int, scheduler: str = ""):
    """A context yielding (executor, description). ``jobs``: workers of a local pool or
    ``LocalCluster``; ``scheduler``: the address (tcp://HOST:PORT) of an existing Dask
    cluster (``kind`` must be DASK; ``jobs`` is then the cluster's business)."""
    check_executor(kind, jobs, scheduler)
    if kind is Executor.LOCAL:
        os.environ.update(SINGLE_THREAD_BLAS)   # the pool's fresh processes inherit it
        # spawned, not forked: every worker starts as a Dask worker does, from a clean
        # interpreter with the environment above
        with concurrent.futures.ProcessPoolExecutor(
                jobs, mp_context=multiprocessing.get_context("spawn")) as pool:
            yield pool, f"process pool, {jobs} workers"
        return
    try:
        import distributed
    except ImportError:
        raise CampaignError(INSTALL_HINT) from None
    if scheduler:
        with distributed.Client(scheduler, timeout="30s") as client:
            n = len(client.scheduler_info(n_workers=-1).get("workers", {}))
            if n == 0:
                raise CampaignError(f"--scheduler {scheduler}: the cluster has no workers "
                                    "(start them with `dask worker " + scheduler + "`)")
            yield client.get_executor(pure=False), f"Dask cluster {scheduler}, {n} workers"
        return
    import dask
    with dask.config.set(WORKER_CONFIG), \
            distributed.LocalCluster(n_workers=jobs, threads_per_worker=1, processes=True,
                                     host="127.0.0.1", scheduler_port=0,
                                     dashboard_address="127.0.0.1:0", env=SINGLE_THREAD_BLAS,
                                     silence_logs=logging.ERROR) as cluster, \
            distributed.Client(cluster) as client:
        yield (client.get_executor(pure=False),
               f"Dask LocalCluster {cluster.scheduler_address}, {jobs} workers")
