"""The quadratic model of DDP (paper section III.A) at one nominal trajectory and the two passes
over it.

Backward sweeps: Std (Alg. 7, no dynamics Hessians), Hess (Alg. 9, with them) and Q (Alg. 10,
Q_k built by composing the cost-to-go polynomial with the stage map). Forward passes: Std
(Alg. 6, integrate every stage, then re-expand all maps in one batch) and Dyn (Alg. 8, evaluate
the stored map when the deviation is inside its convergence radius, integrate otherwise; then
re-expand only the integrated stages in one batch and re-centre the others by one batched
composition).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import da
from ..errors import DaddyError
from ..problem import Problem
from .cost_scale import anchor as cost_anchor, scale as cost_scale
from .lagrangian import Multipliers, augmented_stage_cost, augmented_terminal_cost
from .linalg import regularised_inverse, trust_region_inverse
from .options import Sweep
from .stage_maps import expand_dynamics, maps_at


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
        F: DA (nx, N): stage maps in z = [dx, du], of ``order`` (``DDPOptions.map_order``;
            the sweeps read their first and second derivatives, the Dyn pass evaluates them).
        radius: (N,) convergence radii of F at accuracy eps_da.
        walked: (N,) how far each map has been re-centred since it was expanded (the sum of
            the Dyn pass's deviations |dz_k| over the steps it served the stage; 0 after an
            expansion): where it exceeds the radius, the map may have drifted
            (``aul_safeguards.without_drift``).
        l: (N,), lz: (N, n), lzz: (N, n, n): the augmented stage cost and its derivatives.
        phix: (nx,), phixx: (nx, nx): derivatives of the augmented terminal cost.
        cost: augmented cost J of the nominal.
        anchor: the cost's constant-carrying reference (``cost_scale.anchor``).
    """

    def __init__(self, problem: Problem, X, U, mult: Multipliers, hom, eps_da: float, F=None,
                 walked: np.ndarray | None = None, order: int = 2):
        self.problem = problem
        self.X = np.asarray(X, dtype=float)
        self.U = np.asarray(U, dtype=float)
        self.mult = mult
        self.hom = hom
        self.eps_da = eps_da
        if F is None or F.order != order:   # (maps of another order: expanded again)
            F = expand_dynamics(problem, self.X[:-1], self.U, order=order)
        self.F = F
        self.radius = da.radius(self.F, eps_da)
        self.walked = np.zeros(self.U.shape[0]) if walked is None else walked
        self._map_rows = None
        self._expand_costs()
        self.anchor = cost_anchor(problem, hom)

    @property
    def scale(self) -> float:
        """What a relative test of this nominal's cost divides by (``cost_scale``)."""
        return cost_scale(self.cost, self.anchor)

    @property
    def n(self) -> int:
        return self.problem.nx + self.problem.nu

    def with_costs(self, mult: Multipliers, hom) -> "Stages":
        """The same nominal and maps for other multipliers or another homotopy step."""
        return Stages(self.problem, self.X, self.U, mult, hom, self.eps_da, F=self.F,
                      walked=self.walked, order=self.order)

    @property
    def order(self) -> int:
        """The stage maps' order."""
        return self.F.order

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


def _cost_to_go(Qb: np.ndarray, Kk: np.ndarray, G: np.ndarray, nx: int,
                sweep: Sweep) -> np.ndarray:
    """V_k (bordered, nx+1) of the feedback du = a_k + b_k dx (eq. 4-5; a_k = -Kk[:, n],
    b_k = -Kk[:, :nx]) in Q_k (bordered, n+1): G^T Q_k G, or Alg. 10's composition P_Q,k(dx,
    a_k + b_k dx). G (n+1, nx+1) is the caller's work array ([[I, 0], [b, a], [0, 1]])."""
    n = Qb.shape[0] - 1
    if sweep is Sweep.Q:
        pv = da.compose(_quadratic_da(Qb[:n, n], Qb[:n, :n]),
                        _feedback_map(-Kk[:, n], -Kk[:, :nx]))
        return _bordered(pv.gradient(), pv.hessian())
    np.negative(Kk[:, :nx], out=G[nx:n, :nx])
    np.negative(Kk[:, n], out=G[nx:n, nx])
    Vb = G.T @ Qb @ G
    Vb = Vb + Vb.T
    Vb *= 0.5
    Vb[nx, nx] = 0.0   # the constant (expected change) is not carried: dv1, dv2
    return Vb


def backward_sweep(st: Stages, sweep: Sweep, rho: float,
                   radius: float | np.ndarray = math.inf,
                   indefinite: bool = False) -> Gains | None:
    """One backward sweep; returns None when Q_uu + rho I is not positive definite. radius: the
    trust region of each stage's step |a_k| (``linalg.trust_region_inverse``; inf: none), one for
    all stages or (N,) one per stage. indefinite: a stage whose Q_uu + rho I is indefinite but
    whose radius is finite takes the trust-region subproblem's step on the region's boundary
    (Conn, Gould & Toint, the HDDP and PDDP papers' TRQP) instead of failing the sweep: the
    negative curvature is a direction of descent, not a reason to regularise it away
    (docs/design-notes.md: indefinite trust-region stages).

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
        Minv = regularised_inverse(Qb[nx:n, nx:n], rho)
        bounded = (Minv is None and indefinite and radius < math.inf
                   and bool(np.isfinite(Qb[nx:n]).all()))   # (an overflowed Q: rho is raised)
        if bounded:
            Minv = trust_region_inverse(Qb[nx:n, nx:n], Qb[nx:n, n], rho, radius)
            clipped += 1
        if Minv is None and Qb is not Qb_gn:
            # the dynamics-Hessian terms make Q_uu indefinite at this stage (e.g. the mass-flow
            # term |u| near zero thrust): use the Gauss-Newton Q of this stage instead
            Qb = Qb_gn
            Minv = regularised_inverse(Qb[nx:n, nx:n], rho)
        if Minv is None:
            return None
        Qu_rows[k] = Qb[nx:n]
        Kk = np.matmul(Minv, Qb[nx:n], out=K[k])   # eq. 4-5: a_k = -Kk[:, n], b_k = -Kk[:, :nx]
        if not bounded and radius < math.inf and (full := math.sqrt(Kk[:, n] @ Kk[:, n])) > radius:
            Minv = trust_region_inverse(Qb[nx:n, nx:n], Qb[nx:n, n], rho, radius)
            np.matmul(Minv, Qb[nx:n], out=Kk)
            clipped += 1
            shortest = min(shortest, radius / full)
        Vb = _cost_to_go(Qb, Kk, G, nx, sweep)
    a, b = -K[:, :, n], -K[:, :, :nx]
    Qu, Quu = Qu_rows[:, :, n], Qu_rows[:, :, nx:n]
    dv1 = np.einsum("ki,ki->", a, Qu)                       # sum_k a_k . Q_u,k
    dv2 = 0.5 * np.einsum("ki,ki->", a, np.einsum("kij,kj->ki", Quu, a))   # sum a.Q_uu.a / 2
    return Gains(a, b, float(dv1), float(dv2), clipped, shortest)


# ----------------------------------------------------------------------------- forward passes
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
        return expand_dynamics(st.problem, X[:-1], U, values=X[1:].T, order=st.order)
    return maps_at(st.problem, st.F, trial.dz, trial.poly, X, U, values=X[1:].T)
