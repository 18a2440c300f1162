"""Differential dynamic programming with DA expansions: the loop of paper Alg. 3.

Each iteration: the terminal multipliers' step where they are swept (``multiplier_sweep``), a
backward sweep on the expanded nominal (``sweeps``: Alg. 7 / 9 / 10), a step
accepted by the globalisation (``globalization``: line search or trust region, per-stage trust
where a few stages' cost models fail) on forward passes (Alg. 6 / 8), the new nominal's stage
maps (one batched expansion, eq. 11 re-centring), and the stopping tests (``stopping``).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from .deadline import Deadline, passed
from .globalization import Blame, StepControl
from . import multiplier_sweep
from .options import Method, MultiplierUpdate, SolverOptions, Sweep
from .results import Status, StepResult
from .stopping import CONVERGED, Stopping
from .sweeps import Gains, Stages, Trial, backward_sweep, new_maps


@dataclass
class DDPStats:
    """Counters and timings accumulated over DDP solves."""

    iterations: int = 0
    forward_s: float = 0.0
    expansion_s: float = 0.0
    backward_s: float = 0.0
    stages_total: int = 0
    stages_polynomial: int = 0

    @property
    def polynomial_share(self) -> float:
        return self.stages_polynomial / self.stages_total if self.stages_total else 0.0


@dataclass
class DDPResult(StepResult):
    stages: Stages
    rho: float
    gains: Gains | None  # of the last backward sweep
    radius: float = math.inf   # trust-region radius at the end (Globalization.TRUST_REGION)


def _sweep(st: Stages, sweep: Sweep, rho: float, stats: DDPStats,
           radius: float | np.ndarray = math.inf, indefinite: bool = False) -> Gains | None:
    """A backward sweep; far from the optimum the dynamics-Hessian terms can make Q_uu
    indefinite through V_xx, and the Gauss-Newton (Std) sweep at the same rho is taken
    instead."""
    t0 = time.perf_counter()
    # a diverging iterate overflows Q to inf / nan: the regularised inverse rejects it (rho is
    # raised), so numpy's warnings would only be noise on the user's terminal
    with np.errstate(over="ignore", invalid="ignore"):
        gains = backward_sweep(st, sweep, rho, radius, indefinite)
        if gains is None and sweep is not Sweep.STD:
            gains = backward_sweep(st, Sweep.STD, rho, radius)
    stats.backward_s += time.perf_counter() - t0
    return gains


@dataclass
class _Nominal:
    """The nominal a DDP solve is at and the last backward sweep's gains."""

    st: Stages
    gains: Gains | None = None


def ddp(st: Stages, method: Method, opts: SolverOptions, stats: DDPStats,
        deadline: Deadline | None = None, rho0: float | None = None,
        radius0: float = math.inf, retry: bool = False) -> DDPResult:
    """Alg. 3: backward sweep + forward pass until a stopping test ends the solve.

    rho0: the Q_uu regularisation to start from (default opts.ddp.rho_init); radius0: the
    trust-region radius to start from; retry: this solve retries one whose line search failed
    (``aul``'s trust-region fallback), which the stall test counts differently
    (``stopping.crawling``).
    """
    ctl = StepControl(opts, method.dyn, opts.ddp.rho_init if rho0 is None else rho0, radius=radius0)
    stop = Stopping(opts, retry, [(st.cost, 1.0, st.scale)])
    cur = _Nominal(st)
    status, iterations = Status.DDP_MAX_ITER, opts.ddp.max_iter
    for it in range(1, opts.ddp.max_iter + 1):
        if passed(deadline):
            status, iterations = deadline.status, it - 1
            break
        outcome = _iteration(cur, method, ctl, stop, stats, it)
        if outcome is not None:
            status = outcome
            iterations = it - 1 if status is Status.DDP_NOTHING_TO_GAIN else it
            break
    return DDPResult(status in CONVERGED, iterations, status, cur.st, ctl.rho, cur.gains,
                     ctl.radius)


def _iteration(cur: _Nominal, method: Method, ctl: StepControl, stop: Stopping,
               stats: DDPStats, it: int) -> Status | None:
    """One iteration of Alg. 3 on ``cur`` (updated in place): the status it ends the solve
    with, or None."""
    st = cur.st
    if stop.opts.aul.multiplier_update is MultiplierUpdate.SWEEP:
        st = cur.st = multiplier_sweep.swept(st, ctl.rho, stop.opts.aul.lambda_max)
    gains = _sweep(st, method.sweep, ctl.rho, stats, ctl.sweep_radius, ctl.trust_region)
    if gains is None:
        return ctl.indefinite()
    cur.gains = gains
    J = st.cost
    full_step_gain = -(gains.dv1 + gains.dv2) / st.scale
    t0 = time.perf_counter()
    # a trial step may overflow in the user's dynamics or cost: a non-finite trial is rejected
    # (``forward_pass``), so numpy's warnings would only be noise on the user's terminal
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        step = ctl.step(st, gains, J)
    stats.forward_s += time.perf_counter() - t0
    if isinstance(step, Blame):
        # those stages' steps are bounded now: sweep again on the same expansions (an
        # iteration of ddp_max_iter, as a trust region's rejected step is)
        return stop.after_rejection(st)
    if step is None:
        if stop.nothing_to_gain(it, gains, full_step_gain, ctl.trust_region):
            return Status.DDP_NOTHING_TO_GAIN
        return ctl.rejected(st, gains) or stop.after_rejection(st)
    cur.st = _accept(st, step, method, stats)
    ctl.accepted(step)
    return stop.after_step(it, st, step.cost, cur.st, step.alpha, gains, full_step_gain)


def _accept(st: Stages, step: Trial, method: Method, stats: DDPStats) -> Stages:
    """The expanded nominal of an accepted step: new stage maps (``new_maps``), and how far
    each re-centred map has walked from its expansion."""
    p = st.problem
    stats.iterations += 1
    stats.stages_total += p.N
    stats.stages_polynomial += int(step.poly.sum())
    t0 = time.perf_counter()
    F = new_maps(st, step, method.dyn)
    walked = np.where(step.poly, st.walked + np.sqrt(np.sum(step.dz ** 2, axis=0)), 0.0)
    new = Stages(p, step.X, step.U, st.mult, st.hom, st.eps_da, F=F, walked=walked,
                 order=st.order)
    stats.expansion_s += time.perf_counter() - t0
    return new
