"""Solver options grouped by the algorithm that reads them (``SolverOptions``: DDP, AUL, Newton,
start, KKT, end game, homotopy, run; defaults: the reference code's values), the node's warm
re-plan preset (``SolverOptions.warm_replan``), and the method enum of paper Table 1."""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, fields, replace
from enum import Enum

from ..da.monomials import MAX_ORDER as MAX_MAP_ORDER
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


class UnrestoredStates(Enum):
    """Where a solve goes from a state guess (``WarmStart.X``) its restoration could not make
    feasible: FROM_CONTROLS, the restoration's fallbacks and DDP from the rollout of the
    guess's controls (what a solve given only those controls would do); STOP, the state guess
    is the only start tried: the solve ends there unconverged -- for a caller to whom the
    rest is nothing new (``blend.restart_from_blend`` after a solve from the same controls,
    whose restoration tried the ballistic flight too: the rest would repeat it)."""

    FROM_CONTROLS = "from_controls"
    STOP = "stop"


class MultiplierUpdate(Enum):
    """How the AUL moves its multipliers: after each DDP solve, eq. 9's first-order step
    lam + mu g, or the second-order one of HDDP and DA-HDDP (``multiplier_update``: the
    multipliers of the KKT system of the Lagrangian's quadratic model at the DDP solution); or
    SWEEP: the terminal equalities' multipliers are variables of every DDP iteration's backward
    sweep (HDDP; ``multiplier_sweep``), the other rows eq. 9."""

    FIRST_ORDER = "first_order"
    SECOND_ORDER = "second_order"
    SWEEP = "sweep"


def _check(group: object, prefix: str) -> None:
    """Every number of an options group non-negative and not NaN (DaddyError naming it)."""
    for f in fields(group):
        v = getattr(group, f.name)
        if f.type in ("bool", "Globalization", "MultiplierUpdate", "UnrestoredStates") \
                or isinstance(v, bool):
            continue
        if not isinstance(v, (int, float)) or v != v or v < 0:
            raise DaddyError(f"options.{prefix}.{f.name} must be a non-negative number, got {v!r}")


def _positive(group: object, prefix: str, *names: str) -> None:
    for name in names:
        if not getattr(group, name) > 0:
            raise DaddyError(f"options.{prefix}.{name} must be > 0")


def _fraction(group: object, prefix: str, *names: str) -> None:
    for name in names:
        if not 0 < getattr(group, name) < 1:
            raise DaddyError(f"options.{prefix}.{name} must be in (0, 1), got "
                             f"{getattr(group, name)!r}")


class _Group:
    """Shared by the option groups: ``with_`` (a copy with some fields replaced)."""

    def with_(self, **kw):
        return replace(self, **kw)


@dataclass(frozen=True)
class DDPOptions(_Group):
    """DDP (Alg. 3): stopping, Q_uu regularisation, globalisation."""

    tol: float = 1e-4                 # relative cost decrease that stops a solve (>= min_iter)
    min_iter: int = 3                 # iterations before the tol test applies
    max_iter: int = 200               # iteration bound of one solve
    stall_iter: int = 20              # short steps without progress in a row: stalled (0: off)
    stall_alpha: float = 1e-3         # the step fraction below which a step counts as cut short
    rho_init: float = 0.0             # Q_uu regularisation at the start of a solve
    rho_min: float = 1e-8             # smallest non-zero rho
    rho_max: float = 1e8              # rho above which a solve gives up
    rho_factor: float = 1.6           # rho's growth / shrink factor
    ls_min_ratio: float = 1e-8        # line search: accepted when actual / expected decrease >
    ls_max_ratio: float = 10.0        #   ls_min_ratio and < ls_max_ratio
    ls_shrink: float = 0.5            # step-length factor of a backtrack
    ls_max_halvings: int = 20         # backtracks before the line search fails
    short_step: float = 0.0           # an accepted step shorter than this raises rho (0: never)
    short_step_rho_growth: float = 10.0   # rho's factor after a short step or a failed line search
    globalization: Globalization = Globalization.LINE_SEARCH   # line search or trust region
    stage_trust: bool = True          # bound the few stages a failed step is blamed on
    tr_ratio_tol: float = 0.1         # trust region: accepted when |actual / expected - 1| <= this
    tr_kappa: float = 0.25            # trust region: radius times 1 + kappa, or 1 - kappa
    carry_rho: bool = False           # each solve of an AUL loop resumes from the last one's rho
    map_order: int = 2                # the stage maps' order, 2-6 (the Dyn pass evaluates them)

    def __post_init__(self):
        _check(self, "ddp")
        _positive(self, "ddp", "tol", "rho_max", "rho_factor")
        if (isinstance(self.map_order, bool) or not isinstance(self.map_order, numbers.Integral)
                or self.map_order not in range(2, MAX_MAP_ORDER + 1)):
            raise DaddyError(f"options.ddp.map_order must be an integer in 2..{MAX_MAP_ORDER}, "
                             f"got {self.map_order!r}")
        _fraction(self, "ddp", "ls_shrink", "tr_kappa")
        try:
            object.__setattr__(self, "globalization", Globalization(self.globalization))
        except ValueError:
            raise DaddyError("options.ddp.globalization must be one of "
                             f"{[g.value for g in Globalization]}, got {self.globalization!r}") \
                from None


