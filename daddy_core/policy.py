"""Polynomial feedback laws (issue 47): at a converged solution, the optimal control of each
stage as a polynomial of order k - 1 in the state's deviation, delta u*_k(delta x), from the
DA-HDDP backward sweep on polynomials (Maestrini et al., sec. III).

The sweep works in one algebra of n = nx + nu + nl variables z = [dx, du, dl] (dl: the
terminal multipliers' deviation from the solution's), order k:

    V_N(dx, dl)      = phi(x_N + dx) + (l + dl)^T psi(x_N + dx)
    Q_k(dx, du, dl)  = L_k(x_k + dx, u_k + du) + V_{k+1}(f_k(x_k + dx, u_k + du) - x_{k+1}, dl)
    du*(dx, dl)      : dQ_k/du = 0, by inverting z -> [dx, dQ_k/du, dl] (``da.calculus.invert``)
    V_k(dx, dl)      = Q_k(dx, du*(dx, dl), dl)

and each stage's law re-optimises the multipliers: dl*(dx) from dV_k/dl = 0 (inverted the
same way), delta u*_k(dx) = du*(dx, dl*(dx)). The stage maps f_k, costs and terminal
functions are the problem's own, expanded to order k on DA; derivatives and inversions lose one
order, so the law is exact to order k - 1 (the truncated Taylor series of the re-optimised
control). Where the remaining stages cannot move every terminal row (the multipliers' block of
V_k singular: the last few stages of a short horizon), the stage has no law (None).

Stage constraints active at the solution (inequalities within ACTIVE_TOL of their bound, and
every equality) are held in the law: with their multipliers dnu as further variables, the
stage's law solves its KKT system dQ/du + g_u^T nu = 0, g = 0 instead of dQ/du = 0 -- the
active set of the solution, valid while a perturbation does not change it. The terminal
conditions must be equalities (``g_teq``; inactive ``g_tineq`` rows are dropped); an active
terminal inequality is refused by name.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass, replace

import numpy as np

from .da import functions as dm
from .da.calculus import SIX_DIGITS_CONDITION, derivative, invert, partial_evaluate
from .da.core import DA, _wrap, variables
from .da.maps import compose, evaluate
from .da.monomials import MAX_ORDER, tables
from .errors import DaddyError
from .problem import Problem, StageStep
from .throttle import throttle_thrust, thrust_of, throttle_form

ACTIVE_TOL = 1e-7   # a stage or terminal inequality above -ACTIVE_TOL counts as active
# a stage's systems are solved only where their linear part's condition number leaves the law
# 6 significant digits (cond * eps <= 1e-6); beyond it the stage has no law (design notes)
LAW_MAX_CONDITION = SIX_DIGITS_CONDITION


@dataclass(frozen=True)
class Policy:
    """Feedback laws of a solution: u_k(x) = U[k] + law_k(x - X[k]).

    Attributes:
        order: the laws' order (the stage maps' order - 1).
        X: (N+1, nx) the states the laws are expanded about; U: (N, nu) the controls.
        coefficients: (N, M, nu) each stage's law in nx variables (``da.monomials.tables(nx,
            order)`` layout); NaN rows for a stage without a law (``has_law``).
    """

    order: int
    X: np.ndarray
    U: np.ndarray
    coefficients: np.ndarray
    # laws of an exact fuel form (``throttle``): U and the laws are [s, alpha, beta], and
    # ``thrust`` turns them into the thrust with the form's bound and frame
    u_max: float | None = None
    frame: np.ndarray | None = None

    @property
    def nx(self) -> int:
        return self.X.shape[1]

    @property
    def has_law(self) -> np.ndarray:
        """(N,) bool: the stages whose law exists."""
        return np.all(np.isfinite(self.coefficients), axis=(1, 2))

    @property
    def offset(self) -> float:
        """The largest constant term of the laws: the control a law gives at the plan's own
        state minus the plan's, 0 at an optimum. A plan that is not its problem's optimum (a
        warm re-plan not polished) has laws that move away from it by this much at once."""
        return float(np.nanmax(np.abs(self.coefficients[:, 0, :]), initial=0.0))

    def law(self, k: int) -> DA | None:
        """Stage k's law as a DA (nu,) in nx variables, or None."""
        if not self.has_law[k]:
            return None
        return DA(self.coefficients[k], tables(self.nx, self.order))

    def control(self, k: int, x) -> np.ndarray:
        """The control of stage k for the state x: U[k] + law_k(x - X[k]); x (nx,) gives
        (nu,), a batch x (nx, B) gives (nu, B). A DaddyError for a stage without a law."""
        law = self.law(k)
        if law is None:
            raise DaddyError(f"policy: stage {k} has no feedback law (the remaining stages "
                             "cannot move every terminal row)")
        x = np.asarray(x, float)
        if x.ndim == 1:
            return self.U[k] + evaluate(law, x - self.X[k])
        batch = DA(law.c[:, :, None], law.T)                    # (nu, 1): one law, B points
        return self.U[k][:, None] + evaluate(batch, x - self.X[k][:, None])

    def flown(self, k: int, dx: DA) -> DA:
        """Stage k's control as the problem's step takes it (the thrust, for an exact fuel
        form's laws) for a state deviation dx (DA (nx, 1) in any algebra): a polynomial of
        dx's variables (``uncertainty``)."""
        law = self.law(k)
        if law is None:
            raise DaddyError(f"policy: stage {k} has no feedback law")
        v = compose(DA(law.c[:, :, None], law.T), dx) + self.U[k][:, None]
        return v if self.frame is None else throttle_thrust(v, self.u_max, self.frame)[:3]

    def truncated(self, order: int) -> "Policy":
        """The same laws to a lower ``order``: the laws are truncated Taylor series, so this is
        the policy an order-``order`` build would give."""
        if not (isinstance(order, int) and 1 <= order <= self.order):
            raise DaddyError(f"policy: a truncation order must be in [1, {self.order}], got "
                             f"{order!r}")
        T = tables(self.nx, order)
        return replace(self, order=order, coefficients=self.coefficients[:, :T.size].copy())

    def thrust(self, k: int, x) -> np.ndarray:
        """The problem's control of stage k for the state x (as ``control`` takes it): the
        thrust where the laws are an exact fuel form's, else ``control`` itself."""
        v = self.control(k, x)
        if self.frame is None:
            return v
        batch = v.ndim == 2
        u = thrust_of(np.atleast_2d(v.T if batch else v), self.u_max, self.frame)
        return u.T if batch else u[0]

    def to_dict(self) -> dict:
        return {"order": self.order, "X": self.X.tolist(), "U": self.U.tolist(),
                "coefficients": np.where(np.isfinite(self.coefficients), self.coefficients,
                                         None).tolist(),
                "u_max": self.u_max, "frame": None if self.frame is None else self.frame.tolist()}

    @classmethod
    def from_dict(cls, d: dict) -> "Policy":
        try:
            c = np.array(d["coefficients"], dtype=float)
            frame = d.get("frame")
            return cls(int(d["order"]), np.asarray(d["X"], float), np.asarray(d["U"], float), c,
                       d.get("u_max"), None if frame is None else np.asarray(frame, float))
        except (KeyError, TypeError, ValueError) as exc:
            raise DaddyError(f"policy: a malformed policy record ({exc})") from exc


