"""Multi-phase problems (issue 46, second part): a sequence of phases solved as one problem.
Each phase has its own stage functions, stage count and static parameters, an initial-state
function Gamma_i(omega_i), and a link psi_i to the next phase (the DA-HDDP formulation of
Maestrini et al., sec. II).

The phases are concatenated into one ``Problem`` on the route of ``static_parameters``. The
state gains every phase's parameters omega, the stage-0 flag, a stage counter k and the
previous phase's final state L:

    z = [x, omega, phi, k, L],   w = [u, v]

On the first stage of phase i + 1:
- the state is restarted at Gamma_{i+1}(omega) when the phase has one (otherwise it carries
  on from phase i's end);
- L keeps phase i's end;
- a stage equality holds the link psi_i(x_end, x_start, omega) = 0.

Every other stage runs its own phase's functions. The counter is exact (its constant part),
so each stage knows its phase without any extra argument. The link multipliers are the AUL's
duals of those rows (``link_multipliers``).

Restrictions of this first version: every phase has the same state and control sizes and
plain stage functions f(x, u, dt) (no ``flow_step``), and there is no ``g_path``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from .da import functions as dm
from .da.core import DA
from .errors import DaddyError
from .problem import Problem, StageStep
from .static_parameters import ParameterLayout, StaticParameter, _checked


@dataclass(frozen=True)
class Phase:
    """One phase.

    Attributes:
        stage_dt: (N_i,) its stage lengths.
        step: f(x, u, dt) -> next x (nx, B), as ``Problem.step`` (a plain function).
        stage_cost: l(x, u, dt, hom) -> (B,).
        g_ineq, g_eq: its stage constraints (x, u, dt) -> (n, B), or None.
        params: its ``StaticParameter``s (any phase's functions see all of them: below).
        start: Gamma(omega) -> its initial state (nx,) from the parameters (omega: every
            phase's, in order), or None: it starts where the previous phase ended (the first
            phase: at x0).
        link: psi(x_end, x_start, omega) -> (n,) equalities joining this phase's end to the
            next phase's start, or None (nothing beyond the start rule).

    The stage functions see x alone; a phase whose dynamics use its parameters reads them
    through ``start`` (the usual case: a launch state, a phase's initial condition).
    """

    name: str
    stage_dt: np.ndarray
    step: Callable
    stage_cost: Callable
    g_ineq: Callable | None = None
    g_eq: Callable | None = None
    params: tuple = ()
    start: Callable | None = None
    link: Callable | None = None

    @property
    def N(self) -> int:
        return int(np.size(self.stage_dt))


def multi_phase(name: str, x0, x_target, phases, terminal_cost: Callable, nu: int,
                g_teq: Callable | None = None, g_tineq: Callable | None = None) -> Problem:
    """The phases as one ``Problem`` (module docstring). x0 (nx,): the first phase's start
    (used unless it has a ``start``); terminal_cost, g_teq, g_tineq: of the last phase's end,
    (x, x_target). Solve it with ``solve``. The result's ``parameters`` are every phase's,
    and ``phase_slices(problem)`` tells the stages of each phase."""
    phases = tuple(phases)
    if not phases or not all(isinstance(p, Phase) for p in phases):
        raise DaddyError("phases must be a non-empty sequence of Phase")
    x0 = np.asarray(x0, float)
    nx = x0.size
    for i, ph in enumerate(phases):
        dt = np.asarray(ph.stage_dt, float)
        if dt.ndim != 1 or dt.size < 1 or not np.all(np.isfinite(dt) & (dt > 0)):
            raise DaddyError(f"phases[{i}] ({ph.name!r}).stage_dt must be N >= 1 positive "
                             "durations")
        if ph.link is not None and i == len(phases) - 1:
            raise DaddyError(f"phases[{i}] ({ph.name!r}).link: the last phase links to "
                             "nothing (its end is held by g_teq / g_tineq)")
    params = [q for ph in phases for q in ph.params]
    if not params:   # the stage-0 machinery needs one parameter: a fixed, unused one
        params = [StaticParameter("_unused", -1.0, 1.0, 0.0)]
    params = _checked(params)
    n = len(params)
    N = [ph.N for ph in phases]
    first = np.cumsum([0] + N[:-1])                 # each phase's first stage
    layout = ParameterLayout(nx, nu, params, phases=phases)
    scale = np.array([q.scale for q in params])
    lower = np.array([q.lower for q in params])
    upper = np.array([q.upper for q in params])
    iw, iphi, ik, iL = nx, nx + n, nx + n + 1, nx + n + 2
    links = [_link_size(ph, i, x0, params) for i, ph in enumerate(phases)]
    for i, ph in enumerate(phases):
        _check_start(ph, i, nx, params)
    n_ineq = [_rows(ph.g_ineq, x0, nu, ph) for ph in phases]
    n_eq = [_rows(ph.g_eq, x0, nu, ph) for ph in phases]

    def split(z, w):
        phi = z[iphi]
        omega = dm.stack([z[iw + i] + phi * (scale[i] * w[nu + i]) for i in range(n)])
        return z[:nx], omega, phi, z[ik], z[iL:iL + nx], w[:nu], w[nu:nu + n]

    def phase_of(k) -> np.ndarray:
        return np.searchsorted(first, np.rint(np.atleast_1d(dm.cons(k))), side="right") - 1

    def begins(k) -> np.ndarray:
        """Columns on the first stage of a phase after the first: restart / link there."""
        kk = np.rint(np.atleast_1d(dm.cons(k)))
        return np.isin(kk, first[1:])

    def starts(x, omega, k):
        """The state the stage starts from: Gamma of the phase where it begins and has one."""
        out = x
        for i, ph in enumerate(phases):
            if i == 0 or ph.start is None:
                continue
            at = np.rint(np.atleast_1d(dm.cons(k))) == first[i]
            if at.any():
                gamma = dm.stack(list(ph.start(omega)))
                out = dm.where(at[None, :], gamma if gamma.ndim == 2 else _columns(gamma, x),
                               out)
        return out

    def by_phase(k, fn_of_phase, rows: int, fill: float):
        """Evaluate fn_of_phase(i, columns) on each phase's columns; a (rows, B) result."""
        which = phase_of(k)
        parts = {}
        for i in np.unique(which):
            idx = np.nonzero(which == i)[0]
            parts[int(i)] = (idx, fn_of_phase(int(i), idx))
        return _scatter(parts, which.size, rows, fill)

    def step(z, w, dt, t0=0.0):
        x, omega, phi, k, L, u, _ = split(z, w)
        xs = starts(x, omega, k)
        at = begins(k)[None, :]
        L_new = dm.where(at, x, L) if at.any() else L
        x1 = by_phase(k, lambda i, idx: phases[i].step(_cols(xs, idx), _cols(u, idx), dt[idx]),
                      nx, 0.0)
        return dm.concatenate([x1, omega, dm.stack([0.0 * phi, k + 1.0]), L_new])

    def stage_cost(z, w, dt, hom=(0.0, 1.0)):
        x, omega, _, k, _, u, _ = split(z, w)
        xs = starts(x, omega, k)
        c = by_phase(k, lambda i, idx: dm.stack([phases[i].stage_cost(
            _cols(xs, idx), _cols(u, idx), dt[idx], hom)]), 1, 0.0)
        return c[0]

    def g_ineq(z, w, dt):
        x, omega, _, k, _, u, _ = split(z, w)
        xs = starts(x, omega, k)
        rows = [(lower[i] - omega[i]) * (1.0 / scale[i]) for i in range(n)]
        rows += [(omega[i] - upper[i]) * (1.0 / scale[i]) for i in range(n)]
        mine = dm.stack(rows)
        m = max(n_ineq)
        if not m:
            return mine
        user = by_phase(k, lambda i, idx: _padded(phases[i].g_ineq, _cols(xs, idx),
                                                  _cols(u, idx), dt[idx], m, -1.0), m, -1.0)
        return dm.concatenate([user, mine])

    def g_eq(z, w, dt):
        x, omega, phi, k, _, u, v = split(z, w)
        xs = starts(x, omega, k)
        parts = [dm.stack([(1.0 - phi) * v[i] for i in range(n)])]
        m = max(n_eq)
        if m:
            parts.insert(0, by_phase(k, lambda i, idx: _padded(
                phases[i].g_eq, _cols(xs, idx), _cols(u, idx), dt[idx], m, 0.0), m, 0.0))
        for i, ph in enumerate(phases[:-1]):   # links, on the next phase's first stage
            if not links[i]:
                continue
            at = (np.rint(np.atleast_1d(dm.cons(k))) == first[i + 1]).astype(float)
            psi = dm.stack(list(ph.link(x, xs, omega)))
            if psi.ndim == 1:
                psi = _columns(psi, x)
            parts.append(psi * at[None, :])
        return parts[0] if len(parts) == 1 else dm.concatenate(parts)

    def terminal_of(fn):
        return None if fn is None else (lambda z, xt: fn(z[:nx], xt[:nx]))

    guess = np.array([q.guess for q in params])
    extra = np.concatenate([guess, [1.0, 0.0], np.zeros(nx)])
    labels = {"g_ineq": tuple([f"phase constraint {j}" for j in range(max(n_ineq))]
                              + [f"{q.name} >= lower" for q in params]
                              + [f"{q.name} <= upper" for q in params]),
              "g_eq": tuple([f"phase equality {j}" for j in range(max(n_eq))]
                            + [f"{q.name} set on stage 0" for q in params]
                            + [f"link {ph.name}->{phases[i + 1].name}[{j}]"
                               for i, ph in enumerate(phases[:-1]) for j in range(links[i])])}
    return Problem(name=name, x0=np.concatenate([x0, extra]),
                   x_target=np.concatenate([np.asarray(x_target, float), extra]),
                   stage_dt=np.concatenate([np.asarray(ph.stage_dt, float) for ph in phases]),
                   step=StageStep(step), stage_cost=stage_cost,
                   terminal_cost=lambda z, xt: terminal_cost(z[:nx], xt[:nx]),
                   g_ineq=g_ineq, g_eq=g_eq, g_teq=terminal_of(g_teq),
                   g_tineq=terminal_of(g_tineq), nu=nu + n, labels=labels, parameters=layout)


def phase_slices(problem: Problem, phases) -> list[slice]:
    """The stage indices of each phase in ``multi_phase``'s problem (states: add 1 to stop)."""
    edges = np.cumsum([0] + [ph.N for ph in phases])
    return [slice(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]


def link_multipliers(problem: Problem, phases, duals: dict) -> dict:
    """{"first->second": (n,) multipliers} of each link, from a solution's ``duals`` (the
    AUL's stage multipliers, sign as the AUL writes J + lambda^T g)."""
    lam = np.asarray(duals.get("lam", []), float)
    labels = problem.labels["g_eq"]
    n_ineq = len(problem.labels["g_ineq"])
    edges = np.cumsum([0] + [ph.N for ph in phases])
    out = {}
    for i, ph in enumerate(phases[:-1]):
        rows = [j for j, name in enumerate(labels)
                if name.startswith(f"link {ph.name}->{phases[i + 1].name}[")]
        if rows and lam.size:
            out[f"{ph.name}->{phases[i + 1].name}"] = lam[[n_ineq + j for j in rows],
                                                         edges[i + 1]]
    return out


def phase_report(problem: Problem, X: np.ndarray, U: np.ndarray, duals: dict) -> list[dict]:
    """Each phase of a ``multi_phase`` problem's solution (augmented X (N+1, .), U (N, .)):
    its name, first stage, its states X (N_i + 1, nx) from its own start (Gamma(omega), or the
    previous phase's end) and controls U (N_i, nu), its parameters and the multipliers of its
    link to the next phase (None without one); plain lists, as a solution's JSON holds them."""
    layout = problem.parameters
    nx, nu, phases = layout.nx, layout.nu, layout.phases
    omega = X[-1, nx:nx + layout.n]
    values = layout.values(X)
    links = link_multipliers(problem, phases, duals)
    out = []
    for i, (ph, s) in enumerate(zip(phases, phase_slices(problem, phases))):
        start = X[s.start, :nx] if ph.start is None or i == 0 else np.asarray(
            dm.stack(list(ph.start(omega))), float)
        lam = links.get(f"{ph.name}->{phases[i + 1].name}") if i + 1 < len(phases) else None
        out.append({"name": ph.name, "first_stage": s.start,
                    "X": np.vstack([start, X[s.start + 1:s.stop + 1, :nx]]).tolist(),
                    "U": U[s, :nu].tolist(),
                    "parameters": {q.name: values[q.name] for q in ph.params},
                    "link_multipliers": None if lam is None else np.asarray(lam).tolist()})
    return out


# ------------------------------------------------------------------------------- helpers
def _link_size(ph: Phase, i: int, x0: np.ndarray, params) -> int:
    if ph.link is None:
        return 0
    omega = np.array([q.guess for q in params])
    try:
        psi = np.asarray(ph.link(x0, x0, omega), float)
    except Exception as exc:   # the user's link failing is bad input, named
        raise DaddyError(f"phases[{i}] ({ph.name!r}).link raised {type(exc).__name__}: "
                         f"{exc}") from exc
    if psi.ndim != 1 or psi.size < 1:
        raise DaddyError(f"phases[{i}] ({ph.name!r}).link must return a vector of n >= 1 "
                         f"equalities, got shape {psi.shape}")
    return psi.size


def _check_start(ph: Phase, i: int, nx: int, params) -> None:
    """A DaddyError naming the phase when its start Gamma(omega) is not a state of nx."""
    if ph.start is None:
        return
    omega = np.array([q.guess for q in params])
    try:
        x = np.asarray(ph.start(omega), float)
    except Exception as exc:   # the user's function failing is bad input, named
        raise DaddyError(f"phases[{i}] ({ph.name!r}).start raised {type(exc).__name__}: "
                         f"{exc}") from exc
    if x.shape != (nx,):
        raise DaddyError(f"phases[{i}] ({ph.name!r}).start must return the state ({nx},) of "
                         f"x0, got shape {x.shape}")


def _rows(fn, x0, nu, ph) -> int:
    if fn is None:
        return 0
    g = np.asarray(fn(np.tile(x0[:, None], (1, 2)), np.zeros((nu, 2)), np.asarray(ph.stage_dt)[:2]
                      if ph.N >= 2 else np.repeat(ph.stage_dt, 2)))
    return int(g.shape[0])


def _cols(a, idx):
    return a[:, idx] if a.ndim == 2 else a[idx]


def _columns(v, like):
    """A (rows,) value broadcast to like's B columns."""
    B = like.shape[-1]
    return dm.stack([v[i] + 0.0 * like[0] for i in range(len(v))]) if B else v


def _padded(fn, x, u, dt, m: int, fill: float):
    if fn is None:
        return dm.stack([0.0 * x[0] + fill for _ in range(m)])
    g = fn(x, u, dt)
    if len(g) == m:
        return g
    return dm.concatenate([g, dm.stack([0.0 * x[0] + fill for _ in range(m - len(g))])])


def _scatter(parts: dict, B: int, rows: int, fill: float):
    """Assemble {phase: (columns, (rows, b) value)} into one (rows, B) float array or DA."""
    values = [v for _, v in parts.values()]
    da = next((v for v in values if isinstance(v, DA)), None)
    if da is None:
        out = np.full((rows, B), fill)
        for idx, v in parts.values():
            out[:, idx] = np.asarray(v)
        return out
    c = np.zeros(da.c.shape[:1] + (rows, B))
    c[0] = fill
    for idx, v in parts.values():
        c[..., idx] = v.c if isinstance(v, DA) else np.asarray(v)[None] * (
            np.arange(c.shape[0]) == 0)[:, None, None]
    return DA(c, da.T)
