"""What a relative cost test is relative to: the part of the cost the controls can change.

DDP's tests -- converged when a step lowers the cost by less than ``ddp.tol`` of it, nothing to
gain when the full step is predicted to gain less, the crawl stop, the line search's and the
trust region's "small step" -- compare a decrease with the cost. Relative to |J| itself, a
constant in the cost (a user's J + 1e3; a sail's J = -E with E ~ -0.5 whose controls move it by
1e-4) makes every decrease look small: the solve stopped 43 m short of a 204 km energy gain
with ``converged=True``. The tests are relative to

    scale(J) = min(|J|, |J - anchor|),   anchor = sum_k l_k(x_0, 0) + phi(x_0)

instead: ``anchor`` is the problem's own cost (no multiplier terms) with the initial state at
every node and no control -- a reference point that carries every constant of the stage and
terminal costs, so J + c and J have the same scale (|J - anchor|) and take the same steps. The
smaller of the two distances is taken, so no test is looser than relative to |J|: for the
catalogue's costs (energy or fuel, zero at zero control, and a terminal-miss penalty largest at
x_0) it is |J| and nothing changes; a least-violation cost stays relative to the miss left, not
to the miss removed; a landing that maximises the final mass is relative to the propellant
spent, J = -E to the energy gained. The scale never falls below round-off of the cost itself
(``ROUND_OFF`` |J|): a decrease smaller than that cannot be measured.
"""
from __future__ import annotations

import math

import numpy as np

from ..problem import Problem

ROUND_OFF = 1e-12   # relative resolution of a cost sum, below which decreases are noise


def anchor(problem: Problem, hom) -> float:
    """The problem's cost with x_0 at every node and zero control (module docstring); 0 when
    it is not finite there (the tests are then relative to |J|, as a cost without constants)."""
    p = problem
    x = np.repeat(np.asarray(p.x0, float)[:, None], p.N, axis=1)
    with np.errstate(all="ignore"):
        value = float(np.sum(np.asarray(p.stage_cost(x, np.zeros((p.nu, p.N)), p.stage_dt, hom),
                                        dtype=float))
                      + float(p.terminal_cost(np.asarray(p.x0, float), p.x_target)))
    return value if math.isfinite(value) else 0.0


def scale(cost: float, anchor_value: float) -> float:
    """The size of ``cost`` a relative test divides by: the smaller of |cost| and
    |cost - anchor|, at least the cost's round-off (and never 0)."""
    return max(min(abs(cost), abs(cost - anchor_value)), ROUND_OFF * abs(cost), 1e-300)