def fuel_policy(problem: Problem, sol, order: int = 2) -> Policy:
    """The feedback laws of a fuel-optimal solution that is its exact fuel form's optimum
    (``throttle``): built on that form, whose bang-bang stages hold their throttle bound and
    whose coasting stages hold their direction (no curvature there); ``Policy.thrust`` gives
    the thrust."""
    form = throttle_form(problem, np.asarray(sol.U, float))
    if form is None:
        raise DaddyError("policy: this problem has no exact fuel form (throttle.has_throttle_form)")
    V = form.controls(np.asarray(sol.U, float))
    laws = feedback_policy(form.problem, replace(sol, U=V), order)
    return replace(laws, u_max=form.u_max, frame=form.frame)


def feedback_policy(problem: Problem, sol, order: int = 2, hom=None) -> Policy:
    """The feedback laws of order ``order`` (1 to MAX_ORDER - 1) of the converged solution
    ``sol`` of ``problem`` (module docstring); stage maps of order ``order`` + 1.

    ``hom``: the stage cost's homotopy argument (default: the last step the solve ran,
    ``sol.fuel_step``, or the energy step)."""
    X, U = _checked(problem, sol.X, sol.U, order)
    hom = (sol.fuel_step or (0.0, 1.0)) if hom is None else hom
    lam = _terminal_multipliers(problem, X, U, sol.duals)
    laws = _sweep(problem, X, U, lam, _active_rows(problem, X, U), hom, order)
    return Policy(order, X.copy(), U.copy(), laws)


