"""Explicit Runge-Kutta integrators, generic over floats, numpy arrays and DA.

The right-hand side has the signature ``rhs(t, x, u) -> dx/dt`` with ``x`` of shape (nx, *batch)
and ``u`` (nu, *batch) held constant over the integration (piecewise-constant control). Time ``t``
and step ``h`` may be scalars or arrays of the batch shape, so B stages of different length
integrate in one call.

* ``rk4``: classical fixed-step RK4.
* ``rk78``: Runge-Kutta-Fehlberg 7(8) (Fehlberg 1968, NASA TR R-287) with adaptive steps, each
  batch element on its own step sequence; the error estimate and the step choice use only the
  constant part of a DA state, so the expansion follows the same steps as the float trajectory.
* ``dop853``: Dormand-Prince 8(5,3) for one float state, solve_ivp's DOP853 step for step (the
  solver's independent re-propagation check).
"""
from __future__ import annotations

import functools
import math
from fractions import Fraction as F

import numpy as np

from . import dop853_tableau as _dop
from .da import functions as dm
from .da.core import DA, _wrap
from .dynamics.rhs import Dynamics, as_dynamics
from .errors import DaddyError

# ---------------------------------------------------------------------------------- RKF7(8)
_C = [F(0), F(2, 27), F(1, 9), F(1, 6), F(5, 12), F(1, 2), F(5, 6), F(1, 6), F(2, 3), F(1, 3),
      F(1), F(0), F(1)]
_A = [
    [],
    [F(2, 27)],
    [F(1, 36), F(1, 12)],
    [F(1, 24), 0, F(1, 8)],
    [F(5, 12), 0, F(-25, 16), F(25, 16)],
    [F(1, 20), 0, 0, F(1, 4), F(1, 5)],
    [F(-25, 108), 0, 0, F(125, 108), F(-65, 27), F(125, 54)],
    [F(31, 300), 0, 0, 0, F(61, 225), F(-2, 9), F(13, 900)],
    [F(2), 0, 0, F(-53, 6), F(704, 45), F(-107, 9), F(67, 90), F(3)],
    [F(-91, 108), 0, 0, F(23, 108), F(-976, 135), F(311, 54), F(-19, 60), F(17, 6), F(-1, 12)],
    [F(2383, 4100), 0, 0, F(-341, 164), F(4496, 1025), F(-301, 82), F(2133, 4100), F(45, 82),
     F(45, 164), F(18, 41)],
    [F(3, 205), 0, 0, 0, 0, F(-6, 41), F(-3, 205), F(-3, 41), F(3, 41), F(6, 41), 0],
    [F(-1777, 4100), 0, 0, F(-341, 164), F(4496, 1025), F(-289, 82), F(2193, 4100), F(51, 82),
     F(33, 164), F(12, 41), 0, F(1)],
]
_B8 = [0, 0, 0, 0, 0, F(34, 105), F(9, 35), F(9, 35), F(9, 280), F(9, 280), 0, F(41, 840),
       F(41, 840)]
RK78_C = np.array([float(c) for c in _C])
RK78_A = [[float(a) for a in row] for row in _A]
RK78_B = np.array([float(b) for b in _B8])
RK78_ERR = float(F(41, 840))  # error = 41/840 (k1 + k11 - k12 - k13) h
_SINGLE_BATCH = 8   # float batches up to this size integrate state by state (_rk78_single)


