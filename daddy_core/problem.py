"""The optimal-control problem DDP solves (paper eq. 1, 6, 7), in normalised units.

    minimise   sum_k l(x_k, u_k) + phi(x_N, x_t)
    subject to x_{k+1} = f(x_k, u_k),   g_ineq(x_k, u_k) <= 0,   g_eq(x_k, u_k) = 0,
               g_tineq(x_N, x_t) <= 0,  g_teq(x_N, x_t) = 0,     x_0 given.

Every function is written once and evaluated on floats and DA, batched over stages: ``x`` has
shape (nx, B), ``u`` (nu, B), ``dt`` (B,) the stage durations; stage functions return (B,) for
costs and (n_c, B) for constraints; terminal functions take ``x`` of shape (nx,) (or a DA).
The stage cost also receives ``hom = (h, delta)``, the fuel homotopy weight and Huber width
(paper eq. 12-14); energy-optimal problems ignore it or use h = 0.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any, Callable, Optional

import numpy as np

from .da import functions as dm
from .da.core import DA, variables
from .dynamics.units import Spacecraft, Units, unit_units
from .errors import DaddyError
from .dynamics.rhs import Dynamics, as_dynamics
from .integrators import rk4, rk78
from . import path_constraints


class StageStep:
    """The stage map f(x, u, dt, t0) -> next state, batched (x (nx, B), u (nu, B), dt (B,) the
    stage lengths, t0 (B,) or a float the values of the independent variable where the stages
    start), on floats or DA: what the solver relies on, with the two ways it evaluates a step.

    Wraps a plain function f(x, u, dt) of an autonomous system (``Problem`` wraps any callable
    given as ``step``; it does not see t0; the library's own wrappers of a step, e.g. the
    static parameters', pass t0 on: ``takes_t0``); ``FlowStep`` integrates a continuous
    right-hand side rhs(t, x, u) from t0 and serves both ways faster. The stage start matters where the
    dynamics depend on the independent variable, e.g. the true longitude of Sundman-transformed
    Earth-centred stages (``models.equinoctial_sundman``).
    """

    def __init__(self, fn: Callable, takes_t0: bool = False):
        self.fn = fn
        self.takes_t0 = takes_t0   # fn(x, u, dt, t0): a step of the library's that passes t0 on

    def __call__(self, x, u, dt, t0=0.0):
        return self.fn(x, u, dt, t0) if self.takes_t0 else self.fn(x, u, dt)

    def flow(self, x: np.ndarray, u: np.ndarray, dt: float, t0: float = 0.0) -> np.ndarray:
        """One float state (nx,) after a stage of length dt from t0 under u (nu,)."""
        return self(x[:, None], u[:, None], np.array([dt]), t0)[:, 0]

    def expand(self, x: DA, u: DA, dt: np.ndarray, values: np.ndarray, t0=0.0) -> DA:
        """The DA expansion at (x, u) whose constant part is ``values`` (nx, B): the flows the
        caller has integrated already (a forward pass, Newton's residual)."""
        F = self(x, u, dt, t0)
        F.c[0] = values
        return F

    def probe(self, x: DA, u: DA, dt: np.ndarray, t0=0.0):
        """The user code behind the step evaluated once on DA (x (nx, B), u (nu, B)): shows
        whether it runs on DA and returns (nx, B) (``Problem.check_guess``)."""
        return self(x, u, dt, t0)


class FlowStep(StageStep):
    """The flow of a ``Dynamics`` over a stage, integrated by RK78 or RK4 (see ``flow_step``)."""

    def __init__(self, rhs: Dynamics, integrator: str, tol: float, rk4_steps: int,
                 derivative_tol: float | None):
        if integrator not in ("rk78", "rk4"):
            raise DaddyError(f"integrator must be 'rk78' or 'rk4', got {integrator!r}")
        super().__init__(None)
        self.rhs, self.integrator, self.tol, self.rk4_steps = rhs, integrator, tol, rk4_steps
        self.derivative_tol = tol if derivative_tol is None else max(tol, float(derivative_tol))

    def __call__(self, x, u, dt, t0=0.0):
        if self.integrator == "rk4":
            return rk4(self.rhs, x, u, t0, dt, steps=self.rk4_steps)
        if isinstance(x, DA) and self.derivative_tol > self.tol:
            return self._expand_rk78(x, u, dt, None, t0)
        # every integration first tries the whole stage (h0 = dt): most stages need one step
        return rk78(self.rhs, x, u, t0, dt, tol=self.tol, h0=dt)

    def probe(self, x, u, dt, t0=0.0):
        # the integrators are ours: the user code is the right-hand side, one call is enough
        return self.rhs(t0, x, u)

    def flow(self, x, u, dt, t0=0.0):
        if self.integrator == "rk4":
            return super().flow(x, u, dt, t0)
        return rk78(self.rhs, x, u, t0, dt, tol=self.tol, h0=dt)   # the single-state path

    def expand(self, x, u, dt, values, t0=0.0):
        if self.integrator == "rk4":
            return super().expand(x, u, dt, values, t0)
        return self._expand_rk78(x, u, dt, values, t0)

    def _expand_rk78(self, x: DA, u, dt, values, t0):
        """Derivatives from an RK78 run at ``derivative_tol``, the constant part -- the flow
        itself -- at ``tol`` (or ``values`` as they are)."""
        F = rk78(self.rhs, x, u, t0, dt, tol=self.derivative_tol, h0=dt)
        F.c[0] = rk78(self.rhs, x.cons, dm.cons(u), t0, dt, tol=self.tol, h0=dt) \
            if values is None else values
        return F


@dataclass(frozen=True)
class Problem:
    """A discrete-time optimal-control problem (see the module docstring).

    Attributes:
        name: label used in reports.
        x0: (nx,) initial state; x_target: (nx,) target state.
        stage_dt: (N,) stage lengths in the independent variable: durations (normalised time),
            or angles for Sundman-transformed stages.
        step: f(x, u, dt, t0) -> next state, the flow over one stage (float or DA, batched):
            a ``StageStep`` (``flow_step`` builds one from a right-hand side) or a plain
            function f(x, u, dt) of an autonomous system.
        stage_cost: l(x, u, dt, hom) -> (B,).
        terminal_cost: phi(x, x_target) -> scalar.
        g_ineq, g_eq: stage constraints (x, u, dt) -> (n, B), or None: held at the stage
            points (x_k, u_k).
        g_path: path constraint g(x, u) -> (n_p, B) <= 0 held along every stage, between the
            nodes too (``path_constraints``): imposed at ``path_samples`` points per stage
            (rows after g_ineq's among the stage inequalities), and checked by a dense DOP853
            re-propagation after the solve, whose excess between the samples tightens them
            (``path_offset``: (n_p, N) added to each stage's sampled rows; set by the solver).
            Needs ``rhs``.
        g_tineq, g_teq: terminal constraints (x, x_target) -> (n,), or None.
        units: normalisation units (SI at the boundary); spacecraft: for mass reporting or None.
        u_max: thrust bound in normalised units (None if unbounded); reported and checked.
        mass_index: index of the mass in the state, or None.
        t_start: the independent variable where stage 0 starts (0 for autonomous dynamics;
            the true longitude of x0 for Sundman-transformed stages); stage k starts at
            ``stage_t0[k]`` = t_start + the lengths of the stages before it.
        time_index: index of the physical time in the state when the independent variable is
            not time (Sundman-transformed stages), else None.
        parameters: set by ``static_parameters``: where the static parameters sit in the
            state and control (a ``ParameterLayout``); None for a problem without them.
        labels: optional names of the constraints' components for reports, by function:
            {"g_ineq": ("thrust bound", ...), "g_teq": ("x", ...), ...}.
    """

    name: str
    x0: np.ndarray
    x_target: np.ndarray
    stage_dt: np.ndarray
    step: Callable
    stage_cost: Callable
    terminal_cost: Callable
    g_ineq: Optional[Callable] = None
    g_eq: Optional[Callable] = None
    g_tineq: Optional[Callable] = None
    g_teq: Optional[Callable] = None
    nu: int = 3
    units: Units = field(default_factory=unit_units)
    spacecraft: Optional[Spacecraft] = None
    u_max: Optional[float] = None
    mass_index: Optional[int] = None
    rhs: Optional[Dynamics] = None  # continuous dynamics, for re-propagation checks
    t_start: float = 0.0
    time_index: Optional[int] = None
    labels: dict = field(default_factory=dict)
    g_path: Optional[Callable] = None
    path_samples: int = 4
    path_offset: Optional[np.ndarray] = None
    parameters: Optional[Any] = None   # static_parameters.ParameterLayout of an augmented problem

    def __post_init__(self):
        x0 = np.asarray(self.x0, dtype=float)
        xt = np.asarray(self.x_target, dtype=float)
        dt = np.asarray(self.stage_dt, dtype=float)
        if x0.ndim != 1 or x0.size == 0:
            raise DaddyError(f"problem.x0 must be a non-empty vector, got shape {x0.shape}")
        if xt.shape != x0.shape:
            raise DaddyError(f"problem.x_target must have shape {x0.shape}, got {xt.shape}")
        if not (np.all(np.isfinite(x0)) and np.all(np.isfinite(xt))):
            raise DaddyError("problem.x0 / x_target contain NaN or inf")
        if dt.ndim != 1 or dt.size < 1:
            raise DaddyError(f"problem.stage_dt must be a vector of N >= 1 durations, got {dt.shape}")
        if not np.all(np.isfinite(dt)) or np.any(dt <= 0):
            raise DaddyError("problem.stage_dt: every stage duration must be positive and finite")
        if not (isinstance(self.nu, (int, np.integer)) and self.nu >= 1):
            raise DaddyError(f"problem.nu must be a positive integer, got {self.nu!r}")
        object.__setattr__(self, "x0", x0)
        object.__setattr__(self, "x_target", xt)
        object.__setattr__(self, "stage_dt", dt)
        if not math.isfinite(self.t_start):
            raise DaddyError(f"problem.t_start must be finite, got {self.t_start!r}")
        if not isinstance(self.step, StageStep):
            if not callable(self.step):
                raise DaddyError(f"problem.step must be callable, got {self.step!r}")
            object.__setattr__(self, "step", StageStep(self.step))
        if self.rhs is not None:
            object.__setattr__(self, "rhs", as_dynamics(self.rhs))
        if self.g_path is not None:
            if not callable(self.g_path):
                raise DaddyError(f"problem.g_path must be callable, got {self.g_path!r}")
            if self.rhs is None:
                raise DaddyError("problem.g_path holds between the nodes, which needs the "
                                 "continuous dynamics: give problem.rhs (e.g. flow_step's)")
            if not (isinstance(self.path_samples, (int, np.integer)) and self.path_samples >= 1):
                raise DaddyError(f"problem.path_samples must be a positive integer, got "
                                 f"{self.path_samples!r}")

    @property
    def nx(self) -> int:
        return self.x0.size

    @property
    def N(self) -> int:
        return self.stage_dt.size

    @cached_property
    def stage_t0(self) -> np.ndarray:
        """(N,) the independent variable where each stage starts: t_start + the lengths of the
        stages before it."""
        t0 = np.empty_like(self.stage_dt)
        t0[0] = 0.0
        np.cumsum(self.stage_dt[:-1], out=t0[1:])
        return t0 + self.t_start

    def with_x0(self, x0, stage_dt=None, t_start=None) -> "Problem":
        """A copy starting from another state (and optionally other stage lengths and start)."""
        return replace(self, x0=np.asarray(x0, float),
                       stage_dt=self.stage_dt if stage_dt is None else np.asarray(stage_dt, float),
                       t_start=self.t_start if t_start is None else float(t_start))

    # -- batched evaluation helpers (floats or DA) ------------------------------------------
    @cached_property
    def n_path_rows(self) -> int:
        """How many stage inequalities the sampled g_path adds (path_samples x its components;
        0 without g_path): the last rows of the stage inequalities."""
        if self.g_path is None:
            return 0
        return self.path_samples * len(self.g_path(self.x0[:, None], np.zeros((self.nu, 1))))

    def path_constraints(self, x, u, dt, t0=None, in_use=None):
        """Stacked [g_ineq; sampled g_path; g_eq] (n_ineq + n_eq, B) and the count of
        inequalities, for B stages from x (nx, B) under u (nu, B) with lengths dt (B,) starting
        at t0 (B,; None: ``stage_t0[:B]``, the first B stages). in_use: which stages' g_path
        rows are expanded on DA, from their values (``path_constraints.sampled``; None: all)."""
        parts, n_ineq = [], 0
        if self.g_ineq is not None:
            gi = self.g_ineq(x, u, dt)
            n_ineq = len(gi)
            parts.append(gi)
        if self.g_path is not None:
            t0 = self.stage_t0[:np.size(dt)] if t0 is None else t0
            gp = path_constraints.sampled(self, x, u, dt, t0, in_use)
            n_ineq += len(gp)
            parts.append(gp)
        if self.g_eq is not None:
            parts.append(self.g_eq(x, u, dt))
        if not parts:
            return None, 0
        return (parts[0] if len(parts) == 1 else dm.concatenate(parts)), n_ineq

    def terminal_constraints(self, x):
        """Stacked [g_tineq; g_teq] (n,) and the count of inequalities."""
        parts, n_ineq = [], 0
        if self.g_tineq is not None:
            gi = self.g_tineq(x, self.x_target)
            n_ineq = len(gi)
            parts.append(gi)
        if self.g_teq is not None:
            parts.append(self.g_teq(x, self.x_target))
        if not parts:
            return None, 0
        return (parts[0] if len(parts) == 1 else dm.concatenate(parts)), n_ineq

    def rollout(self, U: np.ndarray, x0=None) -> np.ndarray:
        """Propagate controls U (N, nu) from x0 with the stage map, one stage at a time -> X."""
        X = np.empty((self.N + 1, self.nx))
        X[0] = self.x0 if x0 is None else x0
        for k in range(self.N):
            X[k + 1] = self.stage_flow(X[k], U[k], k)
        return X

    def stage_flows(self, X: np.ndarray, U: np.ndarray) -> np.ndarray:
        """(nx, N) the flow of every stage k from X[k] under U[k] (X (N or N+1, nx), U (N, nu)),
        in one batched float call."""
        return self.step(X[:self.N].T, U.T, self.stage_dt, self.stage_t0)

    def stage_flow(self, x: np.ndarray, u: np.ndarray, k: int) -> np.ndarray:
        """State (nx,) after stage k from x (nx,) under u (nu,), in floats."""
        return self.step.flow(x, u, float(self.stage_dt[k]), float(self.stage_t0[k]))

    def probe_point(self, U0: np.ndarray):
        """(x (nx, 2), u (nu, 2), dt (2,), t0 (2,)): x0 with the controls, lengths and starts of
        the first two stages (the only one twice when N = 1), a batch of two for cheap
        evaluations of the problem functions on floats."""
        k = np.minimum([0, 1], self.N - 1)
        return (np.tile(self.x0[:, None], (1, 2)), np.asarray(U0, float)[k].T, self.stage_dt[k],
                self.stage_t0[k])

    def check_guess(self, U0) -> np.ndarray:
        """Check the initial guess and that every problem function returns finite values of the
        right shape at it, before any iteration. Returns U0 as a float (N, nu) array."""
        N, nu, nx = self.N, self.nu, self.nx
        try:
            raw = np.asarray(U0)
            if raw.dtype.kind not in "iuf":   # no silent casts of complex, bool, text or objects
                raise TypeError(f"dtype {raw.dtype}")
            U0 = raw.astype(float)
        except (TypeError, ValueError) as exc:
            raise DaddyError(f"u_guess must be a real numeric array of shape (N, nu) = "
                             f"({N}, {nu}): {exc}") from exc
        if U0.shape != (N, nu):
            raise DaddyError(f"u_guess must have shape (N, nu) = ({N}, {nu}), got {U0.shape}")
        if not np.all(np.isfinite(U0)):
            raise DaddyError("u_guess contains NaN or inf")
        if self.spacecraft is not None and self.mass_index is not None:
            m = self.x0[self.mass_index] * self.units.mu_kg
            if m <= self.spacecraft.dry_mass_kg:
                raise DaddyError(f"x0 mass ({m:.6g} kg) must exceed the dry mass "
                                 f"({self.spacecraft.dry_mass_kg:.6g} kg)")
        x, u, dt, t0 = self.probe_point(U0)
        checks = {
            "step": lambda: self.step(x, u, dt, t0),
            "stage_cost": lambda: self.stage_cost(x, u, dt, (0.0, 1.0)),
            "g_path": self.g_path and (lambda: self.g_path(x, u)),
            "path constraints": lambda: self.path_constraints(x, u, dt, t0)[0],
            "terminal_cost": lambda: self.terminal_cost(self.x0, self.x_target),
            "terminal constraints": lambda: self.terminal_constraints(self.x0)[0],
        }
        shapes = {"step": (nx, 2), "stage_cost": (2,)}
        for name, fn in checks.items():
            if fn is None:
                continue
            try:
                val = fn()
            except DaddyError:
                raise
            except Exception as exc:  # a user function failing is reported as bad input
                raise DaddyError(f"problem {name} raised {type(exc).__name__}: {exc}") from exc
            if val is None:
                continue
            val = np.asarray(val, dtype=float)
            if name in shapes and val.shape != shapes[name]:
                raise DaddyError(f"problem {name} returned shape {val.shape}, expected "
                                 f"{shapes[name]}")
            if name == "g_path" and (val.ndim != 2 or val.shape[1] != 2):
                raise DaddyError(f"problem g_path returned shape {val.shape} for a batch of 2 "
                                 "stages, expected (n_p, 2): one row per constraint (a single "
                                 "one: dm.stack([g]))")
            if not np.all(np.isfinite(val)):
                raise DaddyError(f"problem {name} returned NaN or inf at the initial guess")
        self._check_on_da(U0[0])
        return U0

    def _check_on_da(self, u0: np.ndarray) -> None:
        """Evaluate every problem function once on DA at (x0, u0), one stage: the solver expands
        them all, and a function written for floats only (a numpy ufunc, ``np.stack``, a list, a
        bare expression where a vector is due) fails here with a DaddyError naming it and the
        fix, not later inside the solver."""
        nx = self.nx
        z = variables(np.concatenate([self.x0, u0])[:, None], order=2)
        x, u, dt, t0 = z[:nx], z[nx:], self.stage_dt[:1], self.stage_t0[:1]
        xn = variables(self.x0, order=2)
        xt = self.x_target
        stage = [("step", lambda: self.step.probe(x, u, dt, t0), (nx, 1)),
                 ("stage_cost", lambda: self.stage_cost(x, u, dt, (0.0, 1.0)), (1,)),
                 ("g_ineq", self.g_ineq and (lambda: self.g_ineq(x, u, dt)), (None, 1)),
                 ("g_eq", self.g_eq and (lambda: self.g_eq(x, u, dt)), (None, 1)),
                 ("g_path", self.g_path and (lambda: self.g_path(x, u)), (None, 1)),
                 ("terminal_cost", lambda: self.terminal_cost(xn, xt), ()),
                 ("g_tineq", self.g_tineq and (lambda: self.g_tineq(xn, xt)), (None,)),
                 ("g_teq", self.g_teq and (lambda: self.g_teq(xn, xt)), (None,))]
        for name, fn, shape in stage:
            if fn:
                _check_da_value(name, fn, shape)

    # -- constraint violation (floats) -----------------------------------------------------
    def constraint_values(self, X: np.ndarray, U: np.ndarray):
        """Path constraints (n_c, N) and terminal constraints (n_t,) of a trajectory X
        (N+1, nx), U (N, nu), with their inequality counts: (g, n_ineq, gt, n_tineq)."""
        g, ni = self.path_constraints(X[:-1].T, U.T, self.stage_dt, self.stage_t0)
        gt, nti = self.terminal_constraints(X[-1])
        return g, ni, gt, nti

    def violation(self, X: np.ndarray, U: np.ndarray) -> float:
        """Max violation over every path and terminal constraint of (X, U)."""
        g, ni, gt, nti = self.constraint_values(X, U)
        return largest(max_violation(g, ni), max_violation(gt, nti))

    def violation_report(self, X: np.ndarray, U: np.ndarray) -> list[dict]:
        """Every constraint's largest violation on (X, U), largest first: {"name" (e.g.
        "g_ineq[0]", "g_teq[2]"), "label" (``labels``' name for it, or None), "violation",
        "stage" (of the largest, path constraints; None for terminal ones)}. Says which
        constraints a failed solve could not meet."""
        g, ni, gt, nti = self.constraint_values(X, U)
        out = []

        def entry(fn, i, violation, stage):
            names = self.labels.get(fn, ())
            return {"name": f"{fn}[{i}]", "label": names[i] if i < len(names) else None,
                    "violation": violation, "stage": stage}
        if g is not None:
            v = violations(g, ni)
            n_p = self.n_path_rows // self.path_samples
            n_gi = ni - self.n_path_rows
            for i, row in enumerate(v):
                k = int(np.argmax(row))
                if i < n_gi:
                    out.append(entry("g_ineq", i, float(row[k]), k))
                elif i < n_gi + n_p:   # g_path component i - n_gi: its worst sample
                    worst = v[i:ni:n_p].max(axis=0)
                    k = int(np.argmax(worst))
                    out.append(entry("g_path", i - n_gi, float(worst[k]), k))
                elif i >= ni:
                    out.append(entry("g_eq", i - ni, float(row[k]), k))
        if gt is not None:
            for i, val in enumerate(violations(gt, nti)):
                out.append(entry("g_tineq", i, float(val), None) if i < nti
                           else entry("g_teq", i - nti, float(val), None))
        # (a NaN first: it is the worst, and sorting on a NaN key leaves the order undefined)
        return sorted(out, key=lambda r: (not math.isnan(r["violation"]), -r["violation"]))

    def terminal_violation(self, x: np.ndarray) -> float:
        """Max violation of the terminal constraints at the final state x (nx,)."""
        gt, nti = self.terminal_constraints(x)
        return max_violation(gt, nti)


_DA_HINT = ("write it with daddy_core.da.functions (dm.sqrt, dm.sin, dm.stack, ...) instead of "
            "numpy's functions, which do not take DA values")


def _check_da_value(name: str, fn: Callable, shape: tuple) -> None:
    """Call ``fn`` on DA inputs; raise a DaddyError naming ``name`` unless it returns a DA (or a
    constant float array) of ``shape`` (None: any length on that axis)."""
    try:
        val = fn()
    except DaddyError:
        raise
    except Exception as exc:   # the function does not run on DA
        raise DaddyError(f"problem {name} raised {type(exc).__name__} on DA inputs ({exc}): "
                         f"{_DA_HINT}") from exc
    if isinstance(val, (list, tuple)):
        raise DaddyError(f"problem {name} returned a {type(val).__name__}: return "
                         "dm.stack([...]) of its components")
    if isinstance(val, np.ndarray) and val.dtype == object:
        raise DaddyError(f"problem {name} returned a numpy object array (np.stack / np.array of "
                         f"DA values): {_DA_HINT}")
    got = tuple(np.shape(val)) if not isinstance(val, DA) else val.shape
    if len(got) != len(shape) or any(w is not None and g != w for g, w in zip(got, shape)):
        want = "(" + ", ".join("n" if w is None else str(w) for w in shape) + \
            ("," if len(shape) == 1 else "") + ")"
        fix = (" (a single constraint: dm.stack([g]))" if None in shape
               and len(got) == len(shape) - 1 else "")
        raise DaddyError(f"problem {name} returned shape {got} on DA inputs, expected {want}"
                         f"{fix}")


def violations(g, n_ineq: int) -> np.ndarray:
    """Element-wise violation of stacked constraint values g (inequalities first, along the
    first axis): max(g, 0) for the n_ineq inequalities, |g| for the equalities."""
    g = np.asarray(g, dtype=float)
    v = np.abs(g)
    v[:n_ineq] = np.maximum(g[:n_ineq], 0.0)
    return v


def largest(*values: float) -> float:
    """The largest of some violations or residuals, NaN when any is NaN (Python's ``max``
    returns or drops a NaN depending on its position: a NaN constraint read as met)."""
    return float(np.max(values))


def max_violation(g, n_ineq: int) -> float:
    """Max of ``violations(g, n_ineq)``; 0 without constraints."""
    if g is None or np.size(g) == 0:
        return 0.0
    return float(violations(g, n_ineq).max())


# ---------------------------------------------------------------------------------- builders
# local error tolerance of the RK78 steps that carry a DA expansion's derivatives (see flow_step)
DERIVATIVE_TOL = 1e-8


def flow_step(rhs, integrator: str = "rk78", tol: float = 1e-13, rk4_steps: int = 20,
              derivative_tol: float | None = DERIVATIVE_TOL) -> FlowStep:
    """Stage map f(x, u, dt) from a continuous right-hand side (a ``Dynamics`` or a plain
    rhs(t, x, u)) and an integrator.

    rk78 on a DA state (an expansion of the stage map): the constant part -- the flow itself --
    comes from a float integration at ``tol``; the derivatives from a DA integration whose
    steps start at the whole stage and keep the constant part's local error below
    ``derivative_tol`` (None: ``tol``). Newton and DDP need derivatives to ~1e-6 relative, not
    1e-13, and the looser tolerance takes far fewer RK steps per stage, while every value the
    solver compares stays integrated to ``tol``.
    """
    return FlowStep(as_dynamics(rhs), integrator, tol, rk4_steps, derivative_tol)