def tracking_policy(problem: Problem, X, U, order: int = 1) -> Policy:
    """The neighbouring laws of any plan (X, U) of ``problem`` that meets its terminal
    equalities, optimal or not (a warm re-plan stopped by its budget): for a state deviation at
    stage k, the controls of the remaining stages that still meet the terminal equalities with
    the least correction sum_j |u_j - U_j|^2 / s_j^2 dt_j / dt_mean (``tracking_problem``) --
    the backward sweep of ``feedback_policy`` on that problem, whose optimum is the plan itself
    (multipliers 0), so the laws' constant terms (``Policy.offset``) are the least correction
    that closes the plan's own terminal residual, 0 for a plan that meets it.

    The stage constraints (thrust bound, path rows) are not held: the laws are for the small
    deviations between re-plans, and a user clips their control to its bounds. ``problem``'s
    cost and stage constraints are not used; its terminal inequalities must be inactive
    (``feedback_policy``).

    Args:
        problem: the plan's problem (its dynamics, stage grid, terminal equalities, u_max).
        X: (N+1, nx) the plan's states; U: (N, nu) its controls.
        order: the laws' order (stage maps of order + 1).
    """
    X, U = _checked(problem, X, U, order)
    tracking = tracking_problem(problem, U)
    V = np.zeros_like(U)
    lam = np.zeros(_terminal_rows(tracking, X, V)[1])
    laws = _sweep(tracking, X, V, lam, [[] for _ in range(problem.N)], (0.0, 1.0), order)
    return Policy(order, X.copy(), U.copy(), laws * correction_scale(problem, U)[:, None, None])


def tracking_problem(problem: Problem, U) -> Problem:
    """The problem of ``tracking_policy``: its control is the scaled correction
    v_j = (u_j - U_j) / s_j to the plan's controls U (N, nu), the stage found from the step's
    t0; its cost sum_j |v_j|^2 dt_j / dt_mean; no terminal cost, no stage constraints. v = 0 is
    the plan. With a thrust bound u_max, s_j = max(|U_j| / u_max, floor) (at most 1; floor:
    ``NewtonOptions.control_weight_floor``), the weights of Newton's minimum-norm steps: a
    correction goes to the thrust arcs, where a change of direction costs no propellant to
    first order, and the coasting arcs keep coasting; without one, s_j = 1."""
    U = np.asarray(U, float)
    scale = correction_scale(problem, U)[:, None]
    t0s, dt = problem.stage_t0, problem.stage_dt
    edges = t0s[1:] - 0.5 * dt[:-1]          # a stage's t0 is nearest its own start
    step, dt_mean = problem.step, float(np.mean(dt))

    def corrected(x, v, d, t0):
        at = np.searchsorted(edges, t0)
        ref, s = U[at].T, scale[at].T                   # (nu,) or (nu, B); (1,) or (1, B)
        if ref.ndim == 1 and np.ndim(v) == 2:         # one stage, a batch of controls
            ref, s = ref[:, None], s[:, None]
        return step(x, v * s + ref, d, t0)

    def correction(x, v, d, hom=(0.0, 1.0)):
        return sum(v[i] * v[i] for i in range(problem.nu)) * (d / dt_mean)

    return replace(problem, step=StageStep(corrected, takes_t0=True), stage_cost=correction,
                   terminal_cost=_no_cost, g_ineq=None, g_eq=None, g_path=None, rhs=None,
                   u_max=None)


def correction_scale(problem: Problem, U: np.ndarray) -> np.ndarray:
    """(N,) the correction scale s_j of ``tracking_problem``."""
    from .solver.newton import control_scale        # (the solver's package imports this one)
    from .solver.options import NewtonOptions
    if not problem.u_max:
        return np.ones(problem.N)
    return control_scale(U, problem.u_max, NewtonOptions().control_weight_floor)


def _checked(problem: Problem, X, U, order: int) -> tuple[np.ndarray, np.ndarray]:
    """X, U as float arrays of the problem's shapes, and the order in range; else DaddyError."""
    if not (isinstance(order, int) and 1 <= order <= MAX_ORDER - 1):
        raise DaddyError(f"policy order must be an integer in [1, {MAX_ORDER - 1}], got {order!r}")
    X, U = np.asarray(X, float), np.asarray(U, float)
    nx, nu, N = problem.nx, problem.nu, problem.N
    if X.shape != (N + 1, nx) or U.shape != (N, nu):
        raise DaddyError(f"policy: the solution's X {X.shape} / U {U.shape} are not this "
                         f"problem's ({N + 1}, {nx}) / ({N}, {nu})")
    return X, U