class _Stages:
    """Stage derivatives k_i of one RK step in one buffer, so x + h * sum_j a_ij k_j is a single
    BLAS contraction over the raw coefficient arrays (works for arrays and DA alike).

    A DA state (M, nx, *batch) is held component-major, (nx, M, *batch) in memory: the states
    it hands to the right-hand side (``combine``) are views whose components x[i] are contiguous
    (M, *batch) blocks, which numpy processes in one inner loop instead of M short ones (4x
    cheaper per operation at B = 110); ``da.functions.stack`` builds the rhs's value in the same
    layout, so ``push`` is a plain copy."""

    def __init__(self, x, n_stages: int):
        self.is_da = isinstance(x, DA)
        raw = x.c.swapaxes(0, 1) if self.is_da else np.asarray(x)
        self.T = x.T if self.is_da else None
        self.buf = np.empty((n_stages,) + raw.shape, dtype=raw.dtype)
        self.raw = raw
        self.count = 0

    def push(self, k):
        self.buf[self.count] = k.c.swapaxes(0, 1) if self.is_da else k
        self.count += 1

    def constant_parts(self) -> np.ndarray:
        """(n_stages, nx, *batch) the float values of the k_i (a DA's constant parts)."""
        return self.buf[:, :, 0] if self.is_da else self.buf

    def combine(self, x_raw, h, coeffs):
        """x + h * sum_j coeffs[j] k_j (h broadcast over the batch, the trailing axes)."""
        m = len(coeffs)
        if m == 0:
            out = x_raw
        else:
            if m == 1:   # one product (numpy's matmul of a single row is ~4x slower)
                acc = self.buf[0] * float(coeffs[0])
            else:
                acc = (np.asarray(coeffs) @ self.buf[:m].reshape(m, -1)).reshape(x_raw.shape)
            acc *= h
            out = np.add(x_raw, acc, out=acc)
        return _wrap(out.swapaxes(0, 1), self.T) if self.is_da else out


_RK4_A = [[], [0.5], [0.0, 0.5], [0.0, 0.0, 1.0]]
_RK4_B = [1 / 6, 1 / 3, 1 / 3, 1 / 6]


def rk4(rhs, x, u, t0, dt, steps: int = 20):
    """Integrate ``rhs`` over ``dt`` with ``steps`` fixed RK4 steps.

    Args:
        rhs: a ``dynamics.Dynamics`` or a plain rhs(t, x, u) -> dx/dt.
        x: (nx, *batch) initial state (array or DA).
        u: (nu, *batch) control, constant over the interval.
        t0: start time (scalar or batch array).
        dt: interval length (scalar or batch array), normalised time units.
        steps: number of RK4 steps.
    Returns:
        state at t0 + dt, same type and shape as ``x``.
    """
    if steps < 1:
        raise DaddyError(f"rk4 steps must be >= 1, got {steps}")
    dyn = as_dynamics(rhs)
    rhs, u = dyn.f, dyn.prepared(u)
    h = np.asarray(dt, dtype=float) / steps
    t = np.asarray(t0, dtype=float)
    for _ in range(steps):
        st = _Stages(x, 4)
        xr = st.raw
        st.push(rhs(t, x, u))
        st.push(rhs(t + h / 2, st.combine(xr, h, _RK4_A[1]), u))
        st.push(rhs(t + h / 2, st.combine(xr, h, _RK4_A[2]), u))
        st.push(rhs(t + h, st.combine(xr, h, _RK4_A[3]), u))
        x = st.combine(xr, h, _RK4_B)
        t = t + h
    return _standard_layout(x)


