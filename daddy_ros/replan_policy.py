"""How a re-optimisation is solved: the solver options of a cold solve, of a warm re-plan and
of the arrival phase, and the thrust-margin ladder. ROS-free.

A warm re-plan starts from a converged plan shifted to the new state (``shift``):
The core names this preset (``SolverOptions.warm_replan``); why each of its settings:
- it runs the last homotopy step only (the plan is fuel-optimal already), the tol_ddp test may
  stop DDP after one iteration, and the penalty resumes high (``options.WARM_MU_INIT``) next
  to the carried
  multipliers: with mu = 1 the first DDP pass trades the constraints away and the solve takes
  far longer;
- shortened DDP steps raise the Quu damping instead of crawling (``ddp.short_step``), and rho
  carries over between solves; no per-stage trust region (one DDP step from a restored start:
  a stage bound would only hold back its convergence test for another iteration);
- ``restore_first``: Newton first restores feasibility from the plan's stage maps, so that a
  solve stopped by its time budget still flies a feasible plan from the new state;
- a polished re-plan stops the AUL at WARM_TOL_AUL unless tol_aul is given: Newton takes the
  constraints to tol_newton anyway, and the AUL rounds below it change the cost very little
  for a large share of the re-plan time;
- Newton treats inequalities within WARM_ACTIVE_TOL of their bound as active: the AUL leaves a
  fuel-optimal plan's full-thrust arcs slightly inside the bound, and with them inactive
  Newton's first minimum-norm step pushed them past it and the next ones pulled them back;
- the stall rules of cold solves are off (``aul.stall_iter``, ``newton.stall_iter``): the
  penalty starts three growth steps below its cap, so "three solves at the cap" is no stall
  there, and a re-plan that cannot meet its target has the thrust-margin ladder and the last
  valid plan to fall back on;
- the KKT residual is neither evaluated nor polished (``kkt.tol`` = inf): its
  expansion of every stage and the KKT polishing's would cost a re-plan more than its whole
  latency target allows, and a re-plan starts next to a plan that was polished;
- no least-violation solve certifies an unmet end (``end_game.certify_infeasibility``): the
  arrival re-plans that cannot meet the target (execution errors in the last hours) are
  expected, the ladder and the last valid plan handle them, and the extra solve cost them
  seconds (halo, 20 flights: the slowest re-plan 17.2 s with it, 2.8 s without; Earth-Mars,
  10 flights: 6.5 s CPU per flight against 5.1 s, the same misses).
The arrival phase (the split last stages) keeps the case's AUL tolerance, Newton active
set and fresh expansions for the polish: its plans decide the arrival miss.

Plans keep a thrust margin for closed-loop corrections and give it up rung by rung
(MARGIN_LADDER) only as far as the target demands: a fuel-optimal plan rides its bound, so a
plan that took the full rating at once has nothing left for the next execution error.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from daddy_core.catalogue import Case
from daddy_core.solver import SolverOptions, case_options

from .config import PlannerConfig
from .plan import SATURATION_SLACK

# augmented-Lagrangian tolerance of a polished warm re-optimisation without an explicit tol_aul
WARM_TOL_AUL = 1e-5
# a warm re-optimisation's Newton steps hold inequalities within this of their bound on it (the
# thrust bound is |u|^2 / u_max^2 - 1 <= 0: |u| within 5e-5 relative of u_max)
WARM_ACTIVE_TOL = 1e-4
# thrust ratings a re-plan climbs through when the one below cannot meet the target, as the
# fraction of the thrust margin still held back (1: the derated bound, 0: the full rating)
MARGIN_LADDER = (1.0, 0.6, 0.3, 0.0)
# the climb stops when a rung leaves more than this fraction of the miss of the rung below
LADDER_MIN_GAIN = 0.9


@dataclass(frozen=True)
class ReplanPolicy:
    """The solver options of each kind of solve.

    Attributes:
        cold: a solve without a plan (the case's settings, the whole homotopy).
        warm: a warm re-plan before the arrival phase (see the module docstring).
        arrival: a warm re-plan of the arrival phase.
    """

    cold: SolverOptions
    warm: SolverOptions
    arrival: SolverOptions

    @classmethod
    def of(cls, case: Case, config: PlannerConfig) -> "ReplanPolicy":
        aul, newton = {}, {}
        if config.tol_aul:
            aul["tol"] = config.tol_aul
        if config.tol_newton:
            newton["tol"] = config.tol_newton
        cold = case_options(case, config.fuel_optimal, aul=aul, newton=newton,
                            run=dict(time_budget_s=config.time_budget_s))
        warm_tol_aul = config.tol_aul or (max(WARM_TOL_AUL, cold.aul.tol) if config.polish
                                          else cold.aul.tol)
        warm = SolverOptions.warm_replan(cold, warm_tol_aul, WARM_ACTIVE_TOL,
                                         bool(config.restore_first))
        arrival = warm.with_(aul=dict(tol=cold.aul.tol), end_game=dict(exact_start=False),
                             newton=dict(polish_from_ddp_maps=False,
                                         active_tol=cold.newton.active_tol))
        return cls(cold, warm, arrival)

    def options(self, warm: bool, arrival: bool) -> SolverOptions:
        """The options of a cold solve, a warm re-plan or one of the arrival phase."""
        if not warm:
            return self.cold
        return self.arrival if arrival else self.warm

    def with_warm(self, **options) -> "ReplanPolicy":
        """Warm re-plans (arrival phase included) with other solver options, as
        ``SolverOptions.with_`` takes them (experiments)."""
        return replace(self, warm=self.warm.with_(**options),
                       arrival=self.arrival.with_(**options))


def lowest_rung(peak, ratings) -> np.ndarray:
    """The lowest rung of the margin ladder (its ``ratings``, lowest first, any one unit) whose
    bound the peak thrust ``peak`` (scalar or (S,), same unit) keeps to, within the
    saturation slack; the top rung when none does."""
    bounds = np.asarray(ratings, float) * (1 + SATURATION_SLACK)
    return np.searchsorted(bounds, peak).clip(0, len(bounds) - 1)


def margin_ratings(rating_n: float, thrust_margin: float) -> list[float]:
    """The thrust bounds [N] of the margin ladder's rungs, lowest first."""
    return [rating_n * (1.0 - thrust_margin * held)
            for held in (MARGIN_LADDER if thrust_margin > 0 else (0.0,))]
