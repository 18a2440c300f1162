"""Solver options: small typed objects instead of a 40-field parameter bag, and the method
enum of paper Table 1."""
from __future__ import annotations

from dataclasses import dataclass, fields, replace
from enum import Enum

from ..errors import DaddyError


class Sweep(Enum):
    """Backward sweep: Std (Alg. 7), Hess (Alg. 9, with dynamics Hessians), Q (Alg. 10)."""

    STD = "std"
    HESS = "hess"
    Q = "q"


class Method(Enum):
    """The six DDP variants of paper Table 1: a backward sweep, and whether the forward pass
    is the Dyn one (Alg. 8) instead of Std (Alg. 6)."""

    STD = "std"
    HESS = "hess"
    Q = "q"
    DYN = "dyn"
    HESSDYN = "hessdyn"
    QDYN = "qdyn"

    @property
    def sweep(self) -> Sweep:
        return Sweep(self.value.removesuffix("dyn") or "std")

    @property
    def dyn(self) -> bool:
        return self.value.endswith("dyn")

    @classmethod
    def parse(cls, method: "Method | str") -> "Method":
        """A Method from itself or its name; DaddyError naming the field otherwise."""
        if isinstance(method, cls):
            return method
        try:
            return cls(method)
        except ValueError:
            raise DaddyError(f"method must be one of {METHODS}, got {method!r}") from None


METHODS = tuple(m.value for m in Method)


class Globalization(Enum):
    """How a DDP iteration keeps its step where the quadratic model holds: a backtracking line
    search on the feedforward step (the reference code), or a trust region on every stage's
    step with acceptance by the reduction ratio (HDDP, PDDP, the many-revolution DDP paper)."""

    LINE_SEARCH = "line_search"
    TRUST_REGION = "trust_region"


