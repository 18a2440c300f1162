"""DDP's globalisation (Alg. 3's step acceptance): the Q_uu regularisation rho, the
backtracking line search of the reference code, the trust region of the HDDP / PDDP /
many-revolution papers (eq. 37), and the per-stage trust region that bounds the few stages a
failed step is blamed on (``blamed_stages``). ``StepControl`` holds one DDP solve's state.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .lagrangian import augmented_cost_terms
from .options import Globalization, SolverOptions
from .results import Status
from .sweeps import Gains, Stages, Trial, forward_pass


@dataclass
class Blame:
    """A line search's first trial failed, and the stage cost's own quadratic model failed at a
    few stages enough to explain it: those stages (indices (m,)) and the bounds (m,) their
    control changes |du_k| get (half of the trial's)."""

    stages: np.ndarray
    bounds: np.ndarray


def _raise_rho(rho: float, opts: SolverOptions, growth: float | None = None) -> float:
    """rho times ``growth`` (default opts.ddp.rho_factor), at least opts.ddp.rho_min."""
    return max(rho * (opts.ddp.rho_factor if growth is None else growth), opts.ddp.rho_min)


def _lower_rho(rho: float, opts: SolverOptions) -> float:
    r = rho / opts.ddp.rho_factor
    return r if r >= opts.ddp.rho_min else 0.0


def _rho_after_step(rho: float, alpha: float, opts: SolverOptions) -> float:
    """Lower rho after an accepted step, unless it was shortened below opts.ddp.short_step: then
    the quadratic model promised far more than the step delivered (e.g. controls in the linear
    part of the pseudo-Huber cost, whose tiny curvature asks for huge steps), and rho is raised,
    Levenberg-Marquardt-like, rather than crawl on with tiny alphas."""
    if alpha < opts.ddp.short_step:
        return _raise_rho(rho, opts, opts.ddp.short_step_rho_growth)
    return _lower_rho(rho, opts)


def _accepted(expected: float, actual: float, J: float, Jn: float, lo: float, hi: float) -> bool:
    """A step whose actual / expected decrease lies in (lo, hi), or that decreases the cost
    where the expected decrease is round-off."""
    return bool(np.isfinite(Jn)) and (
        (expected > 0 and lo < actual / expected < hi)
        or (expected <= 1e-15 * max(1.0, abs(J)) and actual >= 0))


_LOCAL_FRACTION = 0.1


def blamed_stages(st: Stages, trial: Trial, stage_costs: np.ndarray, expected: float,
                   actual: float, tol: float, worth: float | None = None,
                   blamed: np.ndarray | None = None) -> np.ndarray:
    """The stages whose stage-cost model failed on ``trial`` (its augmented stage costs
    ``stage_costs`` (N,)) enough to explain why it was rejected, (m,) indices (empty: the
    failure is not local).

    The quadratic model of stage k's augmented cost, at the trial's actual deviation dz_k,
    predicts l_z dz + dz l_zz dz / 2; where the true change exceeds that by more than a tenth
    of the whole step's expected decrease (or of the gap expected - actual, if smaller), the
    stage is blamed -- when the blamed stages together explain half the gap. Both non-smooth
    parts of a low-thrust stage cost fail this way at single stages: a thrust bound the step
    crosses, and the pseudo-Huber cost's kink at zero thrust.

    Not blamed (the failure is not local: one shorter step for every stage is the answer):
    more than ``_LOCAL_FRACTION`` of the stages, or a step whose ``worth`` (default: its whole
    expected decrease) is below ``tol`` (tol_ddp) relative to the cost (``Stages.scale``), whose
    gap is round-off
    (design notes: local blame only).

    Not blamed again either: stages already blamed since the last accepted step (``blamed``,
    (N,) bool, or None), when no other stage fails with them -- their bounded controls did not
    mend the model, so its failure comes from the states the other stages' steps move them
    to (a keep-out penalty's curvature at a sample the trajectory is pushed into), and only a
    shorter step for every stage can (design notes: blame once)."""
    p = st.problem
    gap = expected - actual
    worth = expected if worth is None else worth
    if not (gap > 0 and math.isfinite(gap)) or worth < tol * st.scale:
        return np.empty(0, dtype=int)
    dz = trial.dz.T                                              # (N, n)
    change = stage_costs - st.l
    model = (np.einsum("ki,ki->k", st.lz, dz)
             + 0.5 * np.einsum("ki,kij,kj->k", dz, st.lzz, dz))
    err = change - model
    bad = np.flatnonzero(err > 0.1 * min(gap, expected))
    if bad.size == 0 or bad.size > _LOCAL_FRACTION * p.N or err[bad].sum() < 0.5 * gap:
        return np.empty(0, dtype=int)
    if blamed is not None and np.all(blamed[bad]):
        return np.empty(0, dtype=int)
    return bad


def line_search(st: Stages, gains: Gains, a0: float, dyn: bool, opts: SolverOptions,
                 J: float, clamp: np.ndarray | None = None,
                 blamed: np.ndarray | None = None) -> Trial | Blame | None:
    """Backtracking from step a0 (one step length at a time): the first step whose actual /
    expected decrease lies in (ls_min_ratio, ls_max_ratio), or that decreases the cost where
    the expected decrease is round-off. Returns that trial (with its cost), or -- when the
    first trial fails at a few stages (``blamed_stages``, with ``opts.ddp.stage_trust``) -- those
    stages and their new bounds, or None.

    The caller bounds the blamed stages' steps (``clamp``, as ``forward_pass`` takes it, and
    the sweep's per-stage radius) and sweeps again (design notes: per-stage trust)."""
    p = st.problem
    for i, a in enumerate(a0 * opts.ddp.ls_shrink ** np.arange(opts.ddp.ls_max_halvings + 1)):
        trial = forward_pass(st, gains, a, dyn, clamp)
        if not trial.ok:
            continue
        stage_costs, terminal = augmented_cost_terms(p, trial.X, trial.U, st.mult, st.hom)
        Jn = trial.cost = float(np.sum(stage_costs) + terminal)
        expected = -(a * gains.dv1 + a * a * gains.dv2)
        if _accepted(expected, J - Jn, J, Jn, opts.ddp.ls_min_ratio, opts.ddp.ls_max_ratio):
            return trial
        if i == 0 and opts.ddp.stage_trust and math.isfinite(Jn):
            bad = blamed_stages(st, trial, stage_costs, expected, J - Jn, opts.ddp.tol,
                                blamed=blamed)
            if bad.size:
                return Blame(bad, 0.5 * np.linalg.norm(trial.dz[p.nx:, bad], axis=0))
    return None


def trust_region_step(st: Stages, gains: Gains, dyn: bool, opts: SolverOptions,
                       J: float, clamp: np.ndarray | None = None,
                       blamed: np.ndarray | None = None) -> Trial | Blame | None:
    """The full step of a trust-region sweep, accepted when its reduction ratio actual /
    expected lies within tr_ratio_tol of 1 (the quadratic model held). A rejected step whose
    failure a few stages explain (``blamed_stages``, with ``opts.ddp.stage_trust``) bounds those
    stages (a ``Blame``, as the line search's first trial does), else None: the whole region
    shrinks. Rationale: a step crossing one stage's thrust bound shrank every stage's region
    (design notes: trust-region blame)."""
    trial = forward_pass(st, gains, 1.0, dyn, clamp)
    if not trial.ok:
        return None
    stage_costs, terminal = augmented_cost_terms(st.problem, trial.X, trial.U, st.mult, st.hom)
    Jn = trial.cost = float(np.sum(stage_costs) + terminal)
    tol = opts.ddp.tr_ratio_tol
    expected, actual = -(gains.dv1 + gains.dv2), J - Jn
    if _accepted(expected, actual, J, Jn, 1 - tol, 1 + tol):
        return trial
    # a step predicted to gain less than tol_ddp: the ratio is round-off, any decrease will do
    small = expected < opts.ddp.tol * st.scale
    if small and actual >= 0 and math.isfinite(Jn):
        return trial
    if opts.ddp.stage_trust and math.isfinite(Jn):
        # the region, not the model, makes a trust-region step's expected decrease small: a
        # gap worth DDP's stopping test is a model failure, not round-off
        bad = blamed_stages(st, trial, stage_costs, expected, actual, opts.ddp.tol,
                             worth=expected - actual, blamed=blamed)
        if bad.size:
            return Blame(bad, 0.5 * np.linalg.norm(trial.dz[st.problem.nx:, bad], axis=0))
    return None


def _max_step(gains: Gains) -> float:
    """The largest stage step |a_k| of a sweep."""
    return float(np.sqrt(np.max(np.einsum("ki,ki->k", gains.a, gains.a))))


@dataclass
class StepControl:
    """The globalisation state of one DDP solve: the Q_uu regularisation rho, and either the
    line search's step length (carried between Dyn iterations, as in the reference code) or
    the trust-region radius (``SolverOptions.ddp.globalization``)."""

    opts: SolverOptions
    dyn: bool
    rho: float
    alpha: float = 1.0
    radius: float = math.inf
    stage_radius: np.ndarray | None = None   # (N,) the line search's per-stage trust region
    blamed: np.ndarray | None = None   # (N,) bool: stages blamed since the last accepted step

    @property
    def trust_region(self) -> bool:
        return self.opts.ddp.globalization is Globalization.TRUST_REGION

    @property
    def sweep_radius(self) -> float | np.ndarray:
        """The trust region the backward sweep bounds each stage's step by."""
        if self.stage_radius is None:
            return self.radius
        return np.minimum(self.stage_radius, self.radius)

    def step(self, st: Stages, gains: Gains, J: float) -> Trial | Blame | None:
        if self.trust_region:
            out = trust_region_step(st, gains, self.dyn, self.opts, J, self.stage_radius,
                                    self.blamed)
        else:
            out = line_search(st, gains, self.alpha if self.dyn else 1.0, self.dyn, self.opts,
                               J, self.stage_radius, self.blamed)
        if isinstance(out, Blame):
            if self.stage_radius is None:
                self.stage_radius = np.full(st.problem.N, math.inf)
                self.blamed = np.zeros(st.problem.N, dtype=bool)
            self.stage_radius[out.stages] = out.bounds
            self.blamed[out.stages] = True
        return out

    def indefinite(self) -> Status | None:
        """After a sweep that found Q_uu + rho I indefinite: raise rho (None) or give up."""
        self.rho = _raise_rho(self.rho, self.opts)
        return Status.QUU_INDEFINITE if self.rho > self.opts.ddp.rho_max else None

    def rejected(self, st: Stages, gains: Gains) -> Status | None:
        """After a rejected step: shrink the trust region, or raise rho for the line search
        (None), or give up."""
        o = self.opts
        if self.trust_region:   # eq. 37 of the many-revolution DDP paper, shrinking
            self.radius = (1.0 - o.ddp.tr_kappa) * min(self.radius, _max_step(gains))
            floor = 1e-12 * (1.0 + float(np.max(np.abs(st.U))))
            return Status.TRUST_REGION_COLLAPSED if self.radius < floor else None
        self.rho = _raise_rho(self.rho, o, o.ddp.short_step_rho_growth)
        return Status.LINE_SEARCH_FAILED if self.rho > o.ddp.rho_max else None

    def accepted(self, trial: Trial) -> None:
        if self.blamed is not None:
            self.blamed[:] = False
        if self.trust_region:   # eq. 37, growing (an unbounded region stays unbounded)
            self.radius *= 1.0 + self.opts.ddp.tr_kappa
            self.rho = _lower_rho(self.rho, self.opts)
        else:
            self.rho = _rho_after_step(self.rho, trial.alpha, self.opts)
            if self.dyn:
                self.alpha = min(1.0, 2.0 * trial.alpha)
        if self.stage_radius is not None:
            # a stage whose bound held the accepted step back gets a larger one, as a trust
            # region that held grows (eq. 37); the others keep theirs
            size = np.sqrt(np.sum(trial.dz[-trial.U.shape[1]:] ** 2, axis=0))
            binding = size >= 0.9 * self.stage_radius
            self.stage_radius[binding] *= 1.0 + self.opts.ddp.tr_kappa