@dataclass(frozen=True)
class AULOptions(_Group):
    """The augmented Lagrangian (Alg. 4, eq. 8-9) and its safeguards."""

    tol: float = 1e-6                 # max constraint violation that ends the loop
    max_iter: int = 40                # outer iteration bound
    lambda_max: float = 1e8           # multiplier bound
    mu_init: float = 1.0              # penalty at the start of each homotopy step
    mu_max: float = 1e8               # penalty cap
    mu_growth: float = 10.0           # penalty growth per outer iteration
    stall_iter: int = 3               # solves at mu_max, violation not halved: stalled (0: off)
    tr_fallback: bool = True          # a line-search solve cut off is retried with the trust region
    multiplier_update: MultiplierUpdate = MultiplierUpdate.FIRST_ORDER   # eq. 9, 2nd order, sweep

    def __post_init__(self):
        _check(self, "aul")
        _positive(self, "aul", "tol", "mu_growth")
        if not isinstance(self.multiplier_update, MultiplierUpdate):
            try:
                object.__setattr__(self, "multiplier_update",
                                   MultiplierUpdate(self.multiplier_update))
            except ValueError:
                raise DaddyError("options.aul.multiplier_update must be one of "
                                 f"{[m.value for m in MultiplierUpdate]}, got "
                                 f"{self.multiplier_update!r}") from None


@dataclass(frozen=True)
class NewtonOptions(_Group):
    """Newton's restoration and polishing of the constraints (Alg. 5 / 11)."""

    tol: float = 1e-10                # max constraint violation targeted
    max_iter: int = 60                # outer iterations (one constraint model each)
    inner_max_iter: int = 20          # inner iterations on one polynomial model
    ls_shrink: float = 0.5            # backtracking factor of an inner step
    ls_max_halvings: int = 25         # backtracks of an inner step
    stall_iter: int = 10              # outer iterations, residual not halved: stalled (0: off)
    cv_ratio: float = 1.1             # convergence-rate threshold (eps_CV, Alg. 5)
    active_tol: float = 1e-6          # an inequality with g > -active_tol is active
    regularisation: float = 1e-12     # diagonal added to Delta Delta^T if not positive definite
    control_weight_floor: float = 1e-2    # control weights max(|u|/u_max, floor)^2 (0: plain)
    map_reach: float = 10.0           # stage maps are re-centred up to this many radii
    polish_from_ddp_maps: bool = False    # polish from DDP's last maps instead of fresh expansions

    def __post_init__(self):
        _check(self, "newton")
        _positive(self, "newton", "tol")
        _fraction(self, "newton", "ls_shrink")
        if self.control_weight_floor > 1:
            raise DaddyError("options.newton.control_weight_floor must be in [0, 1], got "
                             f"{self.control_weight_floor!r}")