def rk78(rhs, x, u, t0, dt, tol: float = 1e-13, h0=None, max_steps: int = 10_000,
         stats: dict | None = None):
    """Integrate ``rhs`` over ``dt`` with adaptive Runge-Kutta-Fehlberg 7(8).

    Each batch element keeps its own step size; the loop runs until every element has reached
    its final time (finished elements take zero-length steps). The local error is the 7th/8th
    order difference of the state's constant part, in the infinity norm over components, and a
    step is accepted when it is <= ``tol`` (absolute).

    Args:
        rhs, x, u, t0: as for ``rk4``.
        dt: interval length (scalar or batch array); may be negative.
        tol: absolute local error tolerance.
        h0: initial step (default dt / 8).
        max_steps: bound on attempted steps (accepted or rejected) before raising.
        stats: optional dict receiving ``steps`` (attempted) and ``rhs_calls``.
    Returns:
        state at t0 + dt, same type and shape as ``x``.
    """
    if not tol > 0:
        raise DaddyError(f"rk78 tol must be > 0, got {tol}")
    dyn = as_dynamics(rhs)
    u = dyn.prepared(u)
    real = (isinstance(x, np.ndarray) and x.dtype.kind == "f"
            and np.asarray(u).dtype.kind in "fiu")   # not DA, not complex (complex-step tests)
    if real and x.ndim == 1 and np.ndim(dt) == 0 and np.ndim(t0) == 0:
        return _rk78_single(dyn, x, u, float(t0), float(dt), tol, h0, max_steps, stats)
    if real and x.ndim == 2 and x.shape[1] <= _SINGLE_BATCH and stats is None:
        return _rk78_few(dyn, x, u, t0, dt, tol, h0, max_steps)
    rhs = dyn.f
    x0 = dm.cons(x)
    batch = x0.shape[1:]
    dt = np.broadcast_to(np.asarray(dt, dtype=float), batch).copy()
    if not np.all(np.isfinite(dt)):
        raise DaddyError("rk78 interval dt contains NaN or inf")
    # steps are controlled in the time since the interval's start (from 0, as for an autonomous
    # system: the same steps whatever t0); the rhs sees t0 + that time
    base = np.broadcast_to(np.asarray(t0, dtype=float), batch).copy()
    t = np.zeros(batch)
    t_end = dt.copy()
    direction = np.where(dt >= 0, 1.0, -1.0)
    h = np.abs(dt) / 8.0 if h0 is None else np.broadcast_to(np.abs(np.asarray(h0, float)), batch).copy()
    h = np.where(h > 0, h, 1.0)
    if dyn.max_step is not None:
        h = np.minimum(h, dyn.max_step)
    n_steps = 0
    arrived = _Arrived(x) if len(batch) == 1 else None
    while True:
        remaining = np.abs(t_end - t)
        active = remaining > 1e-15 * np.maximum(1.0, np.abs(t_end))
        if not np.any(active):
            break
        if arrived is not None and active.sum() <= _COMPACT_SHARE * active.size:
            keep = np.flatnonzero(active)
            x, u = arrived.leave(x, u, keep)
            t, t_end, base, direction, h, dt, active, remaining = (
                v[keep] for v in (t, t_end, base, direction, h, dt, active, remaining))
        n_steps += 1
        if n_steps > max_steps:
            raise DaddyError(f"rk78 exceeded max_steps={max_steps} (stiff or singular dynamics?)")
        hs = np.where(active, np.minimum(h, remaining), 0.0) * direction
        x_new, err = _rk78_trial(rhs, x, u, base + t, hs)
        accept = active & (err <= tol)
        x = dm.where(accept, x_new, x) if np.ndim(accept) else (x_new if accept else x)
        t = np.where(accept, t + hs, t)
        h = _next_step(h, hs, err, tol, active, dt, dyn.max_step)
    if stats is not None:
        stats["steps"] = n_steps
        stats["rhs_calls"] = 13 * n_steps
    return _standard_layout(x if arrived is None else arrived.result(x))


def _rk78_few(dyn: Dynamics, x: np.ndarray, u, t0, dt, tol: float, h0, max_steps: int):
    """``rk78`` of a few float states (nx, B), one at a time in plain Python: numpy's per-call
    overhead dominates on 7 x B arrays; the same steps as the batched path."""
    B = x.shape[1]
    u, t0, dt = (np.broadcast_to(np.asarray(v, dtype=float), s) for v, s in
                 ((u, (np.shape(u)[0], B)), (t0, (B,)), (dt, (B,))))
    hb = None if h0 is None else np.broadcast_to(np.asarray(h0, dtype=float), (B,))
    return np.stack([_rk78_single(dyn, x[:, j], u[:, j], float(t0[j]), float(dt[j]), tol,
                                  None if hb is None else hb[j], max_steps, None)
                     for j in range(B)], axis=1)


def _rk78_trial(rhs, x, u, t, hs):
    """One RKF7(8) step of length hs (batch) from x at t: the 8th-order state and the local
    error estimate (infinity norm of the 7th/8th-order difference of the constant parts)."""
    st = _Stages(x, 13)
    for i in range(13):
        st.push(rhs(t + RK78_C[i] * hs, st.combine(st.raw, hs, RK78_A[i]), u))
    x_new = st.combine(st.raw, hs, RK78_B)
    kb = st.constant_parts()
    err_vec = (kb[0] + kb[10] - kb[11] - kb[12]) * (RK78_ERR * hs)
    err = np.max(np.abs(err_vec), axis=0) if err_vec.ndim else np.abs(err_vec)
    if not np.all(np.isfinite(err)):
        raise DaddyError("rk78: dynamics returned NaN or inf")
    return x_new, err


