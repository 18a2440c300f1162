"""The result of a solve (trajectory, gains, figures of merit; JSON/NPZ round trip) and the warm
start a next solve takes from it."""
from __future__ import annotations

import copy
import json
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np

from .. import trajectory_output
from ..dynamics.units import Units
from ..errors import DaddyError
from ..policy import Policy
from .stage_maps import StageMaps


@dataclass
class Solution:
    """A solved (or best-so-far) trajectory.

    Arrays are normalised (the problem's units); ``X_si`` / ``thrust_n`` give SI views.

    Attributes:
        case, method, fuel_optimal, converged, reason: what was solved and how it ended.
        exact_fuel: the answer is the exact fuel form's optimum (``throttle``: the end game's
            throttle/direction form), not the last pseudo-Huber step's.
        X: (N+1, nx) states; U: (N, nu) controls; stage_dt: (N,) stage lengths (durations, or
            angles for Sundman-transformed stages); t_start: where stage 0 starts in the
            independent variable (``Problem.t_start``).
        gains_a: (N, nu), gains_b: (N, nu, nx): feedback law of the last backward sweep.
        cost: objective sum l + phi (without the augmented-Lagrangian terms).
        max_violation: max constraint violation (normalised; inequality max(g, 0), |g| else).
        kkt_residual: first-order optimality of (X, U) for the cost at the last homotopy step
            (``solver.optimality``: the least-squares KKT residual, stationarity and
            complementarity, relative to the largest cost-gradient component; 0 at a KKT
            point); None when it was not evaluated (an iterate that does not meet the
            constraints, ``SolverOptions.kkt.tol`` = inf) or could not be.
        violations: every constraint's largest violation, largest first
            (``Problem.violation_report``: name, violation, stage); a solve that did not
            converge also names the largest in ``reason``.
        final_mass_kg, propellant_kg: mass figures (None without a mass state).
        repropagation_miss: terminal miss after re-propagating U from x0 with DOP853 at
            rtol = atol = 1e-12 (normalised, over the terminal-constraint components; while
            the solved states stay within 1e-7 of the flow, every stage integrated from its own
            start and the defects carried through the stage maps, equal to round-off:
            ``solve.repropagation_miss``); inf when the re-propagation failed (JSON: "inf").
        iterations: {restore, homotopy, aul, ddp, newton, kkt} (restore: Newton's on the
            start, newton: the polishing's); runtime_s: {total, ddp, newton, ...}.
        history: per-homotopy-step summaries (``resolve: True`` on a re-solve of the last
            step after a stalled KKT polishing, counted in iterations["homotopy"]); units:
            {lu_km, tu_s, mu_kg, thrust_unit_n}.
        stage_maps: the last stage maps (``StageMaps``), in memory only (not in JSON/NPZ): a
            warm start from this solution rolls out and restores with them.
        min_path_margin: the true minimum margin of ``Problem.g_path`` between the nodes
            (dense DOP853 re-propagation, in g_path's units; >= 0: held everywhere), after the
            exchange rounds (``SolverOptions.end_game.path_exchange_rounds``); None without g_path.
    """

    case: str
    method: str
    fuel_optimal: bool
    converged: bool
    reason: str
    X: np.ndarray
    U: np.ndarray
    stage_dt: np.ndarray
    gains_a: np.ndarray
    gains_b: np.ndarray
    cost: float
    max_violation: float
    final_mass_kg: float | None
    propellant_kg: float | None
    repropagation_miss: float | None
    iterations: dict = field(default_factory=dict)
    runtime_s: dict = field(default_factory=dict)
    history: list = field(default_factory=list)
    units: dict = field(default_factory=dict)
    polynomial_share: float = 0.0
    duals: dict = field(default_factory=dict)  # {"lam": (n_c, N), "lam_t": (n_t,)} as lists
    rho: float = 0.0  # Quu regularisation at the end of the last DDP solve (warm starts resume it)
    violations: list = field(default_factory=list)   # Problem.violation_report, largest first
    kkt_residual: float | None = None   # solver.optimality (None in plans saved before it)
    t_start: float = 0.0
    time_index: int | None = None   # Problem.time_index: the state's time when staged in angle
    # Earth-centred solutions solved by ``daddy solve``: trajectory_output.cartesian_miss (the
    # thrust flown in Cartesian coordinates in time against the final node; None otherwise)
    cartesian_miss: dict | None = None
    # problems with a g_path: -max of g_path along the DOP853 re-propagation of every stage
    # (``path_constraints.dense_margin``; >= 0: it holds between the nodes too); None otherwise
    min_path_margin: float | None = None
    parameters: dict | None = None   # static parameters {name: value} (``static_parameters``)
    phases: list | None = None   # a multi-phase problem's phases (``phases.phase_report``)
    exact_fuel: bool = False
    # the solve found the problem infeasible (``infeasibility``): the least-violation solve from
    # its end misses the terminal conditions with the stage constraints held (a certificate
    # where that problem is convex, a local verdict where not); X, U: that point
    infeasible: bool = False
    # feedback laws (``options.policy.order``; ``daddy_core.policy``), or why they were not built
    policy: Policy | None = field(default=None, repr=False, compare=False)
    policy_error: str | None = None
    stage_maps: StageMaps | None = field(default=None, repr=False, compare=False)

    _ARRAYS = ("X", "U", "stage_dt", "gains_a", "gains_b")

    @property
    def N(self) -> int:
        return self.U.shape[0]

    @property
    def fuel_step(self) -> tuple | None:
        """(h, delta) of the last pseudo-Huber homotopy step the solve ran (h > 0), or None: an
        energy-optimal solve, or a fuel-optimal one whose exact end game converged from the
        energy step's solution before any (``SolverOptions.end_game.exact_fuel``)."""
        for step in reversed(self.history):
            if step.get("h", 0.0) > 0:
                return (step["h"], step["delta"])
        return None

    @property
    def thrust_n(self) -> np.ndarray:
        """Controls in newtons (N, nu) (JSON: ``U_N``)."""
        return self.U * self.units.get("thrust_unit_n", 1.0)

    @property
    def X_si(self) -> np.ndarray:
        """States in SI (``Units.states_si``; JSON: ``X_SI``); for Earth-centred solutions
        Cartesian ECI [position m, velocity m/s, mass kg], their elements in ``elements``."""
        if trajectory_output.is_earth_centred(self):
            return trajectory_output.earth_cartesian_si(self)
        return Units.from_dict(self.units).states_si(self.X)

    @property
    def elements(self) -> np.ndarray | None:
        """Earth-centred solutions: (N+1, 6) Keplerian elements of the nodes [a km, e, i deg,
        RAAN deg, argp deg, true longitude deg] (JSON: ``elements_km_deg``); else None."""
        if trajectory_output.is_earth_centred(self):
            return trajectory_output.earth_elements(self)
        return None

    @property
    def times_s(self) -> np.ndarray:
        """(N+1,) node times since the start [s] (JSON: ``times_s``)."""
        return trajectory_output.node_times_s(self)

    def to_dict(self) -> dict:
        d = {f.name: copy.deepcopy(getattr(self, f.name)) for f in fields(self)
             if f.name not in self._ARRAYS + ("stage_maps", "policy")}
        if self.policy is not None:
            d["policy"] = self.policy.to_dict()
        for k in self._ARRAYS:
            d[k] = np.asarray(getattr(self, k)).tolist()
        if d["repropagation_miss"] == np.inf:   # strict JSON has no infinity
            d["repropagation_miss"] = "inf"
        if self.units.get("thrust_unit_n"):
            d["U_N"] = self.thrust_n.tolist()
            d["X_SI"] = self.X_si.tolist()
            d["times_s"] = self.times_s.tolist()
            elements = self.elements
            if elements is not None:
                d["elements_km_deg"] = elements.tolist()
        return d

    def to_json(self, path: str | Path | None = None) -> str:
        text = json.dumps(self.to_dict(), indent=1, allow_nan=False)
        if path is not None:
            Path(path).write_text(text)
        return text

    @classmethod
    def from_dict(cls, d: dict) -> "Solution":
        names = {f for f in cls.__dataclass_fields__}
        kw = {k: v for k, v in d.items() if k in names}
        for k in cls._ARRAYS:
            if k not in kw:
                raise DaddyError(f"solution field {k!r} is missing")
            kw[k] = np.asarray(kw[k], dtype=float)
        if kw.get("repropagation_miss") == "inf":
            kw["repropagation_miss"] = np.inf
        if kw.get("policy") is not None:
            kw["policy"] = Policy.from_dict(kw["policy"])
        return cls(**kw)

    @classmethod
    def from_json(cls, path_or_text: str | Path) -> "Solution":
        text = str(path_or_text)
        if not text.lstrip().startswith("{"):
            text = Path(text).read_text()
        return cls.from_dict(json.loads(text))

    def to_npz(self, path: str | Path) -> None:
        meta = {k: v for k, v in self.to_dict().items()
                if k not in self._ARRAYS + ("U_N", "X_SI", "times_s", "elements_km_deg")}
        np.savez(path, meta=json.dumps(meta), **{k: getattr(self, k) for k in self._ARRAYS})

    @classmethod
    def from_npz(cls, path: str | Path) -> "Solution":
        with np.load(path) as z:
            d = json.loads(str(z["meta"]))
            for k in cls._ARRAYS:
                d[k] = z[k]
        return cls.from_dict(d)


