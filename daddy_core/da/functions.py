"""Elementary functions that dispatch on type, so one function body serves floats, arrays and DA.

Write dynamics with ``from daddy_core.da import functions as dm`` and ``dm.sqrt(x)``; on a float or
numpy array this is ``numpy.sqrt``, on a ``DA`` it is the truncated Taylor composition.
"""
from __future__ import annotations

import math

import numpy as np

from ..errors import DaddyError
from .core import DA, _atan_nilpotent, constant


def _is_da(*xs) -> bool:
    return any(isinstance(x, DA) for x in xs)


def sqrt(x):
    """Square root (a DA must have a positive constant part). A Python float goes to ``math``
    (4x cheaper than a numpy scalar call), NaN for a negative argument as numpy gives."""
    if type(x) is float:
        return math.sqrt(x) if x >= 0.0 else math.nan
    return x.sqrt() if isinstance(x, DA) else np.sqrt(x)


def exp(x):
    return x.exp() if isinstance(x, DA) else np.exp(x)


def tanh(x):
    return x.tanh() if isinstance(x, DA) else np.tanh(x)


def log(x):
    return x.log() if isinstance(x, DA) else np.log(x)


def sin(x):
    if type(x) is float:
        return math.sin(x) if math.isfinite(x) else math.nan
    return x.sin() if isinstance(x, DA) else np.sin(x)


def cos(x):
    if type(x) is float:
        return math.cos(x) if math.isfinite(x) else math.nan
    return x.cos() if isinstance(x, DA) else np.cos(x)


def tan(x):
    return x.tan() if isinstance(x, DA) else np.tan(x)


def arctan(x):
    return x.arctan() if isinstance(x, DA) else np.arctan(x)


def arctan2(y, x):
    """Four-quadrant arctangent of y/x; constant part from ``numpy.arctan2``."""
    if not _is_da(y, x):
        return np.arctan2(y, x)
    y0, x0 = _cons(y), _cons(x)
    den0 = x0 * x0 + y0 * y0
    if np.any(den0 == 0):
        raise DaddyError("arctan2 of a DA at the origin (x = y = 0) is not differentiable")
    # arctan2(y, x) - arctan2(y0, x0) = atan((x0 y - y0 x) / (x0 x + y0 y)), argument nilpotent.
    z = (x0 * y - y0 * x) / (x0 * x + y0 * y)
    return _atan_nilpotent(z) + np.arctan2(y0, x0)


def hypot(*xs):
    """Euclidean norm of the arguments, sqrt(x0^2 + x1^2 + ...)."""
    s = xs[0] * xs[0]
    for x in xs[1:]:
        s = s + x * x
    return sqrt(s)


def norm(v):
    """Euclidean norm over the first axis of a vector (array or DA of shape (m, ...))."""
    return hypot(*[v[i] for i in range(len(v))])


def dot(a, b):
    """Sum over the first axis of a * b."""
    s = a[0] * b[0]
    for i in range(1, len(a)):
        s = s + a[i] * b[i]
    return s


def vector(items):
    """A right-hand side's value dx/dt from its components: ``stack(items)``, except that
    components which are all Python floats stay the list ``items``.

    Floats only: the rhs was called on lists of Python floats by a single-state float integrator
    (``Dynamics.scalar_components``), which unpacks a list directly; an ndarray built from seven
    floats and turned back into a list cost ~10 % of a solve. ``Dynamics.__call__`` still returns
    an array for callers outside the integrators."""
    if type(items[0]) is float:
        try:
            if type(sum(items)) is float:   # a DA, array or numpy scalar among them: not a float
                return items
        except TypeError:
            pass
    return stack(items)


def stack(items, axis: int = 0):
    """Stack floats, arrays and DA along a new ``axis`` (of the value shape)."""
    if DA not in map(type, items):   # (a C-level scan: 5x cheaper than isinstance per item)
        if axis == 0:   # the same array; np.stack's checks cost ~10x for a few scalars
            return np.array(items)
        return np.stack([np.asarray(x) for x in items], axis=axis)
    ref = next(x for x in items if isinstance(x, DA))
    if axis == 0 and all(type(x) is DA and x.T is ref.T and x.c.shape == ref.c.shape
                         for x in items):   # the common case in dynamics: one call
        # component-major in memory, (m, M, *batch) seen as (M, m, *batch): each component a
        # contiguous block, as the integrators hold states (integrators._Stages)
        return DA(np.stack([x.c for x in items]).swapaxes(0, 1), ref.T)
    coeffs = []
    shape = np.broadcast_shapes(*[(x.shape if isinstance(x, DA) else np.shape(x)) for x in items])
    for x in items:
        if isinstance(x, DA):
            ref._check(x)
            xd = x
        else:
            xd = constant(np.asarray(x, dtype=float), ref.n, ref.order)
        c = np.broadcast_to(xd.c.reshape(xd.c.shape[:1] + (1,) * (len(shape) - xd.ndim) + xd.shape),
                            xd.c.shape[:1] + shape)
        coeffs.append(c)
    ax = axis + 1 if axis >= 0 else axis
    return DA(np.stack(coeffs, axis=ax), ref.T)


def concatenate(items, axis: int = 0):
    """Concatenate arrays / DA along an existing axis of the value shape."""
    das = [x for x in items if isinstance(x, DA)]
    if not das:
        return np.concatenate([np.asarray(x) for x in items], axis=axis)
    ref = das[0]
    cs = [(x if isinstance(x, DA) else constant(x, ref.n, ref.order)).c for x in items]
    ax = axis + 1 if axis >= 0 else axis
    return DA(np.concatenate(cs, axis=ax), ref.T)


def where(mask, a, b):
    """Select ``a`` where ``mask`` (broadcast over the value shape) is true, else ``b``."""
    if not _is_da(a, b):
        return np.where(mask, a, b)
    ref = a if isinstance(a, DA) else b
    ac = a.c if isinstance(a, DA) else constant(a, ref.n, ref.order).c
    bc = b.c if isinstance(b, DA) else constant(b, ref.n, ref.order).c
    return DA(np.where(np.asarray(mask, dtype=bool), ac, bc), ref.T)


def cons(x):
    """Constant part of a DA, or the value itself."""
    return _cons(x)


def _cons(x):
    return x.cons if isinstance(x, DA) else np.asarray(x)
