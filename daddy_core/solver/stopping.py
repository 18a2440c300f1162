"""When a DDP solve (Alg. 3) stops, apart from its iteration bound and the time budget: one
``Stopping`` object per solve keeps the history of accepted steps and judges each iteration's
outcome (as crocoddyl's ``stoppingCriteria``).

- converged: the relative cost decrease of a (nearly) full step is below tol_ddp
  (``Status.DDP_CONVERGED``; the paper's test);

every "relative" here relative to the part of the cost the controls change, not to a constant
it carries (``cost_scale``: ``Stages.scale``);
- nothing to gain: the line search found no step for a full step worth less than tol_ddp
  (``Status.DDP_NOTHING_TO_GAIN``: the mismatch is the forward pass's round-off);
- stalled: ``ddp_stall_iter`` steps in a row cut below ``ddp_stall_alpha`` of the full step,
  each lowering the cost by less than tol_ddp (``Status.DDP_STALLED``; design notes: crawl stop).
"""
from __future__ import annotations

from dataclasses import dataclass, field

from .options import SolverOptions
from .results import Status
from .sweeps import Gains, Stages

# the statuses that end a solve converged
CONVERGED = (Status.DDP_CONVERGED, Status.DDP_NOTHING_TO_GAIN)


def crawling(steps: list, opts: SolverOptions) -> bool:
    """DDP has stalled: each of the last ``ddp_stall_iter`` steps (``steps``: (cost, fraction,
    scale) of the start, then after each step) was cut to less than ``ddp_stall_alpha`` of the full
    step and lowered the cost by less than tol_ddp (relative).

    The fraction is the line search's alpha; a trust-region step counts as 1 (a region that
    cuts the Newton step is normal there) -- except in the solve that retries a failed line
    search (``ddp(retry=True)``): there it is the smallest radius / full step of a stage
    (``Gains.shortest``), and a rejected step after the first accepted one is a step of length
    zero (``Stopping.after_rejection``)."""
    k = opts.ddp.stall_iter
    if k <= 0 or len(steps) <= k:
        return False
    return all(fraction < opts.ddp.stall_alpha and before - after < opts.ddp.tol * size
               for (before, _, size), (after, fraction, _) in zip(steps[-k - 1:-1], steps[-k:]))


@dataclass
class Stopping:
    """The stopping tests of one DDP solve. ``steps``: (cost, step fraction, ``Stages.scale``)
    of the start, then after each accepted step; retry: the solve retries a failed line search with the
    trust region (``aul``'s fallback)."""

    opts: SolverOptions
    retry: bool
    steps: list = field(default_factory=list)

    def after_step(self, it: int, st: Stages, trial_cost: float, new: Stages, alpha: float,
                   gains: Gains, full_step_gain: float) -> Status | None:
        """After an accepted step of length ``alpha`` from nominal ``st`` to ``new``
        (``trial_cost``: the trial's own evaluation): converged, stalled, or go on (None). A small decrease after a
        heavily shortened step only says the globalisation struggled, and a step the trust
        region cut says nothing of the full one."""
        opts = self.opts
        rel = (st.cost - trial_cost) / st.scale
        self.steps.append((new.cost, alpha * (gains.shortest if self.retry else 1.0), new.scale))
        if (it >= opts.ddp.min_iter and 0.0 <= rel < opts.ddp.tol and not gains.clipped
                and (alpha >= 0.5 or full_step_gain < opts.ddp.tol)):
            return Status.DDP_CONVERGED
        return Status.DDP_STALLED if crawling(self.steps, opts) else None

    def nothing_to_gain(self, it: int, gains: Gains, full_step_gain: float,
                        trust_region: bool) -> bool:
        """The line search found no step that its model predicts, for a full step worth less
        than tol_ddp: the mismatch is the forward pass's noise (round-off, the Dyn rollout's
        truncation), which raising rho to rho_max would spend the budget on."""
        return (not trust_region and it > self.opts.ddp.min_iter
                and 0.0 <= full_step_gain < self.opts.ddp.tol and not gains.clipped)

    def after_rejection(self, st: Stages) -> Status | None:
        """A rejected step of the retry after its first accepted one counts as a step of length
        zero; before it, rejections are the region shrinking from its unbounded first step to
        where the model holds."""
        if not self.retry or len(self.steps) < 2:
            return None
        self.steps.append((st.cost, 0.0, st.scale))
        return Status.DDP_STALLED if crawling(self.steps, self.opts) else None
