"""Certified infeasibility (issue 50): a solve that ends with terminal conditions it could not
meet asks whether any trajectory could -- the least-violation problem:

    min_U  1/2 |psi(x_N)|^2      subject to every stage constraint (g_ineq, g_path, g_eq)

the problem's own dynamics, start and stage grid, its terminal equalities psi (``g_teq``)
moved into the cost and everything else held (the thrust bound among them). Its solution
decides the verdict (``Verdict``):

- INFEASIBLE: it holds the stage constraints and still misses psi by more than
  ``INFEASIBLE_MARGIN`` x tol_aul. The solve returns that point -- the least miss found, never
  breaking the bounds -- with the reason "infeasible: ...". The least-violation solve is local:
  where that problem is convex (linear dynamics, convex constraints) its minimum is the global
  one and the verdict a certificate; where it is not (a keep-out zone, nonlinear dynamics) it
  says that no point near this solve's end meets the constraints, and the reason says so;
- FEASIBLE: it meets every constraint: the problem is feasible and the failure is the
  solver's; the solve returns it (feasible, not optimal: ``converged=False``) and says so;
- UNDECIDED: the least-violation solve itself did not settle; the solve's own answer stands.

It runs only after a solve that ended unconverged on its constraints (not on its time budget
or a cancel), within what is left of the budget, and never on the least-violation problem
itself (it has no terminal equalities).

Before any solve, ``contradicted_end`` asks the same question of the end alone: is there a
final state x (and a last control u within the bound) meeting the terminal conditions
(g_teq = 0, g_tineq <= 0) and the path constraint at the last stage's end (its last sample,
g_path(x, u) <= 0) together? Dynamics cannot help there, so a contradiction among those rows
(a keep-out containing the target, two terminal rows asking for different ends) is
infeasibility known in milliseconds, where the solve would find it only once its augmented
Lagrangian stalled at the penalty cap (docs/design-notes.md). A least-squares problem in
nx + nu unknowns (SLSQP, first derivatives by DA), from the target and from x0; the verdict
is again local where those rows are not convex.
"""
from __future__ import annotations

import enum
import time
from dataclasses import dataclass, replace

import numpy as np

from ..da import functions as dm
from ..da.core import DA, variables
from ..problem import Problem
from .options import Method, SolverOptions
from .solution import Solution

# a least-violation point that misses psi by more than this x tol_aul certifies infeasibility
# (between 1x and this: too close to the tolerance to call either way -- undecided)
INFEASIBLE_MARGIN = 10.0


class Verdict(enum.Enum):
    INFEASIBLE = "infeasible"
    FEASIBLE = "feasible"
    UNDECIDED = "undecided"


def least_violation_problem(problem: Problem) -> Problem | None:
    """The least-violation problem of the module docstring, or None for a problem without
    terminal equalities (nothing to relax: its stage constraints are what failed)."""
    if problem.g_teq is None:
        return None
    g_teq, n = problem.g_teq, problem.nu

    def miss(x, x_target):
        psi = g_teq(x, x_target)
        return 0.5 * dm.dot(psi, psi)

    def no_cost(x, u, dt, hom=(0.0, 1.0)):
        return 0.0 * sum(u[i] for i in range(n)) * dt

    return replace(problem, name=f"{problem.name} (least violation)", stage_cost=no_cost,
                   terminal_cost=miss, g_teq=None)


def unmet(sol: Solution, opts: SolverOptions, out_of_time: bool) -> bool:
    """``sol`` ended unconverged with constraints above tol_aul, not on its budget or a
    cancel."""
    return not sol.converged and not out_of_time and not sol.max_violation <= opts.aul.tol


def wanted(sol: Solution, opts: SolverOptions, out_of_time: bool) -> bool:
    """Certify ``sol``: it ended unmet (``unmet``) and the options ask for the verdict."""
    return unmet(sol, opts, out_of_time) and opts.end_game.certify_infeasibility