def _next_step(h, hs, err, tol: float, active, dt, max_step: float | None):
    """The classic step controller: safety factor 0.8, growth bounded in [0.2, 5], at most
    ``max_step``; inactive elements keep theirs."""
    with np.errstate(divide="ignore"):
        fac = 0.8 * (tol / np.maximum(err, 1e-300)) ** (1.0 / 8.0)
    fac = np.clip(fac, 0.2, 5.0)
    h = np.where(active, np.abs(hs) * fac, h)
    h = np.where(h > 0, h, np.abs(dt) / 8.0 + 1e-300)
    if max_step is not None:
        h = np.minimum(h, max_step)
    return h


# the batch drops its arrived elements when at most this share of it is still integrating
_COMPACT_SHARE = 0.9


class _Arrived:
    """The batched RK78's elements that have reached their final time, kept out of its steps.

    Each batch element takes its own steps, and the batch loops until the slowest arrives: a
    stage that needs 18 steps (a perilune pass) made every stage of an NRHO batch take 18 at
    full cost, 10x their own 1.7 on average. When the still-integrating share falls to
    ``_COMPACT_SHARE``, the arrived elements are stored here and the loop goes on with the
    others (a gather per compaction; every element's arithmetic is unchanged)."""

    def __init__(self, x):
        self.full = _wrap(x.c.copy(), x.T) if isinstance(x, DA) else np.array(x)
        self.index = np.arange(self.full.shape[-1])   # where the current batch's elements belong

    def leave(self, x, u, keep: np.ndarray):
        """(x, u) of the elements ``keep`` (indices into the current batch); the others' final
        states are stored. u keeps its shape where it does not carry the batch axis."""
        self._store(x)
        n = self.index.size
        self.index = self.index[keep]
        if u is not None and len(u.shape) >= 2 and u.shape[-1] == n:
            u = _take_batch(u, keep)
        return _take_batch(x, keep), u

    def result(self, x):
        """The whole batch's final states, x the current batch's."""
        self._store(x)
        return self.full

    def _store(self, x):
        if isinstance(x, DA):
            self.full.c[..., self.index] = x.c
        else:
            self.full[..., self.index] = x


def _take_batch(v, keep: np.ndarray):
    """The batch elements ``keep`` (last axis) of an array or DA."""
    return _wrap(v.c[..., keep], v.T) if isinstance(v, DA) else np.asarray(v)[..., keep]


def _standard_layout(x):
    """A DA state in the standard C-contiguous (M, nx, *batch) layout (the integrators work
    component-major, ``_Stages``); one copy per integration, so the maps the solver keeps are
    reshaped and sliced without further copies."""
    if isinstance(x, DA) and not x.c.flags.c_contiguous:
        return _wrap(np.ascontiguousarray(x.c), x.T)
    return x


# the nonzero (j, a_ij) of each row and (j, b_j) of the 8th-order weights, as Python floats
_RK78_ROWS = [[(j, a) for j, a in enumerate(row) if a != 0.0] for row in RK78_A]
_RK78_WEIGHTS = [(j, float(b)) for j, b in enumerate(RK78_B) if b != 0.0]


def _float_list(v) -> list:
    """A right-hand side's value as a list of Python floats: the list a scalar-component rhs
    returns (``da.functions.vector``) as it is, an ndarray's tolist() directly."""
    if type(v) is list:
        return v
    return v.tolist() if type(v) is np.ndarray else np.asarray(v, dtype=float).tolist()


def _unpack_rhs(names: list[str], call: str) -> list[str]:
    """Generated lines assigning a right-hand side's value ``call`` to the float variables
    ``names``: a list (what ``da.functions.vector`` returns on floats) unpacks directly, anything
    else through ``_float_list``, without a function call per rhs call for the list."""
    return [f"k_ = {call}", "if type(k_) is not list:", "    k_ = _floats(k_)",
            f"{', '.join(names)}, = k_"]


