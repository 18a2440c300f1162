"""The augmented Lagrangian's safeguards beyond paper Alg. 4, each a named hook that ``aul``
calls (the cases that needed them, the measurements and the tests: docs/design-notes.md).

- ``fallback_options``: a line-search DDP solve cut off by its bound or stalled is solved
  again from its start with the trust region;
- ``without_drift``: states that the Dyn pass's re-centred maps let drift from the flow are
  restored;
- ``diverged``: a first DDP solve that ends far more violated than its infeasible start;
- ``ends_feasible``: a feasible iterate whose DDP solve was cut off gets one more solve;
- ``stalled``: the penalty at its cap without progress;
- ``unmoved``: the violation unmoved while the growing penalty dominated the cost, far above
  the tolerance.
"""
from __future__ import annotations

import numpy as np

from ..errors import DaddyError
from . import newton
from .deadline import Deadline
from .cost_scale import scale as cost_scale
from .lagrangian import Multipliers
from .optimality import objective
from .options import Globalization, SolverOptions
from .results import Status, not_halved
from .sweeps import Stages

# the trust region's |actual / expected - 1| tolerance when the line search falls back to it
FALLBACK_RATIO_TOL = 0.5
# a DDP solve that ended without its stopping test: not optimal where it stopped
CUT_OFF = (Status.DDP_MAX_ITER, Status.DDP_STALLED)
# the first DDP solve diverged when its max violation grew this many times over the start's
DIVERGED_GROWTH = 100.0
# the max violation is unmoved while it stays within this fraction of itself ...
UNMOVED_RTOL = 1e-2
# ... and counts as far above tol_aul beyond this many times it (Newton finishes nearer plateaus)
UNMOVED_FAR = 10.0


def fallback_options(res, opts: SolverOptions) -> SolverOptions | None:
    """The options to solve again with -- the trust region, at a ratio tolerance of at least
    ``FALLBACK_RATIO_TOL`` -- after a line-search DDP solve that ran into ddp_max_iter or
    stalled (``SolverOptions.aul.tr_fallback``), or None. The rest of that AUL loop (one homotopy
    step) keeps them; the next step starts with the line search again. Rationale: the trust
    region accepts only steps its model predicts, where the line search's path can leave it."""
    if not (opts.aul.tr_fallback and res.status in CUT_OFF
            and opts.ddp.globalization is Globalization.LINE_SEARCH):
        return None
    return opts.with_(ddp=dict(globalization=Globalization.TRUST_REGION,
                               tr_ratio_tol=max(opts.ddp.tr_ratio_tol, FALLBACK_RATIO_TOL)))


def without_drift(st: Stages, opts: SolverOptions, deadline: Deadline | None) -> Stages:
    """``st``, or -- when its states have drifted from the dynamics -- the expansions of a
    consistent trajectory near it: Newton's restoration (its stage defects and constraints to
    tol_newton; the controls' exact rollout when Newton fails; ``st`` itself when that rollout
    does not integrate either -- a near-collision the drifted states hid).

    A map re-centred after every accepted step (``sweeps.new_maps``) walks away from where it
    was expanded; the stages whose maps walked beyond their radius (``Stages.walked``) are
    checked against their exact flow (one batched float integration), and a defect above the
    maps' accuracy (eps_da) is drift."""
    p = st.problem
    k = np.flatnonzero(st.walked > st.radius)
    if k.size == 0:
        return st
    flows = _flown(lambda: p.step(st.X[k].T, st.U[k].T, p.stage_dt[k], p.stage_t0[k]))
    if flows is not None and not np.max(np.abs(flows - st.X[k + 1].T)) > st.eps_da:
        return st   # (a flow that does not integrate counts as drift)
    res = newton.polish(p, st.X, st.U, opts, deadline)
    X, U = (res.X, res.U) if res.converged else (_flown(lambda: p.rollout(st.U)), st.U)
    if X is None or not (np.all(np.isfinite(X)) and np.all(np.isfinite(U))):
        return st
    return Stages(p, X, U, st.mult, st.hom, st.eps_da, order=st.order)