def certify(problem: Problem, sol: Solution, opts: SolverOptions, solve_again,
            remaining_s: float | None) -> Solution:
    """``sol`` judged by the least-violation problem (module docstring). ``solve_again(p, U0,
    options)``: a solve of p from the controls U0 (the caller's ``solve`` with its method and
    cancel flag); ``remaining_s``: what is left of the time budget (None: unbounded)."""
    lv = least_violation_problem(problem)
    if lv is None or (remaining_s is not None and remaining_s <= 0.0):
        return sol
    t0 = time.perf_counter()
    o = opts.with_(run=dict(time_budget_s=remaining_s), policy=dict(order=0))
    best = solve_again(lv, np.asarray(sol.U, float), o)
    verdict, miss = judge(problem, best, opts)
    if verdict is Verdict.UNDECIDED:
        return replace(sol, reason=f"{sol.reason}; the least-violation solve did not settle "
                                   f"({best.reason})")
    from .assemble import unsolved   # (assemble imports the solve's modules)
    point = unsolved(problem, best.U, "", (sol.fuel_step or (0.0, 1.0),),
                     Method.parse(sol.method), sol.case)
    if verdict is Verdict.INFEASIBLE:
        worst = point.violations[0]
        reason = (f"infeasible: the least-violation point, every stage constraint held, still "
                  f"misses the terminal conditions by {miss:.3e} (largest: {worst['name']}"
                  + (f", {worst['label']}" if worst["label"] else "") + "; the least miss found "
                  "from this solve's end: a local minimum where the problem is not convex); the "
                  f"solve had ended: {sol.reason}")
    else:
        reason = (f"{sol.reason}; the problem is feasible: the least-violation solve met every "
                  "constraint, and its point (not optimal) is returned")
    runtime = dict(sol.runtime_s, total=sol.runtime_s.get("total", 0.0)
                   + time.perf_counter() - t0)
    return replace(point, reason=reason, iterations=sol.iterations, runtime_s=runtime,
                   history=sol.history, fuel_optimal=sol.fuel_optimal,
                   min_path_margin=best.min_path_margin,
                   infeasible=verdict is Verdict.INFEASIBLE)


def judge(problem: Problem, best: Solution, opts: SolverOptions) -> tuple[Verdict, float]:
    """(the verdict, the least-violation point's terminal miss max |psi|)."""
    X = best.X
    if not (np.all(np.isfinite(X)) and best.max_violation <= opts.aul.tol):
        return Verdict.UNDECIDED, float("nan")
    psi = np.asarray(problem.g_teq(X[-1], problem.x_target), float)
    miss = float(np.max(np.abs(psi), initial=0.0))
    if miss > INFEASIBLE_MARGIN * opts.aul.tol:
        return Verdict.INFEASIBLE, miss
    if miss <= opts.aul.tol:
        return Verdict.FEASIBLE, miss
    return Verdict.UNDECIDED, miss


@dataclass(frozen=True)
class EndMiss:
    """The least miss of the end's own rows (``contradicted_end``): max |g_teq| [g_teq's
    units], the row that misses most and the final state x (nx,) where it is reached."""

    miss: float
    row: int
    x: np.ndarray
    rows: str   # what was asked of the end together, named

    def reason(self) -> str:
        return (f"infeasible: no final state meets {self.rows} together: the least-violation "
                f"end, the bounds held, still misses g_teq by {self.miss:.3e} (largest: "
                f"g_teq[{self.row}]; the least miss found from the target and from x0, a local "
                "minimum where those rows are not convex); nothing was solved, the guess is "
                "returned (within the thrust bound)")


def contradicted_end(problem: Problem, opts: SolverOptions) -> EndMiss | None:
    """The end's own rows in contradiction (module docstring), or None: a point meets them
    to tol_aul, a least miss is below ``INFEASIBLE_MARGIN`` x tol_aul, the least-squares
    solve settled from neither start, or the problem has no terminal equalities. Costs one
    evaluation of the rows when the target (with zero control) meets them, as most
    problems' does."""
    if problem.g_teq is None:
        return None
    rows = _EndRows(problem)
    tol = opts.aul.tol
    starts = [np.asarray(problem.x0, float)]
    xt = None if problem.x_target is None else np.asarray(problem.x_target, float)
    if xt is not None and xt.shape == starts[0].shape:
        starts.insert(0, xt)
    least = None
    for x in starts:
        z = np.r_[x, np.zeros(problem.nu)]
        try:
            if rows.met(z, tol):
                return None
            found = rows.least_miss(z, tol)
        except (ValueError, ArithmeticError):   # rows undefined there (a DomainError: sqrt(0))
            found = None
        if found is None:
            continue                         # undecided from this start
        if found.miss <= INFEASIBLE_MARGIN * tol:
            return None
        least = found if least is None or found.miss < least.miss else least
    return least