@functools.lru_cache(maxsize=None)
def _single_step(nx: int):
    """One RK78 step of an nx-component state in plain Python floats, generated as straight-line
    code: ``step(rhs, state, t, x, u, hs) -> (x_new, err)`` with x, x_new lists of nx floats, err
    the scaled error estimate (raises on a non-finite one). Unrolled, the ~60 combinations
    x + (a_ij h) k_j of a step cost local-variable arithmetic only (loops over lists cost more
    than twice as much), summed left to right in j as the loops did (bit-identical results)."""
    comps = range(nx)

    def combo(prefix, rows, m):   # x_m + (c_j h) k_j,m + ... evaluated left to right
        return " + ".join([f"x{m}"] + [f"{prefix}{j} * k{j}_{m}" for j, _ in rows])

    body = [f"x{m} = x[{m}]" for m in comps]
    body += _unpack_rhs([f"k0_{m}" for m in comps], "rhs(t, state(x), u)")
    for i in range(1, 13):
        body += [f"a{i}_{j} = {a!r} * hs" for j, a in _RK78_ROWS[i]]
        xi = ", ".join(combo(f"a{i}_", _RK78_ROWS[i], m) for m in comps)
        body += _unpack_rhs([f"k{i}_{m}" for m in comps],
                            f"rhs(t + {float(RK78_C[i])!r} * hs, state([{xi}]), u)")
    body += [f"e{m} = abs(k0_{m} + k10_{m} - k11_{m} - k12_{m})" for m in comps]
    body.append(f"if not _isfinite({' + '.join(f'e{m}' for m in comps)}):")
    body.append('    raise DaddyError("rk78: dynamics returned NaN or inf")')
    body += [f"b{j} = {b!r} * hs" for j, b in _RK78_WEIGHTS]
    xn = ", ".join(combo("b", _RK78_WEIGHTS, m) for m in comps)
    body.append(f"return [{xn}], max({', '.join(f'e{m}' for m in comps)}, 0.0) "
                f"* ({RK78_ERR!r} * abs(hs))")
    src = "def step(rhs, state, t, x, u, hs):\n" + "".join(f"    {ln}\n" for ln in body)
    namespace = {"_floats": _float_list,
                 "_isfinite": math.isfinite, "DaddyError": DaddyError}
    exec(compile(src, f"<rk78 step, nx={nx}>", "exec"), namespace)
    return namespace["step"]


def _plain_float_args(dyn: Dynamics, x, u):
    """(f, state, u, x) for the plain-Python single-state integrators: the rhs function,
    ``state`` turning a list of floats into what it receives (the list itself when it has
    ``scalar_components``, else a numpy array), u as it receives it, x as a list of floats."""
    if dyn.scalar_components:
        return dyn.f, list, [float(v) for v in u], [float(v) for v in x]
    return dyn.f, np.array, u, [float(v) for v in x]


