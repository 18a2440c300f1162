"""Is a solution safe to fly, and does it meet the target? The planner's judgement of every
solve before it may replace the plan in force. ROS-free."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from daddy_core.path_constraints import dense_margin
from daddy_core.problem import Problem, largest
from daddy_core.solver import Solution

from .plan import SATURATION_SLACK


@dataclass
class Assessment:
    """The verdict on one solution.

    Attributes:
        safe: finite and within the thrust and mass bounds (it may be flown).
        feasible: safe and meets the terminal constraints to the solver's tolerance.
        reason: why not (empty when feasible).
        U: (N, nu) the controls as flown: thrust magnitudes over the bound by at most
            SATURATION_SLACK (relative; solver tolerance) saturated onto it -- the engine
            cannot do more anyway.
        X: (N+1, nx) the trajectory of U (None when not safe).
        miss: max terminal-constraint violation of X, at least the solver's DOP853
            re-propagation miss (inf when not safe).
        path_margin: problems with a g_path (keep-out zones): its true minimum margin along
            the DOP853 re-propagation of X's stages (``path_constraints.dense_margin``; < 0:
            violated between the nodes, not safe); None otherwise or when not checked.
    """

    safe: bool
    feasible: bool
    reason: str
    U: np.ndarray
    X: np.ndarray | None = None
    miss: float = np.inf
    path_margin: float | None = None


def assess(sol: Solution, problem: Problem, feasibility_tol: float) -> Assessment:
    """Judge ``sol`` of ``problem`` (the solution itself is not changed)."""
    U = np.array(sol.U, dtype=float)
    if not (np.all(np.isfinite(U)) and np.all(np.isfinite(sol.X))):
        return Assessment(False, False, "solution contains NaN or inf", U)
    umax = problem.u_max
    excess = 0.0
    if umax is not None:
        mags = np.linalg.norm(U, axis=1)
        if np.max(mags) > umax * (1 + SATURATION_SLACK):
            return Assessment(False, False, "solution violates the thrust bound", U)
        over = mags > umax
        U[over] *= (umax / mags[over])[:, None]
        excess = float(np.max(mags / umax)) - 1.0
    if sol.repropagation_miss == np.inf:
        return Assessment(False, False, "solution could not be re-propagated (DOP853)", U)
    # the solver's own trajectory, independently re-propagated (DOP853) by solve(), serves as
    # is; controls changed by the saturation beyond round-off are rolled out again
    if excess > 1e-9 or sol.repropagation_miss is None:
        X, repro = problem.rollout(U), 0.0
    else:
        X, repro = sol.X, sol.repropagation_miss
    if not np.all(np.isfinite(X)):
        return Assessment(False, False, "solution propagates to a non-finite state", U)
    g, ni = problem.path_constraints(X[:-1].T, U.T, problem.stage_dt)
    if g is not None and ni and not np.max(g[:ni]) <= 1e-6:   # (NaN: violated)
        return Assessment(False, False,
                          f"solution violates a path constraint by {np.max(g[:ni]):.2e}", U)
    margin = None
    if problem.g_path is not None:
        # the keep-out holds along the whole flight, not only at the nodes: a plan whose
        # dense re-propagation dips into it is not flown (tolerance: the node-wise one's).
        # The solve's own dense check holds for its trajectory (the path exchange ran it on
        # these X and U); controls changed by the saturation are checked again
        margin = sol.min_path_margin if X is sol.X and sol.min_path_margin is not None \
            else dense_margin(problem, X, U).margin
        if not margin >= -1e-6:   # (NaN: violated)
            return Assessment(False, False, f"solution violates g_path between the nodes by "
                              f"{-margin:.2e} (dense re-propagation)", U, path_margin=margin)
    miss = largest(problem.terminal_violation(X[-1]), repro)
    if not miss <= feasibility_tol:
        return Assessment(True, False, f"terminal constraint missed by {miss:.2e} (normalised)",
                          U, X, miss, margin)
    return Assessment(True, True, "", U, X, miss, margin)