class _EndRows:
    """The end's rows as functions of z = (x (nx,), u (nu,)): psi = g_teq(x, x_t), and the
    inequalities g_tineq(x, x_t), g_path(x, u) (the last sample), |u|^2 - u_max^2 <= 0 (where
    u is a thrust alone: not with static parameters among the controls); values and
    Jacobians by DA (order 1)."""

    def __init__(self, problem: Problem):
        self.p, self.nx, self.nu = problem, problem.nx, problem.nu

    @staticmethod
    def _eval(f, z: np.ndarray, column: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """(values (m,), Jacobian (m, len(z))) of f at z; ``column``: f takes (n, 1) columns,
        as g_path does."""
        v = f(variables(z[:, None] if column else z, order=1))
        if not isinstance(v, DA):   # rows that do not depend on z
            v = np.asarray(v, float).reshape(-1)
            return v, np.zeros((len(v), len(z)))
        values = np.asarray(v.cons, float).reshape(-1)
        return values, v.linear().reshape(len(values), len(z))

    def psi(self, z):
        p = self.p
        return self._eval(lambda w: p.g_teq(w[:self.nx], p.x_target), z)

    def ineq(self, z):
        """(values (m,), Jacobian (m, nx + nu)) of the inequalities g <= 0."""
        p, nx, parts = self.p, self.nx, []
        if p.g_tineq is not None:
            parts.append(self._eval(lambda w: p.g_tineq(w[:nx], p.x_target), z))
        if p.g_path is not None:
            parts.append(self._eval(lambda w: p.g_path(w[:nx], w[nx:]), z, column=True))
        if p.u_max and p.parameters is None:
            u = z[nx:]
            parts.append((np.array([u @ u - p.u_max ** 2]), np.r_[np.zeros(nx), 2 * u][None]))
        if not parts:
            return np.zeros(0), np.zeros((0, len(z)))
        return np.concatenate([a for a, _ in parts]), np.vstack([b for _, b in parts])

    def met(self, z: np.ndarray, tol: float) -> bool:
        psi, _ = self.psi(z)
        g, _ = self.ineq(z)
        return bool(np.max(np.abs(psi), initial=0.0) <= tol and np.max(g, initial=0.0) <= tol)

    def least_miss(self, z0: np.ndarray, tol: float) -> EndMiss | None:
        """min 1/2 |psi|^2 under the inequalities, from z0 (SLSQP); None unless it ends at a
        first-order stationary point (``_stationary``) with the inequalities held to tol."""
        from scipy.optimize import minimize   # (here: the import costs 0.5 s, rarely needed)

        def f(z):
            psi, J = self.psi(z)
            return 0.5 * float(psi @ psi), psi @ J
        cons = [dict(type="ineq", fun=lambda z: -self.ineq(z)[0],
                     jac=lambda z: -self.ineq(z)[1])]
        with np.errstate(all="ignore"):
            res = minimize(f, z0, jac=True, method="SLSQP", constraints=cons,
                           options=dict(maxiter=200, ftol=1e-14))
        z = res.x
        if not (np.all(np.isfinite(z)) and self._stationary(z, res.multipliers, tol)):
            return None
        psi = np.abs(self.psi(z)[0])
        p = self.p
        asked = ", ".join(name for name, f in (("g_teq", p.g_teq), ("g_tineq", p.g_tineq),
                                               ("g_path at the end", p.g_path),
                                               ("the thrust bound",
                                                p.u_max and p.parameters is None)) if f)
        return EndMiss(float(psi.max(initial=0.0)), int(np.argmax(psi)), z[:self.nx], asked)

    def _stationary(self, z: np.ndarray, lam: np.ndarray, tol: float) -> bool:
        """z holds the inequalities to tol and is a KKT point of the least squares to 1e-6 of
        its gradient's scale: psi^T J_psi + lam^T J_g = 0, lam >= 0, lam g = 0 (SLSQP's own
        success flag is not asked for: its line search ends on round-off at the optimum)."""
        psi, Jp = self.psi(z)
        g, Jg = self.ineq(z)
        lam = np.asarray(lam, float)
        if lam.shape != g.shape or np.max(g, initial=0.0) > tol or np.min(lam, initial=0) < 0:
            return False
        grad = psi @ Jp
        scale = max(1.0, float(np.max(np.abs(psi), initial=0.0) * np.max(np.abs(Jp), initial=0)))
        return bool(np.max(np.abs(grad + lam @ Jg), initial=0.0) <= 1e-6 * scale
                    and np.max(np.abs(lam * g), initial=0.0) <= 1e-6 * scale)