def _flown(fly):
    """``fly()`` -- a float integration of the problem's flows -- or None where it does not
    integrate (a near-collision: the integrator out of steps; 1 / 0 on Python floats)."""
    try:
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            return fly()
    except (DaddyError, ArithmeticError):
        return None


def ends_feasible(res, gmax: float, after_cut_off: bool, opts: SolverOptions) -> bool:
    """A feasible iterate ends the augmented Lagrangian when its DDP solve ended on its own
    stopping test -- or when the solve before it (``after_cut_off``) also ran into its bound
    at a feasible point. Alg. 4 assumes its inner solves converged: a solve cut off by its
    bound is not optimal, so the loop gives DDP one more solve from there."""
    if not gmax <= opts.aul.tol:   # (NaN: not feasible, as Alg. 4's test before this one)
        return False
    return res.status not in CUT_OFF or after_cut_off


def diverged(gmax: float, gmax_start: float, both_cut_off: bool, opts: SolverOptions) -> bool:
    """The loop's first DDP solve diverged: from a start that violates the constraints
    (``gmax_start`` > tol_aul), neither the line search nor the trust region it fell back to
    converged (``both_cut_off``), and the max violation ended ``DIVERGED_GROWTH`` times the
    start's or more: raising the penalty would restart DDP further off than the guess. A
    restored (feasible) start never counts: leaving it is the penalty's normal trade."""
    return (both_cut_off and gmax_start > opts.aul.tol
            and gmax >= DIVERGED_GROWTH * gmax_start)


def at_cap(mult: Multipliers, opts: SolverOptions) -> bool:
    """Every penalty at mu_max."""
    return (float(np.min(mult.mu, initial=np.inf)) >= opts.aul.mu_max
            and float(np.min(mult.mu_t, initial=np.inf)) >= opts.aul.mu_max)


def stalled(history: list, capped: int, opts: SolverOptions) -> bool:
    """The augmented Lagrangian has stalled: the last ``aul_stall_iter`` DDP solves ran with
    the penalty at mu_max (``capped`` solves in a row did) and the max violation fell by less
    than half over them (an infeasible problem, or a local minimiser of the violation)."""
    return opts.aul.stall_iter <= capped and not_halved(history, opts.aul.stall_iter)


def penalty_dominates(st: Stages) -> bool:
    """The Lagrangian terms of the nominal's augmented cost (J~ - J: the multipliers' and the
    penalty's) exceed the cost itself, measured as the relative tests measure it (``cost_scale``:
    a constant in the cost changes nothing): a DDP solve of it minimises the violation more
    than the cost."""
    plain = objective(st.problem, st.X, st.U, st.hom)
    return st.cost - plain > cost_scale(plain, st.anchor)


def unmoved(history: list, dominated: list, opts: SolverOptions) -> bool:
    """The last ``aul_stall_iter`` + 1 max violations (``history``) lie within
    ``UNMOVED_RTOL`` of each other and above ``UNMOVED_FAR`` x tol_aul, and the penalty
    dominated each of the last ``aul_stall_iter`` solves (``dominated``, ``penalty_dominates``
    after each): the growing penalty moved nothing -- the DDP solves were minimising a
    violation they could not reduce (an infeasible problem, or a local minimiser of the
    violation). Stalled as at the cap, without climbing to it first. A plateau under a penalty
    still weaker than the cost is no stall: it moves once the penalty outweighs the cost
    (docs/design-notes.md)."""
    k = opts.aul.stall_iter
    if not 0 < k < len(history) or not all(dominated[-k:]):
        return False
    last = history[-1 - k:]
    return (min(last) > UNMOVED_FAR * opts.aul.tol
            and max(last) - min(last) <= UNMOVED_RTOL * max(last))
