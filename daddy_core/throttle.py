"""The exact fuel-optimal problem in throttle and direction controls: the end game of a
fuel-optimal solve (``solver.solve``).

Rationale: the paper's homotopy (``fuel``) replaces |u| by a pseudo-Huber cost whose curvature
sits within delta of zero thrust, where DDP and the KKT polishing crawl at thousands of switches
(docs/design-notes.md: exact fuel first). Written with the thrust as

    u = u_max s d(alpha, beta),   0 <= s <= 1 (the throttle),   |d| = 1,

the propellant is linear in s, the thrust bound a simple bound on s, and every function of the
problem is smooth: the KKT polishing (``solver.kkt_polish``: SQP on a working set) meets the
switches as bounds of s entering and leaving its working set. It is the formulation of the
direct transcription behind the reference oracles (T = T_max s d). Its optimum is the true
fuel optimum, which the pseudo-Huber one approaches with a little more propellant.

The direction: d = R (sin beta, cos beta cos alpha, cos beta sin alpha), R a fixed rotation whose
first column -- the pole, where alpha is undetermined -- is the direction the thrust uses
least: the eigenvector of the smallest eigenvalue of sum_k s_k d_k d_k^T over the controls the
form is built from (the radial direction of an Earth-centred transfer in RTN, whose thrust is
transverse and normal). At a coasting stage (s = 0) alpha and beta have no effect on the
dynamics, the costs or the constraints until the stage thrusts again.

What the form needs from a problem: a three-component thrust with a bound (``Problem.u_max``),
a ``fuel.FuelStageCost`` (the propellant as a function of |u|), and dynamics that read the
thrust magnitude as a prepared fourth control component (a ``FlowStep`` of a right-hand side
prepared by ``models.with_thrust_magnitude``, as every low-thrust model here is): the form
hands them |u| = u_max s exactly, where sqrt(|u|^2 + floor^2) would hide the mass flow's
dependence on s at s = 0.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from .da import functions as dm
from .dynamics.models import with_thrust_magnitude
from .fuel import FuelStageCost
from .problem import FlowStep, Problem

LABEL = "throttle >= 0"


@dataclass(frozen=True)
class ThrottleForm:
    """A problem's exact fuel form (module docstring).

    Attributes:
        problem: the fuel-optimal problem over controls V = (s, alpha, beta) (N, 3): the
            original's dynamics, constraints and terminal cost at u = thrust(V), the stage cost
            its ``FuelStageCost.propellant``, and the stage inequalities the original's with
            -s <= 0 appended (row ``throttle_row``).
        u_max: the thrust at s = 1, the original problem's bound.
        frame: (3, 3) rotation R of the direction (columns: the pole, then the axes of alpha =
            0 and alpha = pi / 2 at beta = 0).
        throttle_row: the index of -s <= 0 among a stage's inequality rows.
    """

    problem: Problem
    u_max: float
    frame: np.ndarray
    throttle_row: int

    def controls(self, U: np.ndarray) -> np.ndarray:
        """(N, 3 + k) thrust -> (N, 3 + k) [s, alpha, beta] (alpha = beta = 0 at zero thrust);
        k further columns (a static-parameter problem's increments) pass unchanged."""
        T = U[:, :3]
        norm = np.linalg.norm(T, axis=1)
        local = (T @ self.frame) / np.where(norm > 0, norm, 1.0)[:, None]
        return np.column_stack([norm / self.u_max, np.arctan2(local[:, 2], local[:, 1]),
                                np.arcsin(np.clip(local[:, 0], -1.0, 1.0)), U[:, 3:]])

    def thrust(self, V: np.ndarray) -> np.ndarray:
        """(N, 3 + k) [s, alpha, beta] -> (N, 3 + k) thrust; a throttle below zero (by the
        polishing's tolerance at most) is zero thrust; further columns pass unchanged."""
        return np.column_stack([thrust_of(V[:, :3], self.u_max, self.frame), V[:, 3:]])

    def stage_duals(self, lam: np.ndarray) -> np.ndarray:
        """Stage multipliers in the form's rows (n_c + 1, N) -> the original's (n_c, N)."""
        return np.delete(lam, self.throttle_row, axis=0)

    def _thrust(self, v):
        """[u (3), |u|] from v = [s, alpha, beta] (3, *batch), floats or DA: the prepared
        control the dynamics read (``models.with_thrust_magnitude``'s layout)."""
        if len(v) > 3:        # prepared already
            return v
        return throttle_thrust(v, self.u_max, self.frame)


def throttle_thrust(v, u_max: float, frame: np.ndarray):
    """[u (3), |u|] = u_max s d(alpha, beta) and its magnitude, v = [s, alpha, beta]."""
    us = v[0] * u_max
    cb = dm.cos(v[2])
    d = (dm.sin(v[2]), cb * dm.cos(v[1]), cb * dm.sin(v[1]))
    R = frame
    u = [us * (d[0] * R[i, 0] + d[1] * R[i, 1] + d[2] * R[i, 2]) for i in range(3)]
    return dm.stack(u + [us])


def thrust_of(V: np.ndarray, u_max: float, frame: np.ndarray) -> np.ndarray:
    """(B, 3) [s, alpha, beta] -> (B, 3) thrust (frame (3, 3): ``ThrottleForm.frame``); a
    throttle below zero (by a tolerance at most) is zero thrust."""
    S = np.column_stack([np.maximum(V[:, 0], 0.0), V[:, 1:3]])
    return np.asarray(throttle_thrust(S.T, u_max, frame), float)[:3].T


def intermediate_stages(U: np.ndarray, u_max: float, tol: float = 1e-3) -> int:
    """The number of stages of the thrust U (N, 3) whose throttle |u| / u_max lies strictly
    between tol and 1 - tol: neither coasting nor at the bound (a bang-bang plan has few)."""
    s = np.linalg.norm(U, axis=1) / u_max
    return int(np.sum((s > tol) & (s < 1 - tol)))


def has_throttle_form(problem: Problem) -> bool:
    """``problem`` has what the exact fuel form needs (module docstring); a static-parameter
    problem (``static_parameters``) when the user's problem has."""
    if _parameter_layout(problem) is not None:
        return has_throttle_form(problem.parameters.base)
    step = problem.step
    return bool(problem.nu == 3 and problem.u_max
                and isinstance(problem.stage_cost, FuelStageCost) and isinstance(step, FlowStep)
                and step.rhs.prepare_control is with_thrust_magnitude)


def throttle_form(problem: Problem, U: np.ndarray) -> ThrottleForm | None:
    """The exact fuel form of ``problem`` (module docstring), its frame's pole the direction the
    controls U (N, 3) use least; None when the problem does not have what the form needs."""
    if not has_throttle_form(problem):
        return None
    lay = _parameter_layout(problem)
    if lay is not None:   # the form of the user's problem, augmented as the problem was
        form = throttle_form(lay.base, U[:, :lay.nu])
        return dataclasses.replace(form, problem=lay.rebuild(form.problem))
    step = problem.step
    u_max = float(problem.u_max)
    norm = np.linalg.norm(U, axis=1)
    on = norm > 0
    M = (U[on].T / norm[on]) @ U[on] / u_max          # sum_k s_k d_k d_k^T
    frame = np.linalg.eigh(M)[1] if on.any() else np.eye(3)   # ascending eigenvalues
    n_ineq = 0 if problem.g_ineq is None else _rows(problem, U)
    form = ThrottleForm(problem, u_max, frame, n_ineq)   # (problem replaced below)
    rhs = dataclasses.replace(step.rhs, prepare_control=form._thrust)
    cost = problem.stage_cost

    def thrust(v):
        return form._thrust(v)[:3]

    def stage_cost(x, v, dt, hom=(0.0, 1.0)):
        return cost.propellant(x, form._thrust(v)[3], dt)

    def g_ineq(x, v, dt):
        own = dm.stack([-v[0]])
        if problem.g_ineq is None:
            return own
        return dm.concatenate([problem.g_ineq(x, thrust(v), dt), own])

    labels = dict(problem.labels)
    labels["g_ineq"] = tuple(labels.get("g_ineq", ("",) * n_ineq))[:n_ineq] + (LABEL,)
    fuel = dataclasses.replace(
        problem, step=FlowStep(rhs, step.integrator, step.tol, step.rk4_steps,
                               step.derivative_tol),
        rhs=rhs, stage_cost=stage_cost, g_ineq=g_ineq,
        g_eq=problem.g_eq and (lambda x, v, dt: problem.g_eq(x, thrust(v), dt)),
        g_path=problem.g_path and (lambda x, v: problem.g_path(x, thrust(v))),
        u_max=None, labels=labels)
    return dataclasses.replace(form, problem=fuel)


def _parameter_layout(problem: Problem):
    """A static-parameter problem's ``ParameterLayout`` when it can rebuild its augmentation
    around another form of the user's problem, else None."""
    lay = problem.parameters
    return lay if lay is not None and lay.base is not None else None


def _rows(problem: Problem, U: np.ndarray) -> int:
    """The number of rows of ``problem.g_ineq`` (evaluated at the first stage)."""
    g = problem.g_ineq(problem.x0[:, None], U[:1].T, problem.stage_dt[:1])
    return int(np.shape(g)[0])
