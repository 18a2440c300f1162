"""Differential dynamic programming with DA expansions (paper section III.A).

Backward sweeps: Std (Alg. 7, no dynamics Hessians), Hess (Alg. 9, with them) and Q (Alg. 10,
Q_k built by composing the cost-to-go polynomial with the stage map). Forward passes: Std
(Alg. 6, integrate every stage, then re-expand all maps in one batch) and Dyn (Alg. 8, evaluate
the stored map when the deviation is inside its convergence radius, integrate otherwise; then
re-expand only the integrated stages in one batch and re-centre the others by one batched
composition). The loop is Alg. 3 with a backtracking line search (and a trust region per
stage where the stage cost's own model fails) and Quu regularisation.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from .. import da
from ..errors import DaddyError
from ..problem import Problem
from .lagrangian import (Multipliers, augmented_cost_terms,
                         augmented_stage_cost, augmented_terminal_cost)
from .options import Globalization, Method, SolverOptions, Sweep
from .results import Status, StepResult
from .stage_maps import expand_dynamics, maps_at

# a line search's failure is local (``_blamed_stages``) when it sits at no more than this
# share of the stages; beyond it, one shorter step for every stage is the answer
_LOCAL_FRACTION = 0.1


@dataclass
class DDPStats:
    """Counters and timings accumulated over DDP solves."""

    iterations: int = 0
    forward_s: float = 0.0
    expansion_s: float = 0.0
    backward_s: float = 0.0
    stages_total: int = 0
    stages_polynomial: int = 0

    @property
    def polynomial_share(self) -> float:
        return self.stages_polynomial / self.stages_total if self.stages_total else 0.0


@dataclass
class Gains:
    """Feedback law u = u_k + alpha a_k + b_k dx_k from a backward sweep (eq. 4-5).

    a: (N, nu); b: (N, nu, nx); dv1 = sum a.Q_u; dv2 = sum a.Q_uu.a / 2 (expected change:
    alpha dv1 + alpha^2 dv2).
    """

    a: np.ndarray
    b: np.ndarray
    dv1: float
    dv2: float
    clipped: int = 0   # stages whose step the trust region cut to its boundary
    shortest: float = 1.0   # the smallest radius / unbounded step over the clipped stages


# --------------------------------------------------------------------------- quadratic model
class Stages:
    """The expansions of one nominal trajectory (X, U) for the current multipliers.

    Attributes:
        X: (N+1, nx), U: (N, nu) nominal.
        F: DA (nx, N): second-order stage maps in z = [dx, du].
        radius: (N,) convergence radii of F at accuracy eps_da.
        walked: (N,) how far each map has been re-centred since it was expanded (the sum of
            the Dyn pass's deviations |dz_k| over the steps it served the stage; 0 after an
            expansion): where it exceeds the radius, the map may have drifted
            (``aul._without_drift``).
        l: (N,), lz: (N, n), lzz: (N, n, n): the augmented stage cost and its derivatives.
        phix: (nx,), phixx: (nx, nx): derivatives of the augmented terminal cost.
        cost: augmented cost J of the nominal.
    """

    def __init__(self, problem: Problem, X, U, mult: Multipliers, hom, eps_da: float, F=None,
                 walked: np.ndarray | None = None):
        self.problem = problem
        self.X = np.asarray(X, dtype=float)
        self.U = np.asarray(U, dtype=float)
        self.mult = mult
        self.hom = hom
        self.eps_da = eps_da
        self.F = F if F is not None else expand_dynamics(problem, self.X[:-1], self.U)
        self.radius = da.radius(self.F, eps_da)
        self.walked = np.zeros(self.U.shape[0]) if walked is None else walked
        self._map_rows = None
        self._expand_costs()

    @property
    def n(self) -> int:
        return self.problem.nx + self.problem.nu

    def with_costs(self, mult: Multipliers, hom) -> "Stages":
        """The same nominal and maps for other multipliers or another homotopy step."""
        return Stages(self.problem, self.X, self.U, mult, hom, self.eps_da, F=self.F,
                      walked=self.walked)

    def map_rows(self) -> np.ndarray:
        """(N, nx, M) the stage maps' coefficients, stage by stage contiguous: x_k+1 =
        map_rows()[k] @ monomials(z) (the forward pass's Dyn evaluation). Built once per
        nominal, shared by the line search's trials."""
        if self._map_rows is None:
            self._map_rows = np.ascontiguousarray(self.F.c.transpose(2, 1, 0))
        return self._map_rows

    def _expand_costs(self):
        p = self.problem
        z = da.variables(np.concatenate([self.X[:-1].T, self.U.T]), order=2)
        lt = augmented_stage_cost(p, z[:p.nx], z[p.nx:], self.mult, self.hom)
        if not isinstance(lt, da.DA):  # a cost without any dependence on (x, u)
            lt = da.constant(lt, self.n) + z[0] * 0.0
        self.l = np.asarray(lt.cons, dtype=float)
        self.lz = lt.gradient()
        self.lzz = lt.hessian()
        phi = augmented_terminal_cost(p, da.variables(self.X[-1], order=2), self.mult)
        self.phix = phi.gradient()
        self.phixx = phi.hessian()
        self.cost = float(np.sum(lt.cons) + phi.cons)


# ---------------------------------------------------------------------------- backward sweeps
def _quadratic_da(grad: np.ndarray, hess: np.ndarray) -> da.DA:
    """The DA of v(dx) = grad.dx + dx^T hess dx / 2 (zero constant part)."""
    n = grad.size
    T = da.tables(n, 2)
    c = np.zeros(T.size)
    c[1:n + 1] = grad
    q = hess[T.triu_i, T.triu_j].copy()
    q[~T.offdiag] *= 0.5
    c[n + 1:] = q
    return da.DA(c, T)


def _feedback_map(ak: np.ndarray, bk: np.ndarray) -> da.DA:
    """The map dx -> [dx, a_k + b_k dx] as a DA of shape (nx + nu,) in nx variables."""
    nu, nx = bk.shape
    T = da.tables(nx, 2)
    c = np.zeros((T.size, nx + nu))
    c[1 + np.arange(nx), np.arange(nx)] = 1.0
    c[0, nx:] = ak
    c[1:nx + 1, nx:] = bk.T
    return da.DA(c, T)


def _regularised_inverse(Quu: np.ndarray, rho: float) -> np.ndarray | None:
    """(Quu + rho I)^-1 from its Cholesky factor L (M^-1 = L^-T L^-1), or None when Quu + rho I
    is not positive definite (or not finite). Plain Python on the nu x nu entries (the lower
    triangle is read): for nu x nu blocks numpy's cholesky + solve cost more in call overhead
    than the arithmetic, and the 3 x 3 case (a thrust vector) is unrolled."""
    if Quu.shape == (3, 3):
        return _regularised_inverse_3(Quu, rho)
    A = Quu.tolist()
    n = len(A)
    L = [[0.0] * n for _ in range(n)]
    for i in range(n):
        Li = L[i]
        for j in range(i + 1):
            Lj = L[j]
            t = 0.0   # (explicit loops: a generator sum() per entry cost 40 % more)
            for m in range(j):
                t += Li[m] * Lj[m]
            s = A[i][j] - t
            if i == j:
                s += rho
                if not (s > 0.0 and math.isfinite(s)):
                    return None
                Li[i] = math.sqrt(s)
            else:
                Li[j] = s / Lj[j]
    inv = [[0.0] * n for _ in range(n)]   # L^-1, lower triangular
    for i in range(n):
        Li, d = L[i], 1.0 / L[i][i]
        inv[i][i] = d
        for j in range(i):
            t = 0.0
            for m in range(j, i):
                t += Li[m] * inv[m][j]
            inv[i][j] = -t * d
    Linv = np.array(inv)
    return Linv.T @ Linv


def _regularised_inverse_3(Quu: np.ndarray, rho: float) -> np.ndarray | None:
    """``_regularised_inverse`` for a 3 x 3 Quu (a thrust vector), unrolled: the same L and
    L^-1 operations; M^-1 = L^-T L^-1 summed in Python instead of numpy's matmul."""
    (a00, _, _), (a10, a11, _), (a20, a21, a22) = Quu.tolist()
    s0 = a00 + rho
    if not (s0 > 0.0 and math.isfinite(s0)):
        return None
    l00 = math.sqrt(s0)
    l10, l20 = a10 / l00, a20 / l00
    s1 = a11 - l10 * l10 + rho
    if not (s1 > 0.0 and math.isfinite(s1)):
        return None
    l11 = math.sqrt(s1)
    l21 = (a21 - l20 * l10) / l11
    s2 = a22 - (l20 * l20 + l21 * l21) + rho
    if not (s2 > 0.0 and math.isfinite(s2)):
        return None
    i00, i11, i22 = 1.0 / l00, 1.0 / l11, 1.0 / math.sqrt(s2)   # L^-1, lower triangular
    i10 = -(l10 * i00) * i11
    i21 = -(l21 * i11) * i22
    i20 = -(l20 * i00 + l21 * i10) * i22
    m01, m02, m12 = i10 * i11 + i20 * i21, i20 * i22, i21 * i22
    return np.array([[i00 * i00 + i10 * i10 + i20 * i20, m01, m02],
                     [m01, i11 * i11 + i21 * i21, m12],
                     [m02, m12, i22 * i22]])


def _trust_region_inverse(Quu: np.ndarray, Qu: np.ndarray, rho: float,
                          radius: float) -> np.ndarray:
    """(Quu + lam I)^-1 with the shift lam >= rho that puts the step -(Quu + lam I)^-1 Qu on the
    trust-region boundary |a| = radius (the trust-region subproblem min Qu.a + a.Quu.a / 2,
    |a| <= radius, of HDDP and the many-revolution DDP paper's section III.F; Quu + rho I is
    positive definite and its step is outside the region). The shift solves the secular
    equation 1/|a(lam)| = 1/radius by Newton's method (Conn, Gould & Toint Alg. 7.3.4's
    iteration; nearly linear in lam, so a few iterations reach 1e-3 of the radius): unlike
    a rescaled Newton step it turns the step towards the gradient where Quu is ill-conditioned,
    and the feedback gains b_k use the same shifted Hessian."""
    if not radius > 0.0:   # no step at all: (Quu + inf I)^-1 (the test that stops DDP follows)
        return np.zeros_like(Quu)
    w, V = np.linalg.eigh(Quu)
    g = V.T @ Qu
    lam = rho
    for _ in range(30):
        d = w + lam
        s2 = float(np.sum((g / d) ** 2))
        s = math.sqrt(s2)
        if s <= radius * (1.0 + 1e-3):
            break
        ds = -float(np.sum(g * g / d ** 3)) / s           # d|a|/d lam
        if not ds < 0.0:   # underflow (a radius near round-off): the ratio test rejects it
            break
        lam -= (1.0 / radius - 1.0 / s) * s2 / ds
    return (V / (w + lam)) @ V.T


def _bordered(grad: np.ndarray, hess: np.ndarray) -> np.ndarray:
    """[[hess, grad], [grad^T, 0]] (..., m+1, m+1): the quadratic v(d) = grad.d + d^T hess d / 2
    as one symmetric matrix, (d, 1)^T B (d, 1) = 2 v(d). Compositions of such quadratics with
    affine maps are then single matrix products (one numpy call instead of several per stage)."""
    m = grad.shape[-1]
    B = np.zeros(grad.shape[:-1] + (m + 1, m + 1))
    B[..., :m, :m] = hess
    B[..., :m, m] = grad
    B[..., m, :m] = grad
    return B


def _stage_q(st: Stages, k: int, Lk, Jbk, Vb, sweep: Sweep, fzz):
    """Q_k of stage k as bordered matrices: (Gauss-Newton Q, the sweep's Q) -- the same object
    for Std."""
    nx, n = st.problem.nx, st.n
    Qb_gn = Lk + Jbk.T @ Vb @ Jbk                          # eq. 3 without dynamics Hessians
    if sweep is Sweep.Q:
        # Alg. 10: P_Q = P_l + P_V(P_f - x_{k+1}); derivatives read from its coefficients
        pq = da.compose(_quadratic_da(Vb[:nx, nx], Vb[:nx, :nx]), st.F[:, k] - st.X[k + 1])
        return Qb_gn, Lk + _bordered(pq.gradient(), pq.hessian())
    if fzz is not None:                                     # Alg. 9: + sum_i V_x^i f^i_zz
        Qb = Qb_gn.copy()
        Qb[:n, :n] += np.tensordot(Vb[:nx, nx], fzz[k], axes=(0, 0))
        return Qb_gn, Qb
    return Qb_gn, Qb_gn


def backward_sweep(st: Stages, sweep: Sweep, rho: float,
                   radius: float | np.ndarray = math.inf) -> Gains | None:
    """One backward sweep; returns None when Q_uu + rho I is not positive definite. radius: the
    trust region of each stage's step |a_k| (``_trust_region_inverse``; inf: none), one for
    all stages or (N,) one per stage.

    Cost-to-go and Q are carried as bordered matrices (``_bordered``): V_k = [[V_xx, V_x],
    [V_x^T, .]] (nx+1), Q_k = [[Q_zz, Q_z], [Q_z^T, .]] (n+1), z = [dx, du]. Then eq. 3 (without
    dynamics Hessians) is Q_k = L_k + Jb^T V_k+1 Jb with Jb = diag(f_z, 1), and the cost-to-go
    of the feedback du = a + b dx (eq. 4-5) is V_k = G^T Q_k G with G = [[I, 0], [b, a], [0, 1]]:
    the same V_x, V_xx as the textbook expansion, in a handful of numpy calls per stage.
    """
    p = st.problem
    nx, nu, N = p.nx, p.nu, p.N
    n = nx + nu
    fz = np.moveaxis(st.F.gradient(), 1, 0)  # (N, nx, n)
    fzz = np.moveaxis(st.F.hessian(), 1, 0) if sweep is Sweep.HESS else None
    L = _bordered(st.lz, st.lzz)                           # (N, n+1, n+1)
    Jb = np.zeros((N, nx + 1, n + 1))
    Jb[:, :nx, :n] = fz
    Jb[:, nx, n] = 1.0
    Vb = _bordered(st.phix, st.phixx)
    G = np.zeros((n + 1, nx + 1))
    G[:nx, :nx] = np.eye(nx)
    G[n, nx] = 1.0
    K = np.empty((N, nu, n + 1))    # Minv [Q_ux, Q_uu, Q_u] = -[b_k, ., a_k] of every stage
    Qu_rows = np.empty((N, nu, n + 1))   # [Q_ux, Q_uu, Q_u] of every stage, for dv1, dv2
    clipped, shortest = 0, 1.0
    radii = np.broadcast_to(np.asarray(radius, dtype=float), (N,)).tolist()
    for k in range(N - 1, -1, -1):
        radius = radii[k]
        Qb_gn, Qb = _stage_q(st, k, L[k], Jb[k], Vb, sweep, fzz)
        Minv = _regularised_inverse(Qb[nx:n, nx:n], rho)
        if Minv is None and Qb is not Qb_gn:
            # the dynamics-Hessian terms make Q_uu indefinite at this stage (e.g. the mass-flow
            # term |u| near zero thrust): use the Gauss-Newton Q of this stage instead
            Qb = Qb_gn
            Minv = _regularised_inverse(Qb[nx:n, nx:n], rho)
        if Minv is None:
            return None
        Qu_rows[k] = Qb[nx:n]
        Kk = np.matmul(Minv, Qb[nx:n], out=K[k])   # eq. 4-5: a_k = -Kk[:, n], b_k = -Kk[:, :nx]
        if radius < math.inf and (full := math.sqrt(Kk[:, n] @ Kk[:, n])) > radius:
            Minv = _trust_region_inverse(Qb[nx:n, nx:n], Qb[nx:n, n], rho, radius)
            np.matmul(Minv, Qb[nx:n], out=Kk)
            clipped += 1
            shortest = min(shortest, radius / full)
        if sweep is Sweep.Q:
            # Alg. 10: P_V,k = P_Q,k(dx, a_k + b_k dx)
            pv = da.compose(_quadratic_da(Qb[:n, n], Qb[:n, :n]),
                            _feedback_map(-Kk[:, n], -Kk[:, :nx]))
            Vb = _bordered(pv.gradient(), pv.hessian())
        else:
            np.negative(Kk[:, :nx], out=G[nx:n, :nx])
            np.negative(Kk[:, n], out=G[nx:n, nx])
            Vb = G.T @ Qb @ G
            Vb = Vb + Vb.T
            Vb *= 0.5
            Vb[nx, nx] = 0.0   # the constant (expected change) is not carried: dv1, dv2
    a, b = -K[:, :, n], -K[:, :, :nx]
    Qu, Quu = Qu_rows[:, :, n], Qu_rows[:, :, nx:n]
    dv1 = np.einsum("ki,ki->", a, Qu)                       # sum_k a_k . Q_u,k
    dv2 = 0.5 * np.einsum("ki,ki->", a, np.einsum("kij,kj->ki", Quu, a))   # sum a.Q_uu.a / 2
    return Gains(a, b, float(dv1), float(dv2), clipped, shortest)


# ----------------------------------------------------------------------------- forward passes
@dataclass
class Blame:
    """A line search's first trial failed, and the stage cost's own quadratic model failed at a
    few stages enough to explain it: those stages (indices (m,)) and the bounds (m,) their
    control changes |du_k| get (half of the trial's)."""

    stages: np.ndarray
    bounds: np.ndarray


@dataclass
class Trial:
    """One forward pass (a candidate nominal).

    Attributes:
        X: (N+1, nx), U: (N, nu) the new trajectory; poly: (N,) bool, stage propagated by its
        stored map; dz: (n, N) the stage deviations [dx; du] from the nominal; ok: every state
        finite and every mass positive (a stage that fails either ends the pass: thrust / mass
        has no meaning beyond, and a trajectory whose mass went negative does not recover);
        alpha: its step length; cost: its augmented cost (set by the line search).
    """

    X: np.ndarray
    U: np.ndarray
    poly: np.ndarray
    dz: np.ndarray
    ok: bool
    alpha: float
    cost: float = math.nan


def forward_pass(st: Stages, gains: Gains, alpha: float, dyn: bool,
                 clamp: np.ndarray | None = None) -> Trial:
    """Roll the feedback law out for step length alpha (Alg. 6 / Alg. 8): stage k is served by
    its stored map where [dx; du] lies inside the map's radius (Dyn, eq. 11), else integrated.
    clamp: (N,) per-stage bounds on |du_k| (feedforward and feedback together; the line
    search's per-stage trust region): a longer du_k is scaled back onto it, as control-limited
    DDP clamps its controls in the forward pass.

    The loop is sequential (x_k+1 depends on x_k) over arrays of a few elements, where each numpy
    call costs more than its arithmetic: every step writes into preallocated rows (``out=``), the
    maps are read from per-stage contiguous rows (``Stages.map_rows``), and a stage is checked by
    its mass only (NaN or <= 0 ends the pass; a NaN elsewhere reaches the next stage's
    integration, which raises, or the final check)."""
    p = st.problem
    N, nx = p.N, p.nx
    X = np.empty((N + 1, nx))
    U = np.empty((N, p.nu))
    X[0] = p.x0
    poly = np.zeros(N, dtype=bool)
    Z = np.zeros((N, st.n))                 # row k: [dx; du] of stage k
    Xn, Un, b = st.X, st.U, gains.b
    aa = alpha * gains.a
    im = p.mass_index
    radius = st.radius if dyn else None
    quad = st.F.T.k == 2
    rows = st.map_rows() if dyn else None
    mv = np.empty(st.F.T.size)
    mv[0] = 1.0
    n1, outer_a = st.n + 1, st.F.T.outer_a
    bound = None if clamp is None else clamp.tolist()
    for k in range(N):
        z = Z[k]
        zx, zu = z[:nx], z[nx:]
        np.subtract(X[k], Xn[k], out=zx)
        np.matmul(b[k], zx, out=zu)
        zu += aa[k]
        if bound is not None and bound[k] < math.inf:
            size = math.sqrt(zu @ zu)
            if size > bound[k]:
                zu *= bound[k] / size
        np.add(Un[k], zu, out=U[k])
        if dyn and math.sqrt(z @ z) < radius[k]:                   # eq. 11, first case
            if quad:
                mv[1:n1] = z
                np.take(np.multiply.outer(z, z), outer_a, out=mv[n1:])
            else:
                mv = da.monomial_values(z, st.F.T)
            np.matmul(rows[k], mv, out=X[k + 1])
            poly[k] = True
        else:
            try:
                X[k + 1] = p.stage_flow(X[k], U[k], k)
            except (DaddyError, ArithmeticError):   # incl. 1 / 0 on Python floats
                return Trial(X, U, poly, Z.T, False, alpha)
        if im is not None and not X[k + 1, im] > 0.0:
            return Trial(X, U, poly, Z.T, False, alpha)
    return Trial(X, U, poly, Z.T, bool(np.isfinite(X).all()), alpha)


def new_maps(st: Stages, trial: Trial, dyn: bool) -> da.DA:
    """Stage maps at the new nominal: one batched expansion of the integrated stages and one
    batched re-centring (composition) of the stages served by their polynomial. The forward
    pass integrated X[k+1] from (X[k], U[k]) wherever stage k is re-expanded: those flows are
    the expansions' constant parts (not integrated twice)."""
    X, U = trial.X, trial.U
    if not dyn:
        return expand_dynamics(st.problem, X[:-1], U, values=X[1:].T)
    return maps_at(st.problem, st.F, trial.dz, trial.poly, X, U, values=X[1:].T)


# ----------------------------------------------------------------------------------- the loop
@dataclass
class DDPResult(StepResult):
    stages: Stages
    rho: float
    gains: Gains | None  # of the last backward sweep
    radius: float = math.inf   # trust-region radius at the end (Globalization.TRUST_REGION)


def _raise_rho(rho: float, opts: SolverOptions, growth: float | None = None) -> float:
    """rho times ``growth`` (default opts.rho_factor), at least opts.rho_min."""
    return max(rho * (opts.rho_factor if growth is None else growth), opts.rho_min)


def _lower_rho(rho: float, opts: SolverOptions) -> float:
    r = rho / opts.rho_factor
    return r if r >= opts.rho_min else 0.0


def _rho_after_step(rho: float, alpha: float, opts: SolverOptions) -> float:
    """Lower rho after an accepted step, unless it was shortened below opts.short_step: then
    the quadratic model promised far more than the step delivered (e.g. controls in the linear
    part of the pseudo-Huber cost, whose tiny curvature asks for huge steps), and rho is raised,
    Levenberg-Marquardt-like, rather than crawl on with tiny alphas."""
    if alpha < opts.short_step:
        return _raise_rho(rho, opts, opts.short_step_rho_growth)
    return _lower_rho(rho, opts)


def _predicted_stop(st: Stages, full_step_gain: float, it: int, opts: SolverOptions) -> bool:
    """SolverOptions.ddp_stop_on_prediction: converged before any step when the full step's
    predicted relative decrease is small and the constraints are met to tol_aul (else the small
    steps are how the augmented Lagrangian makes progress)."""
    return (opts.ddp_stop_on_prediction and it >= opts.ddp_min_iter
            and 0.0 <= full_step_gain < opts.ddp_predicted_stop_fraction * opts.tol_ddp
            and st.problem.violation(st.X, st.U) <= opts.tol_aul)


def _sweep(st: Stages, sweep: Sweep, rho: float, stats: DDPStats,
           radius: float | np.ndarray = math.inf) -> Gains | None:
    """A backward sweep; far from the optimum the dynamics-Hessian terms can make Q_uu
    indefinite through V_xx, and the Gauss-Newton (Std) sweep at the same rho is taken
    instead."""
    t0 = time.perf_counter()
    # a diverging iterate overflows Q to inf / nan: the regularised inverse rejects it (rho is
    # raised), so numpy's warnings would only be noise on the user's terminal
    with np.errstate(over="ignore", invalid="ignore"):
        gains = backward_sweep(st, sweep, rho, radius)
        if gains is None and sweep is not Sweep.STD:
            gains = backward_sweep(st, Sweep.STD, rho, radius)
    stats.backward_s += time.perf_counter() - t0
    return gains


def _accepted(expected: float, actual: float, J: float, Jn: float, lo: float, hi: float) -> bool:
    """A step whose actual / expected decrease lies in (lo, hi), or that decreases the cost
    where the expected decrease is round-off."""
    return bool(np.isfinite(Jn)) and (
        (expected > 0 and lo < actual / expected < hi)
        or (expected <= 1e-15 * max(1.0, abs(J)) and actual >= 0))


def _blamed_stages(st: Stages, trial: Trial, stage_costs: np.ndarray, expected: float,
                   actual: float, tol: float, worth: float | None = None) -> np.ndarray:
    """The stages whose stage-cost model failed on ``trial`` (its augmented stage costs
    ``stage_costs`` (N,)) enough to explain why it was rejected, (m,) indices (empty: the
    failure is not local).

    The quadratic model of stage k's augmented cost, at the trial's actual deviation dz_k,
    predicts l_z dz + dz l_zz dz / 2; where the true change exceeds that by more than a tenth
    of the whole step's expected decrease (or of the gap expected - actual, if smaller), the
    stage is blamed -- when the blamed stages together explain half the gap (a tenth of the
    gap alone blamed one stage per sweep where a step crossed a bound at dozens: the worst
    stage sets the gap). Both non-smooth parts of a low-thrust stage cost fail this way at
    single stages: the penalty of a thrust bound that the step crosses (inactive, with no
    curvature in the model, on one side; mu g^2 / 2 on the other; measured on a MEO transfer:
    one stage of 1199 with a model error of 4.6e-4 against a predicted decrease of 7e-7), and
    the pseudo-Huber cost's kink at zero thrust, whose model holds within ~delta.

    Not blamed (the failure is not local, and one shorter step for every stage is the answer):
    more than ``_LOCAL_FRACTION`` of the stages (a cold start that crosses the thrust bound
    along much of the transfer: bounds kept from such a blame would shape the sweeps of every
    later iteration), or a step whose ``worth`` (default: its whole expected decrease) is below
    ``tol`` (DDP's tol_ddp) relative to the cost (its gap is round-off, and a bound halved on
    round-off again and again takes as many accepted steps to regrow, keeping DDP from its
    stopping test)."""
    p = st.problem
    gap = expected - actual
    worth = expected if worth is None else worth
    if not (gap > 0 and math.isfinite(gap)) or worth < tol * abs(st.cost):
        return np.empty(0, dtype=int)
    dz = trial.dz.T                                              # (N, n)
    change = stage_costs - st.l
    model = (np.einsum("ki,ki->k", st.lz, dz)
             + 0.5 * np.einsum("ki,kij,kj->k", dz, st.lzz, dz))
    err = change - model
    bad = np.flatnonzero(err > 0.1 * min(gap, expected))
    if bad.size == 0 or bad.size > _LOCAL_FRACTION * p.N or err[bad].sum() < 0.5 * gap:
        return np.empty(0, dtype=int)
    return bad


def _line_search(st: Stages, gains: Gains, a0: float, dyn: bool, opts: SolverOptions,
                 J: float, clamp: np.ndarray | None = None) -> Trial | Blame | None:
    """Backtracking from step a0 (one step length at a time): the first step whose actual /
    expected decrease lies in (ls_min_ratio, ls_max_ratio), or that decreases the cost where
    the expected decrease is round-off. Returns that trial (with its cost), or -- when the
    first trial fails at a few stages (``_blamed_stages``, with ``opts.stage_trust``) -- those
    stages and their new bounds, or None.

    One step length scales every stage: a model failing at one stage of thousands (a thrust
    bound crossed, a coasting stage pushed through the pseudo-Huber kink) cut the whole step to
    alpha ~ 1e-5 and let DDP crawl for hundreds of iterations on a many-revolution transfer;
    the caller bounds the blamed stages' steps instead (a trust region per stage: ``clamp``,
    as ``forward_pass`` takes it, and the sweep's per-stage radius) and sweeps again."""
    p = st.problem
    for i, a in enumerate(a0 * opts.ls_shrink ** np.arange(opts.ls_max_halvings + 1)):
        trial = forward_pass(st, gains, a, dyn, clamp)
        if not trial.ok:
            continue
        stage_costs, terminal = augmented_cost_terms(p, trial.X, trial.U, st.mult, st.hom)
        Jn = trial.cost = float(np.sum(stage_costs) + terminal)
        expected = -(a * gains.dv1 + a * a * gains.dv2)
        if _accepted(expected, J - Jn, J, Jn, opts.ls_min_ratio, opts.ls_max_ratio):
            return trial
        if i == 0 and opts.stage_trust and math.isfinite(Jn):
            bad = _blamed_stages(st, trial, stage_costs, expected, J - Jn, opts.tol_ddp)
            if bad.size:
                return Blame(bad, 0.5 * np.linalg.norm(trial.dz[p.nx:, bad], axis=0))
    return None


def _trust_region_step(st: Stages, gains: Gains, dyn: bool, opts: SolverOptions,
                       J: float, clamp: np.ndarray | None = None) -> Trial | Blame | None:
    """The full step of a trust-region sweep, accepted when its reduction ratio actual /
    expected lies within tr_ratio_tol of 1 (the quadratic model held). A rejected step whose
    failure a few stages explain (``_blamed_stages``, with ``opts.stage_trust``) bounds those
    stages (a ``Blame``, as the line search's first trial does), else None: the whole region
    shrinks. Why: on the last fuel-optimal homotopy step of a MEO transfer (1199 stages,
    delta = 1e-3) the ratios were either ~1 or -10 to -40 -- a step pushing a stage across its
    thrust bound, whose penalty the model at the inactive side does not see -- and every such
    rejection shrank the radius of all 1199 stages, so every DDP solve crawled through its 200
    iterations at stage steps of 3e-4-7e-4."""
    trial = forward_pass(st, gains, 1.0, dyn, clamp)
    if not trial.ok:
        return None
    stage_costs, terminal = augmented_cost_terms(st.problem, trial.X, trial.U, st.mult, st.hom)
    Jn = trial.cost = float(np.sum(stage_costs) + terminal)
    tol = opts.tr_ratio_tol
    expected, actual = -(gains.dv1 + gains.dv2), J - Jn
    if _accepted(expected, actual, J, Jn, 1 - tol, 1 + tol):
        return trial
    # a step predicted to gain less than tol_ddp: the ratio is round-off, any decrease will do
    small = expected < opts.tol_ddp * abs(J)
    if small and actual >= 0 and math.isfinite(Jn):
        return trial
    if opts.stage_trust and math.isfinite(Jn):
        # the region, not the model, makes a trust-region step's expected decrease small: a
        # gap worth DDP's stopping test is a model failure, not round-off
        bad = _blamed_stages(st, trial, stage_costs, expected, actual, opts.tol_ddp,
                             worth=expected - actual)
        if bad.size:
            return Blame(bad, 0.5 * np.linalg.norm(trial.dz[st.problem.nx:, bad], axis=0))
    return None


def _crawling(steps: list, opts: SolverOptions) -> bool:
    """DDP has stalled: each of the last ``ddp_stall_iter`` steps (``steps``: the start's cost,
    then (cost, fraction) after each step) was cut to less than ``ddp_stall_alpha`` of the full
    step and lowered the cost by less than tol_ddp (relative): steps that DDP's own stopping
    test would have called converged had they been full ones (a small decrease after a heavily
    shortened step only says that the globalisation struggled).

    The fraction is the line search's alpha; a trust-region step counts as 1 -- a step its
    region cuts far below the Newton step is normal there (MEO->MEO's last fuel-optimal step,
    delta = 1e-3: counted by its radius / full step, its trust-region solves stopped early and
    the KKT polishing ended at 1.1e-3 instead of converging) -- except in the solve that
    retries a failed line search (``ddp(retry=True)``): there it is the smallest radius / full
    step of a stage (``Gains.shortest``), and a rejected step after the first accepted one is
    a step of length zero (``_rejected_crawl``). That solve is the last resort before the AUL
    judges the start (``aul._diverged``).

    Why: Lyapunov L1->L2 fuel from random guesses (the robustness harness, seed 0): guesses 8,
    16 and 27 took the thrust 25-90x past its bound in their first steps (the 1e10 terminal
    weight against a penalty of 1), into regions where the line search accepted only
    alpha ~ 1e-5: 150-180 iterations at 1e-6-3e-5 relative decrease each, 25-40 s, before
    ddp_max_iter handed the solve to the trust region; there guess 16's radius fell to 1e-7 of
    the full step, 13 steps lowered the cost by ~1e-7 (relative) each and every later one was
    rejected: 200 iterations, 100 s. The successes' short-step stretches (guess 0's last
    homotopy step: alpha 3e-5-1e-3 for 7 steps, then back to 0.5) end well within 20."""
    k = opts.ddp_stall_iter
    if k <= 0 or len(steps) <= k:
        return False
    return all(fraction < opts.ddp_stall_alpha
               and before - after < opts.tol_ddp * max(abs(before), 1e-300)
               for (before, _), (after, fraction) in zip(steps[-k - 1:-1], steps[-k:]))


def _rejected_crawl(steps: list, J: float, retry: bool, opts: SolverOptions) -> bool:
    """A rejected step of the retry (``ddp(retry=True)``) after its first accepted one counts
    as a step of length zero (appended to ``steps``) for ``_crawling``; before it, the
    rejections are the region shrinking from its unbounded first step to where the model
    holds (40 in a row on the Lyapunov harness's guess 27 before its first accepted step)."""
    if not retry or len(steps) < 2:
        return False
    steps.append((J, 0.0))
    return _crawling(steps, opts)


def _max_step(gains: Gains) -> float:
    """The largest stage step |a_k| of a sweep."""
    return float(np.sqrt(np.max(np.einsum("ki,ki->k", gains.a, gains.a))))


@dataclass
class _StepControl:
    """The globalisation state of one DDP solve: the Q_uu regularisation rho, and either the
    line search's step length (carried between Dyn iterations, as in the reference code) or
    the trust-region radius (``SolverOptions.globalization``)."""

    opts: SolverOptions
    dyn: bool
    rho: float
    alpha: float = 1.0
    radius: float = math.inf
    stage_radius: np.ndarray | None = None   # (N,) the line search's per-stage trust region

    @property
    def trust_region(self) -> bool:
        return self.opts.globalization is Globalization.TRUST_REGION

    @property
    def sweep_radius(self) -> float | np.ndarray:
        """The trust region the backward sweep bounds each stage's step by."""
        if self.stage_radius is None:
            return self.radius
        return np.minimum(self.stage_radius, self.radius)

    def step(self, st: Stages, gains: Gains, J: float) -> Trial | Blame | None:
        if self.trust_region:
            out = _trust_region_step(st, gains, self.dyn, self.opts, J, self.stage_radius)
        else:
            out = _line_search(st, gains, self.alpha if self.dyn else 1.0, self.dyn, self.opts,
                               J, self.stage_radius)
        if isinstance(out, Blame):
            if self.stage_radius is None:
                self.stage_radius = np.full(st.problem.N, math.inf)
            self.stage_radius[out.stages] = out.bounds
        return out

    def indefinite(self) -> Status | None:
        """After a sweep that found Q_uu + rho I indefinite: raise rho (None) or give up."""
        self.rho = _raise_rho(self.rho, self.opts)
        return Status.QUU_INDEFINITE if self.rho > self.opts.rho_max else None

    def rejected(self, st: Stages, gains: Gains) -> Status | None:
        """After a rejected step: shrink the trust region, or raise rho for the line search
        (None), or give up."""
        o = self.opts
        if self.trust_region:   # eq. 37 of the many-revolution DDP paper, shrinking
            self.radius = (1.0 - o.tr_kappa) * min(self.radius, _max_step(gains))
            floor = 1e-12 * (1.0 + float(np.max(np.abs(st.U))))
            return Status.TRUST_REGION_COLLAPSED if self.radius < floor else None
        self.rho = _raise_rho(self.rho, o, o.short_step_rho_growth)
        return Status.LINE_SEARCH_FAILED if self.rho > o.rho_max else None

    def accepted(self, trial: Trial) -> None:
        if self.trust_region:   # eq. 37, growing (an unbounded region stays unbounded)
            self.radius *= 1.0 + self.opts.tr_kappa
            self.rho = _lower_rho(self.rho, self.opts)
        else:
            self.rho = _rho_after_step(self.rho, trial.alpha, self.opts)
            if self.dyn:
                self.alpha = min(1.0, 2.0 * trial.alpha)
        if self.stage_radius is not None:
            # a stage whose bound held the accepted step back gets a larger one, as a trust
            # region that held grows (eq. 37); the others keep theirs
            size = np.sqrt(np.sum(trial.dz[-trial.U.shape[1]:] ** 2, axis=0))
            binding = size >= 0.9 * self.stage_radius
            self.stage_radius[binding] *= 1.0 + self.opts.tr_kappa


def ddp(st: Stages, method: Method, opts: SolverOptions, stats: DDPStats,
        deadline: float | None = None, rho0: float | None = None,
        radius0: float = math.inf, retry: bool = False) -> DDPResult:
    """Alg. 3: iterate backward sweep + forward pass until the relative cost decrease is small.

    Globalisation (``_StepControl``): the line search accepts a step when actual / expected
    decrease lies in (ls_min_ratio, ls_max_ratio), halving alpha otherwise; in the Dyn variant
    alpha carries over between iterations (doubled after an accepted step, capped at 1), as in
    the reference code; a first trial that fails at a few stages (``_blamed_stages``) bounds
    those stages' steps and sweeps again instead (``opts.stage_trust``). The trust region
    bounds every stage's step and accepts the full step when the reduction ratio is near 1; a
    rejected step shrinks the region and sweeps again on the same expansions. rho0: the Quu
    regularisation to start from (default opts.rho_init);
    radius0: the trust-region radius to start from; retry: this solve retries one whose line
    search failed (``aul._trust_region_fallback``), so a step its trust region cuts far below
    the full step counts towards the stall test as a short line-search step does, and a
    rejected one as a step of length zero (``_crawling``, ``_rejected_crawl``).
    """
    p = st.problem
    ctl = _StepControl(opts, method.dyn, opts.rho_init if rho0 is None else rho0, radius=radius0)
    J = st.cost
    last = None
    steps = [(J, 1.0)]   # the start's cost, then (cost, step fraction) after each accepted step

    def result(converged, iterations, status):
        return DDPResult(converged, iterations, status, st, ctl.rho, last, ctl.radius)

    for it in range(1, opts.ddp_max_iter + 1):
        if deadline is not None and time.perf_counter() > deadline:
            return result(False, it - 1, Status.TIME_BUDGET)
        gains = _sweep(st, method.sweep, ctl.rho, stats, ctl.sweep_radius)
        if gains is None:
            if (stop := ctl.indefinite()) is not None:
                return result(False, it, stop)
            continue
        last = gains
        full_step_gain = -(gains.dv1 + gains.dv2) / max(abs(J), 1e-300)
        if not gains.clipped and _predicted_stop(st, full_step_gain, it, opts):
            return result(True, it - 1, Status.DDP_PREDICTED)
        t0 = time.perf_counter()
        step = ctl.step(st, gains, J)
        stats.forward_s += time.perf_counter() - t0
        if isinstance(step, Blame):
            # those stages' steps are bounded now: sweep again on the same expansions (an
            # iteration of ddp_max_iter, as a trust region's rejected step is)
            if _rejected_crawl(steps, J, retry, opts):
                return result(False, it, Status.DDP_STALLED)
            continue
        if step is None:
            # the whole line search found no step that its model predicts, for a step worth
            # less than DDP's own stopping test: the mismatch is the forward pass's noise
            # (round-off, the Dyn rollout's truncation error), which raising rho to rho_max
            # would spend the budget on (e.g. 20 futile iterations of 21 forward passes each,
            # half of a many-revolution LEO solve) -- converged as it stands
            if (not ctl.trust_region and it > opts.ddp_min_iter
                    and 0.0 <= full_step_gain < opts.tol_ddp and not gains.clipped):
                return result(True, it - 1, Status.DDP_NOTHING_TO_GAIN)
            if (stop := ctl.rejected(st, gains)) is not None:
                return result(False, it, stop)
            if _rejected_crawl(steps, J, retry, opts):
                return result(False, it, Status.DDP_STALLED)
            continue
        stats.iterations += 1
        stats.stages_total += p.N
        stats.stages_polynomial += int(step.poly.sum())
        t0 = time.perf_counter()
        F = new_maps(st, step, method.dyn)
        walked = np.where(step.poly, st.walked + np.sqrt(np.sum(step.dz ** 2, axis=0)), 0.0)
        st = Stages(p, step.X, step.U, st.mult, st.hom, st.eps_da, F=F, walked=walked)
        stats.expansion_s += time.perf_counter() - t0
        rel = (J - step.cost) / max(abs(J), 1e-300)
        J = st.cost
        ctl.accepted(step)
        steps.append((J, step.alpha * (gains.shortest if retry else 1.0)))
        # converged when the decrease is small for a (nearly) full step: a small decrease after a
        # heavily shortened step only says the globalisation struggled (and a step the trust
        # region cut says nothing of the full one)
        if (it >= opts.ddp_min_iter and 0.0 <= rel < opts.tol_ddp and not gains.clipped
                and (step.alpha >= 0.5 or full_step_gain < opts.tol_ddp)):
            return result(True, it, Status.DDP_CONVERGED)
        if _crawling(steps, opts):
            return result(False, it, Status.DDP_STALLED)
    return result(False, opts.ddp_max_iter, Status.DDP_MAX_ITER)
