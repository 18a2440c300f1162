"""What every step of one solve reads: the problem, the method, the options, the homotopy steps,
the clock, the work counters and the progress callback (``SolveContext``)."""
from __future__ import annotations

import time
from collections.abc import Callable
from contextlib import contextmanager
from dataclasses import dataclass, field

from ..problem import Problem
from .deadline import CancelFlag, Deadline, passed
from .ddp import DDPStats
from .options import Method, SolverOptions


@dataclass
class Clock:
    """Start, deadline and the phase timings of one solve (``Solution.runtime_s``, s); cancel:
    the caller's cancel flag (``deadline.CancelFlag``) or None."""

    budget_s: float | None
    start: float = field(default_factory=time.perf_counter)
    times: dict = field(default_factory=dict)
    cancel: CancelFlag | None = None

    @property
    def deadline(self) -> Deadline | None:
        """The solve's ``Deadline`` (None: no budget and no cancel flag)."""
        if self.budget_s is None and self.cancel is None:
            return None
        return Deadline(None if self.budget_s is None else self.start + self.budget_s,
                        self.cancel)

    def out_of_time(self) -> bool:
        return passed(self.deadline)

    @contextmanager
    def phase(self, name: str):
        """Add the time spent in the block to phase ``name`` (a phase may run again)."""
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.times[name] = self.times.get(name, 0.0) + time.perf_counter() - t0


@dataclass
class Work:
    """The iterations one solve spent outside DDP and the AUL (which ``DDPStats`` and the
    homotopy count): every Newton and KKT polishing adds its own here, kept or not."""

    restore: int = 0
    newton: int = 0
    kkt: int = 0


@dataclass
class SolveContext:
    """One solve's fixed inputs and running counters.

    Attributes:
        problem, method, opts: what is solved and how.
        steps: the (h, delta) homotopy steps of this solve (``homotopy.homotopy_steps``).
        polish: Newton polishing (Alg. 11) and the KKT end game run.
        clock, stats, work: timings, DDP counters, Newton / KKT counters.
        progress: a callable taking progress lines, or None.
        rho0: the Quu regularisation the homotopy starts from (a warm start's), or None.
    """

    problem: Problem
    method: Method
    opts: SolverOptions
    steps: tuple
    polish: bool
    clock: Clock
    stats: DDPStats = field(default_factory=DDPStats)
    work: Work = field(default_factory=Work)
    progress: Callable[[str], None] | None = None
    rho0: float | None = None

    def say(self, line: str) -> None:
        if self.progress is not None:
            self.progress(line)