def _no_cost(x, x_target):
    return 0.0 * x[0]


def _sweep(problem: Problem, X: np.ndarray, U: np.ndarray, lam: np.ndarray, active: list,
           hom, order: int) -> np.ndarray:
    """The backward sweep of the module docstring about (X, U) with the terminal multipliers
    ``lam`` (of ``g_teq``) and each stage's held rows ``active``: the laws' coefficients
    (``Policy.coefficients``)."""
    k = order + 1
    nx, nu, N = problem.nx, problem.nu, problem.N
    nl, m = lam.size, max(map(len, active), default=0)
    if order == 1 and m == 0:
        laws = _sweep_quadratic(problem, X, U, lam)
        if laws is not None:
            return laws
    n = nx + nu + m + nl
    if n > 64:
        raise DaddyError(f"policy: {n} DA variables (states, controls, active stage rows, "
                         "terminal rows) exceed 64")
    xs = variables(X[:-1].T, order=k, n=n)                         # (nx, N) at every stage
    us = variables(U.T, order=k, n=n, first=nx)                      # (nu, N)
    F = problem.step(xs, us, problem.stage_dt, problem.stage_t0)      # (nx, N)
    L = problem.stage_cost(xs, us, problem.stage_dt, hom)            # (N,)
    rows = problem.path_constraints(xs, us, problem.stage_dt, problem.stage_t0)[0] if m else None
    V = _terminal_lagrangian(problem, X[-1], lam, k, n)
    ident = variables(np.zeros(n), order=k)                          # z itself, (n,)
    laws = np.full((N, tables(nx, order).size, nu), np.nan)
    for j in range(N - 1, -1, -1):
        G = dm.concatenate([F[:, j] - X[j + 1], ident[nx:]])
        Q = L[j] + compose(V, G)
        # the active rows held as equalities, their multipliers nu the variables after du:
        # stationary in (du, dnu) is the stage's KKT system
        held = Q
        for r, i in enumerate(active[j]):
            held = held + ident[nx + nu + r] * rows[i, j]
        du = _stage_law(held, ident, nx, nu, len(active[j]), j)       # du*(dx, dl), (nu,)
        V = compose(Q, dm.concatenate([ident[:nx], du, ident[nx + nu:]]))
        law = _with_multipliers(V, du, ident, nx, nu + m, nl)
        if law is not None:
            laws[j] = _restrict(law, nx, order).c
    return laws


