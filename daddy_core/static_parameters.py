"""Static parameters and free time of flight (issue 46, first part): decision variables that
hold over every stage, solved as one problem with the controls.

The route is the augmented state with the parameter stage folded into stage 0, done here so
that a user never sees it. The problem's state gains the parameters omega and a stage-0 flag
phi, and its control gains an increment v:

    z = [x, omega, phi],   w = [u, v],   z0 = [x0, guess, 1]
    omega+ = omega + phi * scale * v      (the parameters move on stage 0 only)
    phi+ = 0,                             (1 - phi) v = 0   (a stage equality: v idle after)
    lower <= omega+ <= upper              (a stage-0 inequality: phi (bound rows) - (1 - phi))

Every stage runs the user's functions with omega+: the parameters' sensitivities reach the
backward sweep through the state, as HDDP's omega border does. Because the result is an
ordinary ``Problem``, the AUL, the Newton polish and the KKT end game treat the parameters like
any other variable, with no code of their own. The price is nu_omega controls per stage that
stay at 0.

Two views of the user's problem:

- ``with_parameters(problem, params)``: the user's functions receive the state with the
  parameters appended, [x, omega] ((nx + n_omega, B)); ``step`` (or the rhs) returns the nx
  physical rows.
- ``with_free_time(problem, lower, upper)``: the time of flight T is the parameter, and the
  user's functions are unchanged. Each stage's duration becomes dt T / T_ref (T_ref = the sum
  of ``stage_dt``): plain steps and stage costs receive the scaled dt, and a right-hand side is
  scaled by T / T_ref over the same stage grid, its independent variable mapped to
  t_start + (t - t_start) T / T_ref (so dynamics that depend on it explicitly fly the scaled
  grid too). For a problem staged in an angle (``time_index`` set: the Earth-centred cases'
  true longitude) the same parameter is the span of the angle, a free arrival angle.
  ``time_cost`` adds c T to the terminal cost (c = 1 with a zero stage cost is minimum time).

``solve`` pads a user's (N, nu) guess with idle increments (a solution's: with the increments
that set its parameters), and answers in the user's view: X (N+1, nx), U (N, nu), the stage
lengths as flown, and the values in ``Solution.parameters``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from .da import functions as dm
from .dynamics.rhs import Dynamics
from .errors import DaddyError
from .problem import FlowStep, Problem, StageStep


@dataclass(frozen=True)
class StaticParameter:
    """One static parameter: its bounds (finite, lower < upper), its guess (inside them;
    default their middle) and its typical size ``scale`` (the stage-0 increment moves it by
    scale v: a scale near the parameter's range keeps v of order 1)."""

    name: str
    lower: float
    upper: float
    guess: float | None = None
    scale: float | None = None

    def checked(self) -> "StaticParameter":
        lo, hi = self.lower, self.upper
        if not (isinstance(lo, (int, float)) and isinstance(hi, (int, float))
                and math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise DaddyError(f"parameter {self.name!r}: lower and upper must be finite with lower "
                             f"< upper (a parameter without bounds can run away, e.g. a time of "
                             f"flight going negative), got [{lo!r}, {hi!r}]")
        guess = 0.5 * (lo + hi) if self.guess is None else self.guess
        if not (isinstance(guess, (int, float)) and lo <= guess <= hi):
            raise DaddyError(f"parameter {self.name!r}: guess must lie in [{lo}, {hi}], got "
                             f"{guess!r}")
        scale = hi - lo if self.scale is None else self.scale
        if not (isinstance(scale, (int, float)) and scale > 0 and math.isfinite(scale)):
            raise DaddyError(f"parameter {self.name!r}: scale must be a positive number, got "
                             f"{scale!r}")
        return replace(self, lower=float(lo), upper=float(hi), guess=float(guess),
                       scale=float(scale))


@dataclass(frozen=True)
class ParameterLayout:
    """Where the parameters sit in an augmented problem: the user's state and control sizes
    ``nx``, ``nu`` and the parameters, in order."""

    nx: int
    nu: int
    params: tuple
    report: Callable | None = None   # raw values {name: omega} -> what the user set bounds on
    # with_parameters / with_free_time (None for phases): the user's problem and how its
    # functions see the augmented state
    base: Problem | None = field(default=None, compare=False, repr=False)
    view: object = field(default=None, compare=False, repr=False)
    unreport: Callable | None = None   # ``report``'s inverse (warm starts from a solution)
    phases: tuple = field(default=(), compare=False, repr=False)   # multi_phase's ``Phase``s

    @property
    def n(self) -> int:
        return len(self.params)

    @property
    def flag(self) -> int:
        """The index of the stage-0 flag phi in the augmented state."""
        return self.nx + self.n

    def values(self, X: np.ndarray) -> dict:
        """{name: value} of the parameters on an augmented trajectory X (N+1, nx + n + 1)."""
        raw = {p.name: float(X[-1, self.nx + i]) for i, p in enumerate(self.params)}
        return raw if self.report is None else self.report(raw)

    def padded(self, U: np.ndarray, start: dict | None = None) -> np.ndarray:
        """A user's (N, nu) controls with the increments appended (N, nu + n): idle, or with
        ``start`` ({name: value}, as ``values`` reports them) the stage-0 increments that set
        the parameters there; augmented controls pass unchanged."""
        U = np.asarray(U, float)
        if not (U.ndim == 2 and U.shape[1] == self.nu):
            return U
        W = np.hstack([U, np.zeros((U.shape[0], self.n))])
        if start is not None and U.shape[0] > 0:
            raw = start if self.unreport is None else self.unreport(start)
            for i, p in enumerate(self.params):
                if p.name in raw:
                    W[0, self.nu + i] = (min(max(raw[p.name], p.lower), p.upper)
                                         - p.guess) / p.scale
        return W

    def rebuild(self, problem: Problem) -> Problem:
        """The same augmentation of another form of the user's problem (e.g. ``throttle``'s
        exact fuel form); only for a layout with a ``base``."""
        return _augmented(problem, self.params, self.view, self.report, self.unreport)

    def user_view(self, X: np.ndarray, U: np.ndarray, stage_dt: np.ndarray) -> tuple:
        """(X (N+1, nx), U (N, nu), the stage lengths as flown (N,)) of an augmented
        trajectory: the user's columns, and a free time's scaled durations."""
        omega = X[-1, self.nx:self.nx + self.n]
        dt = np.asarray(self.view.duration(np.asarray(stage_dt, float), omega), float)
        return X[:, :self.nx].copy(), U[:, :self.nu].copy(), dt


def with_parameters(problem: Problem, params) -> Problem:
    """``problem`` with the static parameters ``params`` (``StaticParameter``s); its functions
    receive the state with the parameters appended (module docstring)."""
    return _augmented(problem, _checked(params), _ParameterView())


def with_free_time(problem: Problem, lower: float, upper: float, guess: float | None = None,
                   time_cost: float = 0.0, name: str = "tof",
                   target: Callable | None = None, scale: float = 1.0) -> Problem:
    """``problem`` with its time of flight free in [lower, upper] (normalised time, as
    ``stage_dt``); ``time_cost`` c adds c T to the terminal cost (module docstring).

    ``target(T, x_target)``: a target that moves, e.g. a planet to rendezvous with: its state at
    the arrival time T (a float or a DA scalar, normalised) given the problem's ``x_target``
    (nx,) -- the target's state at T_ref, the problem's own time of flight. The terminal cost
    and constraints receive it in place of ``x_target``; written for floats and DA
    (``dynamics.kepler.kepler_flow`` moves a body on its orbit). Default: a fixed target.

    ``scale``: the ``StaticParameter`` scale of theta = ln(T / T_ref) (docs/parameters.md
    measures its effect on Earth-Mars and on minimum time)."""
    if target is not None and not callable(target):
        raise DaddyError(f"target must be a function target(T, x_target), got {target!r}")
    if not (isinstance(time_cost, (int, float)) and math.isfinite(time_cost)):
        raise DaddyError(f"time_cost must be a finite number, got {time_cost!r}")
    if not lower > 0:
        raise DaddyError(f"parameter {name!r}: lower must be > 0 (a time of flight), got "
                         f"{lower!r}")
    if not (isinstance(upper, (int, float)) and upper > lower):
        raise DaddyError(f"parameter {name!r}: upper must be a number > lower, got {upper!r}")
    reference = float(np.sum(problem.stage_dt))
    if guess is None:   # the problem's own time of flight, where the bounds allow it
        guess = min(max(reference, lower), upper)
    elif not (isinstance(guess, (int, float)) and lower <= guess <= upper):
        raise DaddyError(f"parameter {name!r}: guess must lie in [{lower}, {upper}], got "
                         f"{guess!r}")
    # the parameter is theta = ln(T / reference): every theta is a positive time, so no
    # iterate can make the durations -- and a cost such as sum u^2 dt -- negative
    def log(t):
        return math.log(t / reference)
    param = StaticParameter(name, log(lower), log(upper), log(guess), scale)

    def report(raw):
        return {name: reference * math.exp(raw[name])}

    def unreport(values):
        return {name: log(values[name])} if values.get(name, 0) > 0 else {}
    return _augmented(problem, _checked([param]),
                      _TimeView(reference, float(time_cost), target, problem.t_start), report,
                      unreport)


def _checked(params) -> tuple:
    params = tuple(params)
    if not params or not all(isinstance(p, StaticParameter) for p in params):
        raise DaddyError("params must be a non-empty sequence of StaticParameter")
    names = [p.name for p in params]
    if len(set(names)) != len(names):
        raise DaddyError(f"parameter names must be distinct, got {names}")
    return tuple(p.checked() for p in params)


# ------------------------------------------------------------------------------ the views
class _ParameterView:
    """The user's functions see [x, omega]; durations unchanged."""

    def state(self, x, omega):
        return dm.concatenate([x, omega])

    def duration(self, dt, omega):
        return dt

    def independent(self, t, omega):
        return t

    def rates(self, rhs, t, y, u, nx):
        dx = rhs(t, y, u)
        return dx if type(dx) is list else dm.stack(list(dx))

    def terminal(self, cost, x, omega, x_target):
        return cost(dm.concatenate([x, omega]), x_target)

    def target(self, x_target, omega):
        return x_target


@dataclass(frozen=True)
class _TimeView:
    """The user's functions see x; durations and rates scaled by T / reference = exp(theta),
    the parameter theta = ln(T / reference)."""

    reference: float
    time_cost: float
    moving: Callable | None = None     # target(T, x_target) (``with_free_time``)
    origin: float = 0.0                # the problem's t_start: where the grid's scaling starts

    def state(self, x, omega):
        return x

    def duration(self, dt, omega):
        return dt * dm.exp(omega[0])

    def independent(self, t, omega):
        return self._flown(t, dm.exp(omega[0]))

    def _flown(self, t, stretch):
        """The independent variable flown at the grid's t: origin + (t - origin) T / T_ref."""
        return self.origin + (t - self.origin) * stretch

    def rates(self, rhs, t, y, u, nx):
        if type(y) is list:   # a single float state as a list (Dynamics.scalar_components)
            e = math.exp(y[nx])
            return [float(d) * e for d in rhs(self._flown(t, e), y[:nx], u)]
        e = dm.exp(y[nx])
        return dm.stack(list(rhs(self._flown(t, e), y[:nx], u))) * e

    def terminal(self, cost, x, omega, x_target):
        return (cost(x, self.target(x_target, omega))
                + (self.time_cost * self.reference) * dm.exp(omega[0]))

    def target(self, x_target, omega):
        """The target at the arrival time T = reference exp(theta)."""
        if self.moving is None:
            return x_target
        return self.moving(self.reference * dm.exp(omega[0]), x_target)


# --------------------------------------------------------------------------- augmentation
def _augmented(p: Problem, params: tuple, view, report: Callable | None = None,
               unreport: Callable | None = None) -> Problem:
    if p.g_path is not None:
        raise DaddyError("static parameters with a path constraint (g_path) are not built yet")
    nx, nu, n = p.nx, p.nu, len(params)
    lay = ParameterLayout(nx, nu, params, report, p, view, unreport)
    scale = np.array([q.scale for q in params])
    lower = np.array([q.lower for q in params])
    upper = np.array([q.upper for q in params])

    def parts(z, w):
        """(x, omega after stage 0's increment, phi, u, v) of augmented z, w."""
        phi = z[lay.flag]
        omega = dm.stack([z[nx + i] + phi * (scale[i] * w[nu + i]) for i in range(n)])
        return z[:nx], omega, phi, w[:nu], w[nu:nu + n]

    inner = _inner_step(p, view, nx, n)

    def step(z, w, dt, t0=0.0):
        x, omega, phi, u, _ = parts(z, w)
        y = inner(dm.concatenate([x, omega]), u, dt, t0)
        return dm.concatenate([y, dm.stack([0.0 * phi])])

    def stage_cost(z, w, dt, hom=(0.0, 1.0)):
        x, omega, _, u, _ = parts(z, w)
        return p.stage_cost(view.state(x, omega), u, view.duration(dt, omega), hom)

    def with_user_rows(fn, z, w, dt, mine):
        """The user's stage constraint rows (if any) above the parameters' own."""
        if fn is None:
            return mine
        x, omega, _, u, _ = parts(z, w)
        return dm.concatenate([fn(view.state(x, omega), u, view.duration(dt, omega)), mine])

    def g_ineq(z, w, dt):
        # the bounds bind on stage 0, where the parameters are set; on later stages the rows
        # read -1 (inactive): the same bound repeated on every stage of a parameter that does
        # not change would make N dependent rows, and a bound at its limit a degenerate vertex
        # for the multipliers (the optimality measure's, the KKT polish's)
        _, omega, phi, _, _ = parts(z, w)
        rows = [phi * ((lower[i] - omega[i]) * (1.0 / scale[i])) - (1.0 - phi)
                for i in range(n)]
        rows += [phi * ((omega[i] - upper[i]) * (1.0 / scale[i])) - (1.0 - phi)
                 for i in range(n)]
        return with_user_rows(p.g_ineq, z, w, dt, dm.stack(rows))

    def g_eq(z, w, dt):
        _, _, phi, _, v = parts(z, w)
        return with_user_rows(p.g_eq, z, w, dt, dm.stack([(1.0 - phi) * v[i] for i in range(n)]))

    def terminal(fn):
        if fn is None:
            return None
        return lambda z, x_target: fn(view.state(z[:nx], z[nx:nx + n]),
                                      view.target(x_target[:nx], z[nx:nx + n]))

    def terminal_cost(z, x_target):
        return view.terminal(p.terminal_cost, z[:nx], z[nx:nx + n], x_target[:nx])

    labels = dict(p.labels)
    names = [q.name for q in params]
    labels["g_ineq"] = tuple(labels.get("g_ineq", ())) + tuple(
        [f"{m} >= lower" for m in names] + [f"{m} <= upper" for m in names])
    labels["g_eq"] = tuple(labels.get("g_eq", ())) + tuple(f"{m} set on stage 0" for m in names)
    guess = np.array([q.guess for q in params])
    return replace(p, x0=np.concatenate([p.x0, guess, [1.0]]),
                   x_target=np.concatenate([p.x_target, guess, [0.0]]),
                   step=StageStep(step, takes_t0=True), stage_cost=stage_cost,
                   terminal_cost=terminal_cost, g_ineq=g_ineq, g_eq=g_eq, g_tineq=terminal(p.g_tineq),
                   g_teq=terminal(p.g_teq), nu=nu + n, labels=labels, parameters=lay,
                   rhs=None)


def _inner_step(p: Problem, view, nx: int, n: int) -> Callable:
    """The user's stage on y = [x, omega] (omega constant over the stage): a FlowStep over a
    right-hand side with zero parameter rates, or a plain step with the view's duration."""
    if isinstance(p.step, FlowStep):
        user = p.step.rhs

        def rates(t, y, u):   # u arrives prepared (the user's prepare_control, once a stage)
            dx = view.rates(user.f, t, y, u, nx)
            if type(dx) is list:   # floats: the list the scalar-component integrators unpack
                return dx + [0.0] * n
            return dm.concatenate([dx, 0.0 * y[nx:nx + n]])
        return FlowStep(Dynamics(rates, scalar_components=user.scalar_components,
                                 prepare_control=user.prepare_control, max_step=user.max_step),
                        p.step.integrator, p.step.tol, p.step.rk4_steps, p.step.derivative_tol)

    def plain(y, u, dt, t0=0.0):
        omega = y[nx:nx + n]
        x1 = p.step(view.state(y[:nx], omega), u, view.duration(dt, omega),
                    view.independent(t0, omega))
        return dm.concatenate([x1, y[nx:nx + n]])
    return plain