def _rk78_single(dyn: Dynamics, x, u, t0, dt, tol, h0, max_steps, stats):
    """RK78 for one float state: same scheme and step control as the batched path, in plain
    Python floats (the Std/Dyn forward passes integrate one 7-component state at a time, where
    every numpy call is overhead), one generated straight-line step (``_single_step``).

    A right-hand side with ``Dynamics.scalar_components`` (it reads x and u only by integer
    index, like the catalogue models) receives lists of Python floats; any other receives numpy
    arrays, as documented for ``rk78``. ``u`` is prepared already."""
    rhs, state, uu, x = _plain_float_args(dyn, x, u)
    step = _single_step(len(x))
    t, t_end = 0.0, dt   # controlled from 0, as in the batched path; the rhs sees t0 + t
    direction = 1.0 if dt >= 0 else -1.0
    h = abs(dt) / 8.0 if h0 is None else abs(float(h0))
    if h == 0.0:
        return np.array(x)
    h_max = math.inf if dyn.max_step is None else dyn.max_step
    h = min(h, h_max)
    n_steps = 0
    while abs(t_end - t) > 1e-15 * max(1.0, abs(t_end)):
        n_steps += 1
        if n_steps > max_steps:
            raise DaddyError(f"rk78 exceeded max_steps={max_steps} (stiff or singular dynamics?)")
        hs = min(h, abs(t_end - t)) * direction
        try:
            x_new, err = step(rhs, state, t0 + t, x, uu, hs)
        except ValueError as exc:   # the rhs's own error, or it returned the wrong length
            n_out = np.size(rhs(t0 + t, state(x), uu))
            if n_out != len(x):
                raise DaddyError(f"rk78: rhs returned {n_out} components for a state of "
                                 f"{len(x)} components") from exc
            raise
        if err <= tol:
            x = x_new
            t += hs
        h = min(h_max, abs(hs) * min(5.0, max(0.2, 0.8 * (tol / max(err, 1e-300)) ** 0.125)))
    if stats is not None:
        stats["steps"] = n_steps
        stats["rhs_calls"] = 13 * n_steps
    return np.array(x)


# ---------------------------------------------------------------------------------- DOP853
_DOP_STAGES = _dop.N_STAGES   # 12 stages, then f at the new point (FSAL; not in the error)
_DOP_ROWS, _DOP_WEIGHTS, _DOP_E5, _DOP_E3 = _dop.A_ROWS, _dop.B, _dop.E5, _dop.E3
_DOP_SAFETY, _DOP_MIN_FACTOR, _DOP_MAX_FACTOR = 0.9, 0.2, 10.0   # scipy's RungeKutta values
_DOP_EXPONENT = -1.0 / 8.0   # -1 / (error estimator order 7 + 1)


@functools.lru_cache(maxsize=None)
def _dop853_step(nx: int):
    """One DOP853 step of an nx-component float state as generated straight-line code (as
    ``_single_step`` for RK78): ``step(rhs, state, t, x, f, u, h, rtol, atol) -> (x_new,
    f_new, err)`` with x, f = rhs(t, x), x_new, f_new lists of nx floats and err scipy's
    error norm (accept when < 1; NaN when the trial step met NaN dynamics)."""
    comps = range(nx)

    def combo(rows, m):   # (a_0 k_0,m + a_1 k_1,m + ...), scipy's K^T a order
        return "(" + " + ".join(f"{a!r} * k{j}_{m}" for j, a in rows) + ")"

    body = [f"x{m} = x[{m}]" for m in comps]
    body.append(f"{', '.join(f'k0_{m}' for m in comps)}, = f")
    for i in range(1, _DOP_STAGES):
        xi = ", ".join(f"x{m} + {combo(_DOP_ROWS[i], m)} * h" for m in comps)
        body += _unpack_rhs([f"k{i}_{m}" for m in comps],
                            f"rhs(t + {_dop.C[i]!r} * h, state([{xi}]), u)")
    body += [f"y{m} = x{m} + {combo(_DOP_WEIGHTS, m)} * h" for m in comps]
    body.append(f"fn = _floats(rhs(t + h, state([{', '.join(f'y{m}' for m in comps)}]), u))")
    body += [f"s{m} = atol + max(abs(x{m}), abs(y{m})) * rtol" for m in comps]
    body.append("e5 = " + " + ".join(f"({combo(_DOP_E5, m)} / s{m}) ** 2" for m in comps))
    body.append("e3 = " + " + ".join(f"({combo(_DOP_E3, m)} / s{m}) ** 2" for m in comps))
    body.append("err = 0.0 if e5 == 0.0 and e3 == 0.0 else "
                f"abs(h) * e5 / _sqrt((e5 + 0.01 * e3) * {nx})")
    body.append(f"return [{', '.join(f'y{m}' for m in comps)}], fn, err")
    src = "def step(rhs, state, t, x, f, u, h, rtol, atol):\n" + "".join(
        f"    {ln}\n" for ln in body)
    namespace = {"_floats": _float_list, "_sqrt": math.sqrt}
    exec(compile(src, f"<dop853 step, nx={nx}>", "exec"), namespace)
    return namespace["step"]