def _sweep_quadratic(problem: Problem, X: np.ndarray, U: np.ndarray,
                     lam: np.ndarray) -> np.ndarray | None:
    """``_sweep`` for order-1 laws without held rows, on matrices: the same truncated
    polynomials (every Q_k, V_k quadratic in z = [dx, du, dl]) and the same condition limits,
    ~10x faster than composing them as DAs. None where a stage's control block is singular
    (``_sweep`` then takes the DA route, which holds flat controls)."""
    nx, nu, N, nl = problem.nx, problem.nu, problem.N, lam.size
    ns, n = nx + nu, nx + nu + nl
    xs, us = variables(X[:-1].T, order=2, n=ns), variables(U.T, order=2, n=ns, first=nx)
    F = problem.step(xs, us, problem.stage_dt, problem.stage_t0)      # (nx, N)
    L = problem.stage_cost(xs, us, problem.stage_dt, (0.0, 1.0)) + 0.0 * xs[0]
    y0 = np.moveaxis(F.cons, 0, -1) - X[1:]                           # (N, nx)
    J = np.moveaxis(F.linear(), 0, 1)                                 # (N, nx, ns)
    HF = np.moveaxis(F.hessian(), 0, 1)                               # (N, nx, ns, ns)
    Lg, LH = L.linear(), L.hessian()                                  # (N, ns), (N, ns, ns)
    x = variables(X[-1], order=2)
    phi = problem.terminal_cost(x, problem.x_target) + 0.0 * x[0]
    Vx, Vxx = phi.linear().copy(), phi.hessian().copy()
    Vl, Vxl = np.zeros(nl), np.zeros((nx, nl))
    if nl:
        psi = problem.g_teq(x, problem.x_target)
        Vx += lam @ psi.linear()
        Vxx += np.einsum("i,ijk->jk", lam, psi.hessian())
        Vl, Vxl = psi.cons.copy(), psi.linear().T.copy()
    Vll = np.zeros((nl, nl))
    u, w = slice(nx, ns), np.r_[0:nx, ns:n]        # z's controls; w = [dx, dl] within z
    laws = np.full((N, 1 + nx, nu), np.nan)
    for j in range(N - 1, -1, -1):
        gy = Vx + Vxx @ y0[j]
        Qg = np.concatenate([Lg[j] + J[j].T @ gy, Vl + Vxl.T @ y0[j]])     # (n,)
        Qh = np.zeros((n, n))
        Qh[:ns, :ns] = LH[j] + J[j].T @ Vxx @ J[j] + np.einsum("i,ijk->jk", gy, HF[j])
        Qh[:ns, ns:] = J[j].T @ Vxl
        Qh[ns:, :ns] = Qh[:ns, ns:].T
        Qh[ns:, ns:] = Vll
        Quu = Qh[u, u]
        if not _invertible(Qh[u], n, u):
            return None
        K = -np.linalg.solve(Quu, np.column_stack([Qg[u], Qh[u][:, w]]))   # du = K [1, w]
        Vg = Qg[w] + Qh[w][:, u] @ K[:, 0]
        Vh = Qh[np.ix_(w, w)] + Qh[w][:, u] @ K[:, 1:]
        Vx, Vl = Vg[:nx], Vg[nx:]
        Vxx, Vxl, Vll = Vh[:nx, :nx], Vh[:nx, nx:], Vh[nx:, nx:]
        if not nl:
            laws[j] = np.vstack([K[:, 0], K[:, 1:].T])
        elif _invertible(np.column_stack([Vxl.T, np.zeros((nl, nu)), Vll]), n, slice(ns, n)):
            D = -np.linalg.solve(Vll, np.column_stack([Vl, Vxl.T]))   # dl* = D [1, dx]
            Kx, Kl = K[:, 1:nx + 1], K[:, nx + 1:]
            laws[j] = np.vstack([K[:, 0] + Kl @ D[:, 0], (Kx + Kl @ D[:, 1:]).T])
    return laws


def _invertible(rows: np.ndarray, n: int, at: slice) -> bool:
    """The linear part of z -> z with the components ``at`` replaced by ``rows`` (a gradient's
    Jacobian) is invertible within LAW_MAX_CONDITION, as ``_stationary`` requires."""
    M = np.eye(n)
    M[at] = rows
    return bool(np.linalg.cond(M) < LAW_MAX_CONDITION)


def _stationary(Q: DA, ident: DA, solve: list, hold: list = ()) -> DA:
    """z with dQ/dz_v = 0 for the variables ``solve`` and dz_v = 0 for those in ``hold``, as
    polynomials of the others (a map (n,)): the inverse of z -> [.., dQ/dz_v.., ..] at zero
    gradient."""
    grad = {v: derivative(Q, v) for v in solve}
    M = dm.stack([grad[v] if v in grad else ident[v] for v in range(ident.shape[0])])
    fixed = {v: -float(g.cons) for v, g in grad.items()}
    fixed.update({v: 0.0 for v in hold})
    return partial_evaluate(invert(M, LAW_MAX_CONDITION), fixed)


def _stage_law(held: DA, ident: DA, nx: int, nu: int, n_active: int, stage: int) -> DA:
    """du*(dx, dl) of one stage: stationary in the controls and the active rows' multipliers.
    Where that system is singular because some controls have no curvature and no active row
    reads them -- a coasting stage's thrust direction in the exact fuel form -- those are held
    at the plan's (``FLAT_CONTROL``), and the rest solved."""
    controls = list(range(nx, nx + nu))
    rows = list(range(nx + nu, nx + nu + n_active))
    try:
        return _stationary(held, ident, controls + rows)[nx:nx + nu]
    except DaddyError:
        pass
    flat = [v for v in controls if _flat(held, v, rows)]
    if not flat:
        raise DaddyError(f"policy: stage {stage}'s control block is singular (no law)")
    solve = [v for v in controls if v not in flat] + rows
    return _stationary(held, ident, solve, flat)[nx:nx + nu]