@dataclass
class WarmStart:
    """What a solve starts from besides the problem: controls, and what a previous solution
    lends a nearby solve.

    Attributes:
        U: (N, nu) initial controls (None: 1e-6 on every component).
        duals: multipliers {"lam": (n_c, N), "lam_t": (n_t,)} (used where their shapes fit).
        rho: Quu regularisation to resume from (None: ``SolverOptions.ddp.rho_init``).
        maps: stage maps of a nearby trajectory with the problem's stages: the initial rollout
            evaluates them where a stage lies inside their radius (Alg. 8) and the Newton
            restoration re-centres them instead of expanding.
        X: (N+1, nx) states at the problem's stage ends (row 0 is replaced by the problem's
            x0): where Newton's restoration starts instead of a rollout of U -- the exact warm
            start's (``exact_start``), and, without maps, the general start's (a state guess:
            the blend of two orbits of ``multistart``, another solver's trajectory); its
            residuals are exact, so the states need not be flyable.
    """

    U: np.ndarray | None = None
    duals: dict | None = None
    rho: float | None = None
    maps: StageMaps | None = None
    X: np.ndarray | None = None

    @classmethod
    def of(cls, guess, stage_dt: np.ndarray, carry_rho: bool, t_start: float = 0.0) -> "WarmStart":
        """A WarmStart from what ``solve`` accepts as a guess: a WarmStart, a ``Solution``
        (its U and duals; its maps when its stages are the same, ``stage_dt`` from
        ``t_start``; its rho with ``carry_rho``) or controls."""
        if isinstance(guess, WarmStart):
            return guess
        if isinstance(guess, Solution):
            same = np.array_equal(guess.stage_dt, stage_dt) and guess.t_start == t_start
            maps = guess.stage_maps if same else None
            return cls(guess.U, guess.duals, guess.rho if carry_rho else None, maps,
                       guess.X if same else None)
        return cls(guess)