@dataclass(frozen=True)
class StartOptions(_Group):
    """Where DDP starts (``start``)."""

    restore: bool = True              # drive any guess to feasibility with Newton before DDP
    # a state guess the restoration could not make feasible: DDP from the guess's controls, or stop
    unrestored_states: UnrestoredStates = UnrestoredStates.FROM_CONTROLS

    def __post_init__(self):
        _check(self, "start")
        if not isinstance(self.unrestored_states, UnrestoredStates):
            try:
                object.__setattr__(self, "unrestored_states",
                                   UnrestoredStates(self.unrestored_states))
            except ValueError:
                raise DaddyError(f"options.start.unrestored_states must be one of "
                                 f"{[m.value for m in UnrestoredStates]}, got "
                                 f"{self.unrestored_states!r}") from None


@dataclass(frozen=True)
class KKTOptions(_Group):
    """First-order optimality (``optimality``) and the KKT polishing (``kkt_polish``)."""

    tol: float = 1e-4                 # KKT residual a polished solve reaches (inf: not evaluated)
    max_iter: int = 30                # KKT polishing iterations
    cost_slack: float = 5.0           # refuse a step missing its cost model by this many
    trial_violation: float = 100.0    # a step violating by this many times its size is refused
    chord_iter: int = 6               # chord iterations of a step's restoration
    restore_iter: int = 10            # Newton iterations of a step's restoration, at most
    restore_stall_iter: int = 2       # ... which stops when not halved over these (refused)

    def __post_init__(self):
        _check(self, "kkt")
        _positive(self, "kkt", "tol")


@dataclass(frozen=True)
class EndGameOptions(_Group):
    """The end game's attempts (``end_game``) and the path constraints' exchange."""

    exact_fuel: bool = True           # a fuel solve ends in the exact (throttle) fuel form
    exact_fuel_max_iter: int = 100    # KKT iterations of an exact fuel attempt
    exact_fuel_stall_iter: int = 50   # the attempt from the energy step stops unhalved after these
    exact_fuel_end_stall_iter: int = 10   # the attempt from the homotopy's end likewise
    exact_start: bool = False         # a warm fuel solve starts in the exact form (exact_start)
    exact_start_iter: int = 6         # Newton iterations of its restoration (more: no fit)
    resolves: int = 1                 # re-solves of the last step after a stalled KKT polishing
    path_exchange_rounds: int = 4     # exchange rounds of g_path between the nodes (0: none)
    certify_infeasibility: bool = True   # an unmet end gets a least-violation solve (infeasibility)
    blend_restart: bool = True        # an unmet end is solved again from the blended states (blend)

    def __post_init__(self):
        _check(self, "end_game")
        _positive(self, "end_game", "exact_start_iter")


@dataclass(frozen=True)
class RunOptions(_Group):
    """The whole solve."""

    time_budget_s: float | None = None    # wall-clock budget [s] (None: unbounded)
    verbose: bool = False             # print progress lines

    def __post_init__(self):
        tb = self.time_budget_s
        if tb is not None and (isinstance(tb, bool) or not isinstance(tb, (int, float))
                               or not tb > 0):
            raise DaddyError(f"options.run.time_budget_s must be > 0, got {tb!r}")


@dataclass(frozen=True)
class PolicyOptions(_Group):
    """The feedback laws a converged solve returns (``daddy_core.policy``)."""

    order: int = 0                    # the laws' order, 1-5 (stage maps one order higher); 0: none

    def __post_init__(self):
        if isinstance(self.order, bool) or self.order not in range(0, 6):
            raise DaddyError(f"options.policy.order must be an integer in 0..5 (0: no policy), "
                             f"got {self.order!r}")


GROUPS = {"ddp": DDPOptions, "aul": AULOptions, "newton": NewtonOptions, "start": StartOptions,
          "kkt": KKTOptions, "end_game": EndGameOptions, "run": RunOptions,
          "policy": PolicyOptions}