FLAT_CONTROL = 1e-14   # a control whose curvature is below this (relative) and no active row reads


def _flat(Q: DA, v: int, rows: list) -> bool:
    """Control variable v has (to FLAT_CONTROL) no curvature in Q and no active row's
    multiplier term reads it linearly."""
    H = Q.hessian()
    scale = max(1.0, float(np.abs(H).max()))
    return (abs(H[v, v]) <= FLAT_CONTROL * scale
            and all(abs(H[v, r]) <= FLAT_CONTROL * scale for r in rows))


def _with_multipliers(V: DA, du: DA, ident: DA, nx: int, between: int, nl: int) -> DA | None:
    """du*(dx, dl*(dx)): the multipliers re-optimised (dV/dl = 0), None where V's multiplier
    block is singular (``between``: the variables between dx and dl, which V does not use)."""
    if nl == 0:
        return du
    try:
        dl = _stationary(V, ident, list(range(nx + between, nx + between + nl)))
    except DaddyError:
        return None
    dl = dl[nx + between:]
    zeros = 0.0 * ident[nx:nx + between]
    return compose(du, dm.concatenate([ident[:nx], zeros, dl]))


def _active_rows(problem: Problem, X, U) -> list[list[int]]:
    """Each stage's rows of ``problem.path_constraints`` held in its law: the inequalities
    within ACTIVE_TOL of their bound, and every equality."""
    g, ni = problem.path_constraints(X[:-1].T, U.T, problem.stage_dt, problem.stage_t0)
    if g is None:
        return [[] for _ in range(problem.N)]
    g = np.asarray(g, float)
    held = np.vstack([g[:ni] > -ACTIVE_TOL, np.ones((g.shape[0] - ni, g.shape[1]), bool)])
    return [np.flatnonzero(held[:, j]).tolist() for j in range(problem.N)]


def _terminal_lagrangian(problem: Problem, xN: np.ndarray, lam: np.ndarray, k: int,
                         n: int) -> DA:
    """phi(x_N + dx) + (lam + dl)^T psi(x_N + dx) in the sweep's algebra."""
    x = variables(xN, order=k, n=n)
    V = problem.terminal_cost(x, problem.x_target) + 0.0 * x[0]
    if lam.size:
        psi = problem.g_teq(x, problem.x_target)
        mult = variables(lam, order=k, n=n, first=n - lam.size)
        V = V + dm.dot(mult, psi)
    return V


def _terminal_rows(problem: Problem, X, U) -> tuple[int, int]:
    """(inequalities, equalities) of the terminal constraints; refuses active terminal
    inequalities (module docstring)."""
    _, _, gt, nti = problem.constraint_values(X, U)
    if gt is not None and nti and np.any(gt[:nti] > -ACTIVE_TOL):
        raise DaddyError("policy: a terminal inequality (g_tineq) is active; feedback laws are "
                         "built for terminal equalities (g_teq)")
    return nti, 0 if gt is None else gt.shape[0] - nti


def _terminal_multipliers(problem: Problem, X, U, duals) -> np.ndarray:
    """The solution's multipliers of ``g_teq`` (``_terminal_rows``)."""
    nti, nte = _terminal_rows(problem, X, U)
    lam_t = np.asarray((duals or {}).get("lam_t", []), float)
    if lam_t.size != nti + nte:
        raise DaddyError(f"policy: the solution has {lam_t.size} terminal multipliers, the "
                         f"problem {nti + nte} terminal rows (solve it again)")
    return lam_t[nti:]


def _restrict(p: DA, m: int, order: int) -> DA:
    """p (shape (nu,), in n variables) as a polynomial of its first m variables to ``order``
    (it must not depend on the others)."""
    keep = _restriction(p.T.n, p.T.k, m, order)
    return _wrap(np.ascontiguousarray(p.c[keep]), tables(m, order))


@functools.lru_cache(maxsize=None)
def _restriction(n: int, k: int, m: int, order: int) -> np.ndarray:
    """Indices in tables(n, k) of the monomials of tables(m, order) (others' exponents 0)."""
    index = {tuple(e): i for i, e in enumerate(tables(n, k).exponents.tolist())}
    return np.array([index[tuple(e) + (0,) * (n - m)]
                     for e in tables(m, order).exponents.tolist()], int)


__all__ = ["Policy", "feedback_policy", "fuel_policy", "tracking_policy", "correction_scale",
           "tracking_problem"]