def dop853_batch(rhs, x: np.ndarray, u: np.ndarray, t0, dt, rtol: float = 1e-12,
                 atol: float = 1e-12, max_steps: int = 100_000) -> np.ndarray:
    """``dop853`` for B float states at once, each over its own interval with its own step
    control: the same scheme, error norm and step control per member (first trial step the
    whole interval), as numpy operations on (nx, B) arrays. For many independent intervals --
    e.g. every stage of a trajectory from its own start state -- this costs a few rhs calls on
    arrays instead of ~13 per interval in Python (4960 LEO stages: milliseconds, not 0.5 s).

    Args:
        rhs: a ``Dynamics`` or a plain rhs(t, x, u) -> dx/dt (called with (nx, B) arrays).
        x: (nx, B) initial states; u: (nu, B) controls (prepared here); t0, dt: (B,) or
            scalars, each member's start time and interval length (dt may be negative).
        rtol, atol, max_steps: as for ``dop853`` (max_steps per member).
    Returns:
        (nx, B) states at t0 + dt.
    Raises:
        DaddyError: a member's step fell below round-off (NaN or inf dynamics, a singularity)
        or max_steps was exceeded.
    """
    dyn = as_dynamics(rhs)
    f = dyn.f
    x = np.array(x, dtype=float)
    B = x.shape[1]
    u = dyn.prepared(np.asarray(u, dtype=float))
    t0 = np.broadcast_to(np.asarray(t0, dtype=float), (B,))
    dt = np.broadcast_to(np.asarray(dt, dtype=float), (B,))
    direction = np.where(dt >= 0, 1.0, -1.0)
    t = np.zeros(B)
    h_abs = np.abs(dt).copy()
    rejected = np.zeros(B, dtype=bool)
    k0 = np.asarray(f(t0, x, u), dtype=float)
    if k0.shape != x.shape:
        raise DaddyError(f"dop853_batch: rhs returned shape {k0.shape} for states {x.shape}")
    for _ in range(max_steps):
        active = direction * (t - dt) < 0
        if not active.any():
            return x
        eps = np.abs(np.nextafter(t, direction * np.inf) - t)
        if np.any(active & (h_abs < 10 * eps)):
            raise DaddyError("dop853_batch: step size below round-off (NaN or inf dynamics, or "
                             "a singularity)")
        t_new = t + h_abs * direction
        t_new = np.where(direction * (t_new - dt) > 0, dt, t_new)
        h = np.where(active, t_new - t, 0.0)
        K = [k0]
        for i in range(1, _DOP_STAGES):
            xi = x + h * sum(a * K[j] for j, a in _DOP_ROWS[i])
            K.append(np.asarray(f(t0 + t + _dop.C[i] * h, xi, u), dtype=float))
        y = x + h * sum(b * K[j] for j, b in _DOP_WEIGHTS)
        scale = atol + np.maximum(np.abs(x), np.abs(y)) * rtol
        e5 = np.sum((sum(e * K[j] for j, e in _DOP_E5) / scale) ** 2, axis=0)
        e3 = np.sum((sum(e * K[j] for j, e in _DOP_E3) / scale) ** 2, axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            err = np.where((e5 == 0) & (e3 == 0), 0.0,
                           np.abs(h) * e5 / np.sqrt((e5 + 0.01 * e3) * x.shape[0]))
            grow = np.where(err == 0, _DOP_MAX_FACTOR,
                            np.minimum(_DOP_MAX_FACTOR, _DOP_SAFETY * err ** _DOP_EXPONENT))
            shrink = np.where(np.isnan(err), _DOP_MIN_FACTOR,
                              np.maximum(_DOP_MIN_FACTOR, _DOP_SAFETY * err ** _DOP_EXPONENT))
        accept = active & (err < 1)
        if accept.any():
            fn = np.asarray(f(t0 + t + h, y, u), dtype=float)   # (FSAL: the next k0)
            x = np.where(accept, y, x)
            k0 = np.where(accept, fn, k0)
            t = np.where(accept, t_new, t)
        h_abs = np.where(accept, h_abs * np.where(rejected, np.minimum(1.0, grow), grow),
                         np.where(active, h_abs * shrink, h_abs))
        rejected = np.where(accept, False, rejected | active)
    raise DaddyError(f"dop853_batch exceeded max_steps={max_steps}")


def dop853(rhs, x, u, t0, dt, rtol: float = 1e-12, atol: float = 1e-12, first_step=None,
           max_steps: int = 100_000, stats: dict | None = None) -> np.ndarray:
    """Integrate one float state with Dormand-Prince 8(5,3) (Hairer's DOP853): the scheme, error
    norm and step control of ``scipy.integrate.solve_ivp(method="DOP853")``, in plain Python
    floats with a generated straight-line step (solve_ivp's per-step numpy overhead is ~3x the
    cost of a 7-component rhs). It serves as the independent check of the solver's RK78 maps.

    A trial step whose error norm is NaN (the dynamics returned NaN somewhere in it, e.g. a
    whole-stage trial step through a singularity) is rejected and shrunk by the minimum factor,
    as scipy does.

    Args:
        rhs: a ``Dynamics`` or a plain rhs(t, x, u) -> dx/dt; receives lists of floats when
            it has ``scalar_components``, numpy arrays otherwise.
        x: (nx,) initial state; u: control, constant over the interval (prepared here).
        t0, dt: start time and interval length (normalised units; dt may be negative).
        rtol, atol: scipy's relative and absolute tolerances.
        first_step: first trial step (default |dt|: the whole interval, error control decides).
        max_steps: bound on attempted steps before raising.
        stats: optional dict receiving ``steps`` (accepted), ``rejected`` and ``rhs_calls``.
    Returns:
        (nx,) state at t0 + dt.
    Raises:
        DaddyError: the step fell below round-off of t (dynamics NaN or inf, or singular), or
        max_steps was exceeded.
    """
    dyn = as_dynamics(rhs)
    rhs, state, uu, x = _plain_float_args(dyn, x, dyn.prepared(u))
    t0, dt = float(t0), float(dt)
    t, t_end = 0.0, dt   # steps controlled from 0 (as rk78's); the rhs sees t0 + t
    direction = 1.0 if dt >= 0 else -1.0
    h_abs = abs(dt) if first_step is None else abs(float(first_step))
    step = _dop853_step(len(x))
    f = _float_list(rhs(t0, state(x), uu))
    if len(f) != len(x):
        raise DaddyError(f"dop853: rhs returned {len(f)} components for a state of {len(x)}")
    accepted = rejected_total = 0
    while direction * (t - t_end) < 0:
        rejected = False
        while True:
            if accepted + rejected_total >= max_steps:
                raise DaddyError(f"dop853 exceeded max_steps={max_steps}")
            if h_abs < 10 * abs(math.nextafter(t, direction * math.inf) - t):
                raise DaddyError(f"dop853: step size below round-off at t = {t0 + t!r} (NaN or inf "
                                 "dynamics, or a singularity)")
            t_new = t + h_abs * direction
            if direction * (t_new - t_end) > 0:
                t_new = t_end
            h = t_new - t
            h_abs = abs(h)
            x_new, f_new, err = step(rhs, state, t0 + t, x, f, uu, h, rtol, atol)
            if err < 1:
                factor = (_DOP_MAX_FACTOR if err == 0 else
                          min(_DOP_MAX_FACTOR, _DOP_SAFETY * err ** _DOP_EXPONENT))
                h_abs *= min(1.0, factor) if rejected else factor
                break
            h_abs *= (_DOP_MIN_FACTOR if err != err   # NaN: scipy's max(0.2, nan) = 0.2
                      else max(_DOP_MIN_FACTOR, _DOP_SAFETY * err ** _DOP_EXPONENT))
            rejected = True
            rejected_total += 1
        t, x, f = t_new, x_new, f_new
        accepted += 1
    if stats is not None:
        stats.update(steps=accepted, rejected=rejected_total,
                     rhs_calls=1 + _DOP_STAGES * (accepted + rejected_total))
    return np.array(x)