# the options' flat names before they were grouped -> (group, field): for the errors that name
# a field's new place, and for the flat per-case settings of case files
MOVED = {
    "tol_ddp": ("ddp", "tol"), "ddp_min_iter": ("ddp", "min_iter"),
    "ddp_max_iter": ("ddp", "max_iter"), "ddp_stall_iter": ("ddp", "stall_iter"),
    "ddp_stall_alpha": ("ddp", "stall_alpha"),
    **{k: ("ddp", k) for k in ("rho_init", "rho_min", "rho_max", "rho_factor", "ls_min_ratio",
                               "ls_max_ratio", "ls_shrink", "ls_max_halvings", "short_step",
                               "short_step_rho_growth", "globalization", "stage_trust",
                               "tr_ratio_tol", "tr_kappa", "carry_rho")},
    "tol_aul": ("aul", "tol"), "aul_max_iter": ("aul", "max_iter"),
    "aul_stall_iter": ("aul", "stall_iter"),
    **{k: ("aul", k) for k in ("lambda_max", "mu_init", "mu_max", "mu_growth", "tr_fallback")},
    "tol_newton": ("newton", "tol"),
    **{f"newton_{k}": ("newton", k) for k in ("max_iter", "inner_max_iter", "ls_shrink",
                                              "ls_max_halvings", "stall_iter", "cv_ratio",
                                              "active_tol", "regularisation",
                                              "control_weight_floor")},
    "map_reach": ("newton", "map_reach"),
    "polish_from_ddp_maps": ("newton", "polish_from_ddp_maps"),
    "restore_start": ("start", "restore"),
    "tol_optimality": ("kkt", "tol"),
    **{f"kkt_{k}": ("kkt", k) for k in ("max_iter", "cost_slack", "trial_violation",
                                        "chord_iter", "restore_iter")},
    "kkt_resolves": ("end_game", "resolves"),
    **{k: ("end_game", k) for k in ("exact_fuel", "exact_fuel_max_iter", "exact_fuel_stall_iter",
                                    "exact_fuel_end_stall_iter", "path_exchange_rounds")},
    "time_budget_s": ("run", "time_budget_s"), "verbose": ("run", "verbose"),
}


def _homotopy(steps) -> tuple:
    """The (h, delta) steps as a tuple of float pairs (DaddyError naming the field)."""
    try:
        hom = tuple(tuple(map(float, p)) for p in steps)
    except (TypeError, ValueError) as exc:
        raise DaddyError("options.homotopy must be a sequence of (h, delta) number pairs") \
            from exc
    if not hom or any(len(p) != 2 or not (0 <= p[0] <= 1) or not p[1] > 0 for p in hom):
        raise DaddyError("options.homotopy must be a non-empty sequence of (h in [0, 1], "
                         "delta > 0)")
    return hom