@dataclass(frozen=True)
class SolverOptions:
    """Tolerances and algorithm parameters (defaults: the reference code's values), grouped by
    the part of the solver that reads them.

    DDP (Alg. 3):
        tol_ddp: relative cost decrease that stops a DDP solve (after >= ddp_min_iter).
        ddp_min_iter: iterations before the tol_ddp test applies (the reference: 3; a warm
            start from a converged solution can stop after 1).
        ddp_max_iter: iteration bound of one DDP solve.
        ddp_stall_iter, ddp_stall_alpha: DDP has stalled (``Status.DDP_STALLED``) when
            ddp_stall_iter steps in a row were each shorter than ddp_stall_alpha of the full step
            (the line search's alpha; in the trust-region retry of a failed line search, the
            region's radius / step, a rejected step counting as zero) and lowered the cost by
            less than tol_ddp (relative): the model holds along a vanishing fraction of each
            step, and the iteration bound would be spent crawling (``stopping.crawling``: the
            measurement). 0 turns the test off.
        rho_init, rho_min, rho_max, rho_factor: Quu regularisation schedule.
        ls_min_ratio, ls_max_ratio, ls_shrink, ls_max_halvings: backtracking line search; a step
            is accepted when actual / expected decrease is in (min, max).
        short_step, short_step_rho_growth: when an accepted step was shortened below
            ``short_step``, multiply rho by ``short_step_rho_growth`` (Levenberg-Marquardt-like
            damping of a model that promises too much, e.g. controls in the linear part of the
            pseudo-Huber cost). 0 (default): accepted steps never raise rho, as in the
            reference. A line search that fails altogether always raises rho by
            ``short_step_rho_growth`` (the reference: by rho_factor, which let DDP stall for
            hundreds of forward passes while rho crept up).
        globalization: ``Globalization`` (or its value): "line_search" or "trust_region".
        stage_trust: a trust region per stage: when the line search's first trial (or a
            trust-region step) fails because the stage cost's own model failed at a few stages
            (``globalization.blamed_stages``), those stages' control changes are bounded to half of
            what failed (the sweep's per-stage radius and the forward pass's clamp) and the
            sweep runs again, instead of one shorter step length (or a smaller region) for
            every stage; an accepted step that a bound held back grows that bound by
            (1 + tr_kappa).
        tr_fallback: with the line search, a DDP solve that runs into ddp_max_iter (or stalls)
            is solved again from its start with the trust region, which the rest of that
            homotopy step keeps (``aul_safeguards.fallback_options``).
        tr_ratio_tol, tr_kappa: the trust region accepts a step when |actual / expected - 1|
            <= tr_ratio_tol and then grows its radius by (1 + tr_kappa), else shrinks it by
            (1 - tr_kappa) and sweeps again on the same expansions (PDDP's Table 2: 0.1, 0.25;
            the many-revolution DDP paper's eq. 37). The first step is unbounded (the papers
            start from the control bound, which a general problem does not name): the first
            rejection sets the radius to (1 - tr_kappa) times that step's largest stage step.
        carry_rho: each DDP solve of an AUL loop resumes from the previous one's rho instead
            of rho_init (each homotopy step restarts from rho_init or the warm start's rho:
            carried across homotopy steps it led the halo case to a worse local optimum).
    Augmented Lagrangian (Alg. 4, eq. 8-9):
        tol_aul: maximum constraint violation that stops the augmented Lagrangian.
        aul_max_iter: outer iteration bound.
        lambda_max, mu_init, mu_max, mu_growth: multiplier bound and penalty schedule.
        aul_stall_iter: stop (``Status.AUL_STALLED``) when the penalty has been at mu_max for
            this many outer iterations and the max violation fell by less than half over them
            (0: never): a failing solve then says so in seconds instead of spending its
            aul_max_iter iterations or its time budget.
    Newton (Alg. 5 / 11):
        tol_newton: maximum constraint violation targeted by Newton polishing.
        newton_max_iter: outer iterations (one expansion each); newton_inner_max_iter: inner
            iterations on one polynomial model; newton_ls_shrink, newton_ls_max_halvings: the
            backtracking of an inner step (it must reduce the model's max residual).
        newton_stall_iter: stop (``Status.NEWTON_STALLED``) when the best residual did not
            halve over this many outer iterations, or the residual stopped moving
            (``newton._flat``), and (``Status.NEWTON_NO_DESCENT``) when a fresh model above the
            best residual cannot be taken down by 1 % (0: none of these): each outer iteration
            converges its model at a Newton rate, so a run this slow is one that will not
            converge.
        newton_cv_ratio: the convergence-rate threshold (eps_CV, paper Alg. 5).
        newton_active_tol: an inequality with g > -tol is treated as active.
        newton_regularisation: diagonal added to Delta Delta^T if it is not positive definite.
        newton_control_weight_floor: the steps weigh each stage's control by
            max(|u_k| / u_max, floor)^2 (problems with a thrust bound), so that coasting stages
            keep coasting and the thrust arcs take the correction (see ``newton``); 0: the
            paper's plain minimum-norm steps.
        polish_from_ddp_maps: start the polishing from the DDP's last stage maps (re-centred
            where the step stays inside their radius) instead of expanding every stage. Off by
            default: maps re-centred again and again carry derivative errors, and closed-loop
            arrival plans polished this way missed their target by more.
    Start:
        restore_start: before DDP, drive the initial guess -- cold or warm -- to feasibility
            with Newton (``newton.polish``); when Newton does not get there from a cold
            guess that thrusts, it restores the ballistic trajectory (zero control) instead;
            when that stalls too (e.g. Earth-Mars: the ballistic flight is far from Mars), DDP
            starts from the guess itself. If DDP does not converge (e.g. the time budget), the
            solve returns the restored feasible iterate (converged=False, with the reason).
            Why it is the default, for cold starts too: the augmented Lagrangian starts with a
            penalty of mu_init, under which DDP's first solve from a random guess trades the
            thrust bound for the terminal miss: on DRO->DRO its iterates took the thrust to
            3 u_max and the trajectory to a lunar flyby at 4,400 km, where the line search
            crawled at steps of 1e-4 until the time budget ran out; from the restored guess
            the energy step starts feasible and stays near it (robustness harness, random
            guesses: DRO->DRO 91 -> 96 of 100, halo 18 -> 21 of 30, Earth-Mars 100 of 100
            either way; with the ballistic fallback DRO 100 of 100, halo 28 of 30). From the
            paper's near-zero guess the restoration converges on the halo and DRO transfers
            (same optima) and stalls on Earth-Mars, Lyapunov and NRHO->DRO (the guess is used
            as before).
        map_reach: Newton and the restoration's rollout re-centre stage maps up to this many
            times their convergence radius (eps_da): Newton's residuals are exact, so
            derivatives a little less accurate only slow its convergence, and an outer
            iteration that does not reduce the residual expands afresh.
    Path constraints (``Problem.g_path``; ``path_constraints``, ``path_exchange``):
        path_exchange_rounds: after the solve, at most this many rounds of the exchange step:
            the dense DOP853 check finds where g_path rises above zero between a stage's
            samples, those samples are tightened (``path_constraints.tightened``) and the last
            homotopy step is solved again from the solution (0: the samples alone; the
            dense margin is still reported, and a violation between them fails the solve).
    Homotopy (eq. 12-14):
        homotopy: sequence of (h, delta) pairs (h = Huber weight, delta = Huber width).
    Optimality (``optimality``: the relative KKT residual reported as
    ``Solution.kkt_residual``):
        tol_optimality: a polished solve converges when its final iterate meets the
            constraints and its KKT residual is at most this (``polish=False``: the residual is
            reported, the DDP's own test decides; inf: neither evaluated nor checked, as the
            guidance node's warm re-plans run, and ``Solution.kkt_residual`` is None). Above it
            after the Newton polishing, the KKT polishing (``kkt_polish``: Newton on the KKT
            conditions, each step restored to feasibility) runs for at most ``kkt_max_iter``
            iterations: DDP's relative-decrease test stops early on ill-conditioned problems,
            where a step along a stiff direction gains little however large the gradient.
        kkt_cost_slack: a KKT step whose cost at Y + dY misses the cost's own quadratic model
            by more than this many predicted decreases is refused before its restoration (it
            left the region where the cost is quadratic) and the Hessian shift raised.
        kkt_trial_violation: a KKT step whose point violates the constraints by more than
            this many times its own size (max |dY|) is refused before its restoration (the
            linearisation's remainder is second order in the step: the step left the region
            where the model holds) and the Hessian shift raised.
        kkt_chord_iter, kkt_restore_iter: a KKT step's restoration to feasibility: chord
            iterations on the step's own Jacobian first (each one float integration), then
            Newton with at most kkt_restore_iter iterations (a step needing more left the
            region where the linearisation holds: a larger shift is cheaper).
        kkt_resolves: when the KKT polishing ends above tol_optimality, the last homotopy step
            is solved again (AUL + DDP, then both polishings) from the polished iterate with
            its KKT multipliers, at most this many times, and kept when it ends with a smaller
            KKT residual (``solve``: why).
        exact_fuel: a fuel-optimal solve of a problem that has an exact fuel form (``throttle``:
            the thrust as throttle and direction, the propellant linear in the throttle) ends
            with the KKT polishing of that form, for at most ``exact_fuel_max_iter`` iterations,
            instead of polishing the pseudo-Huber cost of the last homotopy step: the solution
            is the true fuel optimum (``throttle``: why). It is tried from the energy-optimal
            (first) step's solution, stopped when its lowest KKT residual has not halved over
            ``exact_fuel_stall_iter`` iterations (GTO->GEO's halves only over tens of them, on
            its way to converging in 95), then from the end of the rest of the homotopy,
            stopped after ``exact_fuel_end_stall_iter`` (near the optimum there, it converges
            in 15 or creeps); if neither converges, the last step's pseudo-Huber end game runs
            (``solve._exact_end``: why).
    Run:
        time_budget_s: wall-clock budget for the whole solve (None: unbounded).
        verbose: print progress lines (homotopy step, AUL iteration, violation, cost).
    """

    tol_ddp: float = 1e-4
    tol_aul: float = 1e-6
    tol_newton: float = 1e-10
    rho_init: float = 0.0
    rho_min: float = 1e-8
    rho_max: float = 1e8
    rho_factor: float = 1.6
    ls_min_ratio: float = 1e-8
    ls_max_ratio: float = 10.0
    ls_shrink: float = 0.5
    ls_max_halvings: int = 20
    short_step: float = 0.0
    short_step_rho_growth: float = 10.0
    carry_rho: bool = False
    globalization: Globalization = Globalization.LINE_SEARCH
    stage_trust: bool = True
    tr_ratio_tol: float = 0.1
    tr_fallback: bool = True
    tr_kappa: float = 0.25
    restore_start: bool = True
    polish_from_ddp_maps: bool = False
    ddp_max_iter: int = 200
    ddp_min_iter: int = 3
    ddp_stall_iter: int = 20
    ddp_stall_alpha: float = 1e-3
    aul_max_iter: int = 40
    newton_max_iter: int = 60
    lambda_max: float = 1e8
    mu_init: float = 1.0
    mu_max: float = 1e8
    mu_growth: float = 10.0
    aul_stall_iter: int = 3
    newton_cv_ratio: float = 1.1
    newton_stall_iter: int = 10
    newton_active_tol: float = 1e-6
    newton_regularisation: float = 1e-12
    newton_control_weight_floor: float = 1e-2
    newton_inner_max_iter: int = 20
    newton_ls_shrink: float = 0.5
    newton_ls_max_halvings: int = 25
    map_reach: float = 10.0
    homotopy: tuple = ((0.0, 1e-2),)
    tol_optimality: float = 1e-4
    kkt_max_iter: int = 30
    kkt_cost_slack: float = 5.0
    kkt_trial_violation: float = 100.0
    kkt_chord_iter: int = 6
    kkt_restore_iter: int = 4
    kkt_resolves: int = 1
    exact_fuel: bool = True
    exact_fuel_max_iter: int = 100
    exact_fuel_stall_iter: int = 50
    exact_fuel_end_stall_iter: int = 10
    path_exchange_rounds: int = 4
    time_budget_s: float | None = None
    verbose: bool = False

    def __post_init__(self):
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name in ("homotopy", "time_budget_s", "globalization") or f.type == "bool":
                continue
            if not isinstance(v, (int, float)) or v != v or v < 0:
                raise DaddyError(f"options.{f.name} must be a non-negative number, got {v!r}")
        for name in ("tol_ddp", "tol_aul", "tol_newton", "tol_optimality", "rho_max",
                     "rho_factor", "mu_growth"):
            if getattr(self, name) <= 0:
                raise DaddyError(f"options.{name} must be > 0")
        try:
            object.__setattr__(self, "globalization", Globalization(self.globalization))
        except ValueError:
            raise DaddyError("options.globalization must be one of "
                             f"{[g.value for g in Globalization]}, got {self.globalization!r}") \
                from None
        for name in ("ls_shrink", "newton_ls_shrink", "tr_kappa"):
            if not 0 < getattr(self, name) < 1:
                raise DaddyError(f"options.{name} must be in (0, 1), got {getattr(self, name)!r}")
        if self.newton_control_weight_floor > 1:
            raise DaddyError("options.newton_control_weight_floor must be in [0, 1], got "
                             f"{self.newton_control_weight_floor!r}")
        try:
            hom = tuple(tuple(map(float, p)) for p in self.homotopy)
        except (TypeError, ValueError) as exc:
            raise DaddyError("options.homotopy must be a sequence of (h, delta) number pairs") \
                from exc
        if not hom or any(len(p) != 2 or not (0 <= p[0] <= 1) or not p[1] > 0 for p in hom):
            raise DaddyError("options.homotopy must be a non-empty sequence of (h in [0, 1], delta > 0)")
        object.__setattr__(self, "homotopy", hom)
        tb = self.time_budget_s
        if tb is not None and (isinstance(tb, bool) or not isinstance(tb, (int, float))
                               or not tb > 0):
            raise DaddyError(f"options.time_budget_s must be > 0, got {self.time_budget_s!r}")

    @property
    def eps_da(self) -> float:
        """Accuracy of the Dyn method's polynomial radius: min(eps_AUL, eps_DDP)."""
        return min(self.tol_aul, self.tol_ddp)

    def with_(self, **kw) -> "SolverOptions":
        return replace(self, **kw)


def case_options(case, fuel_optimal: bool, **overrides) -> SolverOptions:
    """The paper's solver settings for a catalogue case."""
    s = case.solver
    hom = s.get("homotopy", {"h": [0.0], "delta": [1e-2]})
    pairs = tuple(zip(hom["h"], hom["delta"])) if fuel_optimal else ((0.0, hom["delta"][0]),)
    kw = dict(tol_ddp=s.get("tol_ddp", 1e-4), tol_aul=s.get("tol_aul", 1e-6),
              tol_newton=s.get("tol_newton", 1e-10), rho_max=s.get("rho_max", 1e8), homotopy=pairs)
    kw.update(overrides)
    return SolverOptions(**kw)


__all__ = ["METHODS", "Globalization", "Method", "SolverOptions", "Sweep", "case_options"]
