"""The terminal multipliers as variables of the backward sweep (``MultiplierUpdate.SWEEP``):
HDDP's treatment (Lantoine & Russell; the DA-HDDP paper, sec. II), in which each DDP iteration
moves the multipliers of the terminal equalities psi as well as the controls.

The cost-to-go is carried in y = [dx, dl] (dl: the multipliers' change), starting from the
augmented terminal cost and the multipliers' own term dl^T psi:

    V_N(dx, dl) = phi~(x_N + dx) + dl^T psi(x_N + dx)
    Q_k(dx, du, dl) = L~_k(dx, du) + V_k+1(f_z [dx; du], dl)         (Gauss-Newton, eq. 3)
    du*(dx, dl) = -Q_uu^-1 (Q_u + Q_ux dx + Q_ul dl)
    V_k(dx, dl) = Q_k(dx, du*(dx, dl), dl)

At the first stage (dx = 0), V_0(0, dl) = V_l dl + dl^T V_ll dl / 2 is concave in dl (V_ll =
-sum Q_lu Q_uu^-1 Q_ul), and the multipliers step to its maximum, dl* = -V_ll^-1 V_l: the dual
ascent step on the quadratic model. The DDP iteration then sweeps and steps the controls at the
new multipliers. On a problem with linear dynamics and terminal equalities and a quadratic cost
the model is exact: dl* gives the optimal multipliers, the controls' step at them is the
optimum, and DDP ends after one step (the DA-HDDP paper's LQ test, sec. IV.A).

Only the terminal equalities are swept; path constraints and terminal inequalities keep the
AUL's update (eq. 9). A sweep that cannot be formed (Q_uu not positive definite at the
iteration's rho) or whose V_ll is not negative definite (the controls cannot move every
terminal row), or is too ill-conditioned for six digits (``da.calculus.SIX_DIGITS_CONDITION``, the
feedback laws' rule), leaves the multipliers where they are.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .. import da
from ..errors import DaddyError
from ..da.calculus import SIX_DIGITS_CONDITION
from .linalg import regularised_inverse
from .sweeps import Stages, _bordered


def terminal_rows(st: Stages) -> tuple[np.ndarray, np.ndarray] | None:
    """psi (nl,) and psi_x (nl, nx) of the terminal equalities at st's final state, or None
    when the problem has none."""
    p, n_tineq = st.problem, st.mult.n_tineq
    gt, _ = p.terminal_constraints(da.variables(st.X[-1], order=2))
    if gt is None or gt.shape[0] <= n_tineq:
        return None
    gt = gt[n_tineq:]
    return np.asarray(gt.cons, dtype=float), gt.gradient()


def multiplier_step(st: Stages, rho: float) -> np.ndarray | None:
    """dl* (nl,) of the terminal equalities (module docstring), or None where the sweep cannot
    give one."""
    rows = terminal_rows(st)
    if rows is None:
        return None
    psi, psi_x = rows
    p = st.problem
    nx, nu, N, nl = p.nx, p.nu, p.N, psi.size
    n = nx + nu
    ny, nw = nx + nl, n + nl
    fz = np.moveaxis(st.F.gradient(), 1, 0)                 # (N, nx, n)
    # V_N in y = [dx, dl], bordered (ny + 1)
    grad = np.concatenate([st.phix, psi])
    hess = np.zeros((ny, ny))
    hess[:nx, :nx] = st.phixx
    hess[nx:, :nx] = psi_x
    hess[:nx, nx:] = psi_x.T
    Vb = _bordered(grad, hess)
    # the stage cost and the stage map in w = [dx, du, dl], bordered (nw + 1)
    L = np.zeros((nw + 1, nw + 1))
    Jb = np.zeros((ny + 1, nw + 1))
    Jb[nx:ny, n:nw] = np.eye(nl)
    Jb[ny, nw] = 1.0
    G = np.zeros((nw + 1, ny + 1))                           # [dx, dl, 1] -> [dx, du, dl, 1]
    G[:nx, :nx] = np.eye(nx)
    G[n:nw, nx:ny] = np.eye(nl)
    G[nw, ny] = 1.0
    keep = np.r_[0:nx, n:nw, nw]                             # Q's columns of y and the border
    with np.errstate(over="ignore", invalid="ignore"):
        for k in range(N - 1, -1, -1):
            L[:n, :n] = st.lzz[k]
            L[:n, nw] = L[nw, :n] = st.lz[k]
            Jb[:nx, :n] = fz[k]
            Q = L + Jb.T @ Vb @ Jb
            Minv = regularised_inverse(Q[nx:n, nx:n], rho)
            if Minv is None:
                return None
            G[nx:n, :] = -(Minv @ Q[nx:n, keep])
            Vb = G.T @ Q @ G
            Vb = 0.5 * (Vb + Vb.T)
        V_ll, V_l = Vb[nx:ny, nx:ny], Vb[nx:ny, ny]
    if not (np.all(np.isfinite(V_ll)) and np.all(np.isfinite(V_l))):
        return None
    w = np.linalg.eigvalsh(V_ll)
    if not (w[-1] < 0.0 and w[0] / w[-1] <= SIX_DIGITS_CONDITION):
        return None
    return -np.linalg.solve(V_ll, V_l)


def swept(st: Stages, rho: float, lambda_max: float) -> Stages:
    """``st`` with its terminal equalities' multipliers moved by ``multiplier_step`` (clipped to
    lambda_max), its costs re-expanded for them; ``st`` itself where there is no step."""
    try:
        step = multiplier_step(st, rho)
    except (DaddyError, ArithmeticError, np.linalg.LinAlgError):
        return st
    if step is None or not np.all(np.isfinite(step)):
        return st
    mult = st.mult
    lam_t = mult.lam_t.copy()
    lam_t[mult.n_tineq:] = np.clip(lam_t[mult.n_tineq:] + step, -lambda_max, lambda_max)
    return st.with_costs(replace(mult, lam_t=lam_t), st.hom)