@dataclass(frozen=True, init=False)
class SolverOptions:
    """Every tolerance and limit of a solve, one group per algorithm (each group's fields are
    documented where the group is defined): ``ddp``, ``aul``, ``newton``, ``start``, ``kkt``,
    ``end_game``, ``run``, ``policy``, and ``homotopy``, the (h, delta) steps of eq. 12-14.

    A group is given as its object or as a dict of its fields, e.g.
    ``SolverOptions(ddp=dict(tol=1e-6), kkt=dict(max_iter=50))``; ``with_`` replaces fields the
    same way, a dict merging into the group it names. A field under its old flat name
    (``tol_ddp``) is a DaddyError naming its new place (``ddp.tol``).
    """

    ddp: DDPOptions
    aul: AULOptions
    newton: NewtonOptions
    start: StartOptions
    kkt: KKTOptions
    end_game: EndGameOptions
    run: RunOptions
    policy: PolicyOptions
    homotopy: tuple

    def __init__(self, homotopy=((0.0, 1e-2),), **groups):
        for name, value in groups.items():
            if name not in GROUPS:
                raise DaddyError(_unknown(name))
        for name, cls in GROUPS.items():
            value = groups.get(name, cls())
            if isinstance(value, dict):
                unknown = sorted(set(value) - {f.name for f in fields(cls)})
                if unknown:
                    raise DaddyError(f"options.{name}.{unknown[0]} is not an option (known: "
                                     f"{', '.join(f.name for f in fields(cls))})")
                value = cls(**value)
            elif not isinstance(value, cls):
                raise DaddyError(f"options.{name} must be a {cls.__name__} or a dict of its "
                                 f"fields, got {type(value).__name__}")
            object.__setattr__(self, name, value)
        object.__setattr__(self, "homotopy", _homotopy(homotopy))

    @property
    def eps_da(self) -> float:
        """Accuracy of the Dyn method's polynomial radius: min(eps_AUL, eps_DDP)."""
        return min(self.aul.tol, self.ddp.tol)

    def with_(self, **changes) -> "SolverOptions":
        """A copy with groups replaced: a group object, or a dict of fields merged into it;
        ``homotopy``: new steps."""
        kw = {name: getattr(self, name) for name in GROUPS}
        kw["homotopy"] = changes.pop("homotopy", self.homotopy)
        for name, value in changes.items():
            if name not in GROUPS:
                raise DaddyError(_unknown(name))
            kw[name] = getattr(self, name).with_(**value) if isinstance(value, dict) else value
        return SolverOptions(**kw)

    @classmethod
    def warm_replan(cls, cold: "SolverOptions", tol_aul: float, active_tol: float,
                    restore_first: bool) -> "SolverOptions":
        """The guidance node's warm re-plan from its last plan (``daddy_ros.replan_policy``:
        why each setting): the last homotopy step only, one DDP iteration may stop it, the
        penalty started high and rho carried, no stall rules, no KKT residual, the polishing
        from DDP's maps with a wider active set, no per-stage trust region; a fuel-optimal
        plan restored in the exact fuel form first (``end_game.exact_start``); no
        least-violation solve and no restart after an unmet end
        (``end_game.certify_infeasibility``, ``end_game.blend_restart``)."""
        return cold.with_(
            homotopy=cold.homotopy[-1:],
            ddp=dict(min_iter=1, short_step=0.5, carry_rho=True, stage_trust=False),
            aul=dict(tol=tol_aul, mu_init=WARM_MU_INIT, stall_iter=0),
            newton=dict(stall_iter=0, polish_from_ddp_maps=True,
                        active_tol=max(active_tol, cold.newton.active_tol)),
            kkt=dict(tol=math.inf), start=dict(restore=bool(restore_first)),
            end_game=dict(exact_start=True, certify_infeasibility=False, blend_restart=False))


# a warm re-plan's starting penalty: three growth steps below the cap, where a plan's
# multipliers already hold the constraints
WARM_MU_INIT = 1e5


def _unknown(name: str) -> str:
    """The error of an unknown option name: its new place when it is an old flat name."""
    if name in MOVED:
        group, field = MOVED[name]
        return (f"options.{name} is now options.{group}.{field}: give "
                f"{group}=dict({field}=...)")
    return f"options.{name} is not an option group (groups: {', '.join(GROUPS)}, homotopy)"


def case_options(case, fuel_optimal: bool, **changes) -> SolverOptions:
    """The paper's solver settings for a catalogue case (its ``solver`` section), with
    ``changes`` as ``SolverOptions.with_`` takes them."""
    s = case.solver
    hom = s.get("homotopy", {"h": [0.0], "delta": [1e-2]})
    pairs = tuple(zip(hom["h"], hom["delta"])) if fuel_optimal else ((0.0, hom["delta"][0]),)
    groups: dict = {}
    for key, value in s.items():   # (the flat per-case tolerances; homotopy and guess aside)
        if key in MOVED:
            group, field = MOVED[key]
            groups.setdefault(group, {})[field] = value
    return SolverOptions(homotopy=pairs, **groups).with_(**changes)


__all__ = ["AULOptions", "DDPOptions", "EndGameOptions", "GROUPS", "Globalization", "KKTOptions",
           "METHODS", "Method", "MultiplierUpdate", "NewtonOptions", "RunOptions", "SolverOptions",
           "StartOptions", "Sweep", "case_options"]
