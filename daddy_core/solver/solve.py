"""DADDy orchestration (paper Fig. 1): validate (``Problem.check_guess``) -> warm start ->
(Newton restoration) -> fuel homotopy (augmented Lagrangian -> DDP) -> Newton polishing ->
the DOP853 re-propagation check -> Solution.

Each step lives in its own module; this one only chains them and assembles the Solution.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import DaddyError
from ..integrators import dop853, dop853_batch
from ..path_constraints import violated_at_start
from ..problem import Problem, largest
from ..throttle import ThrottleForm, has_throttle_form, throttle_form
from . import newton, path_exchange
from .ddp import DDPStats
from .homotopy import HomotopyResult, continuation, homotopy_steps, resume
from .kkt_polish import kkt_polish
from .optimality import Optimality, objective, optimality
from .options import Method, SolverOptions
from .solution import Solution, WarmStart
from .stage_maps import StageMaps, expand_dynamics


def _describe(r: dict) -> str:
    """One entry of ``Problem.violation_report`` as the reason of a failed solve names it."""
    label = "" if r.get("label") is None else f" ({r['label']})"
    stage = "" if r["stage"] is None else f" (stage {r['stage']})"
    return f"{r['name']}{label} {r['violation']:.2e}{stage}"


def repropagation_miss(problem: Problem, U: np.ndarray, X: np.ndarray | None = None,
                       maps: StageMaps | None = None) -> float | None:
    """Terminal miss (max terminal-constraint violation) after re-propagating U from x0 with
    DOP853 at rtol = atol = 1e-12, stage by stage (``integrators.dop853``: solve_ivp's scheme and
    step control); inf when the re-propagation fails (NaN or inf dynamics).

    Each stage's first trial step is the whole stage (scipy's initial-step heuristic costs two
    rhs calls and usually picks a shorter step); the error control still accepts only steps
    within the tolerances.

    With the trajectory X (N+1, nx) that U was solved on and its stage maps (``StageMaps`` whose
    radius holds (X, U)), every stage is re-propagated at once from its own start X_k (``dop853_batch``, the
    same steps as one at a time) and the stage defects d_k = DOP853(X_k, U_k) - X_{k+1} are
    carried to the end through the maps' state Jacobians: x_N = X_N + e_N, e_{k+1} = Phi_k e_k
    + d_k, e_0 = x0 - X_0 -- the sequential re-propagation to first order in e, whose neglected
    second-order terms are below round-off while every |e_k| <= ``_LINEAR_REPROPAGATION`` (else
    the stages are integrated one after the other from x0). A converged many-revolution
    solution is re-propagated in milliseconds instead of ~13 Python rhs calls per stage (4960
    LEO stages: 0.5 s of a warm re-plan)."""
    if problem.rhs is None:
        x = problem.rollout(U)[-1]
    else:
        x = _linear_repropagation(problem, U, X, maps)
        if x is None:
            x = problem.x0.copy()
            try:
                for k in range(problem.N):
                    x = dop853(problem.rhs, x, U[k], problem.stage_t0[k], problem.stage_dt[k],
                               rtol=1e-12, atol=1e-12)
            except DaddyError:
                return math.inf
    if problem.terminal_constraints(x)[0] is None:
        return None
    return problem.terminal_violation(x)


# the largest deviation e_k from the solved states that the linearised re-propagation carries
# (its second-order remainder ~ |f_xx| e^2 stays below round-off of the states)
_LINEAR_REPROPAGATION = 1e-7


def _linear_repropagation(problem: Problem, U: np.ndarray, X: np.ndarray | None,
                          maps: StageMaps | None) -> np.ndarray | None:
    """x_N of ``repropagation_miss``'s linearised re-propagation, or None when it does not
    apply (no states or maps, maps expanded farther from (X, U) than their radius, a failed
    stage, or a deviation beyond _LINEAR_REPROPAGATION)."""
    if X is None or maps is None or maps.N != problem.N or not maps.deviation(X, U)[1].all():
        return None
    nx = problem.nx
    try:
        flows = dop853_batch(problem.rhs, X[:-1].T, U.T, problem.stage_t0, problem.stage_dt,
                             rtol=1e-12, atol=1e-12)
    except DaddyError:
        return None
    defects = flows.T - X[1:]                                                # (N, nx)
    # Phi_k[i, j] = d x_{k+1, i} / d x_{k, j}: the maps' linear coefficients (M, nx, N) of the
    # state variables
    phi = np.ascontiguousarray(np.transpose(maps.F.c[1:nx + 1], (2, 1, 0)))  # (N, nx, nx)
    E = np.empty((problem.N + 1, nx))
    E[0] = problem.x0 - X[0]
    for k in range(problem.N):
        np.add(phi[k] @ E[k], defects[k], out=E[k + 1])
    if not np.max(np.abs(E)) <= _LINEAR_REPROPAGATION:   # (or NaN)
        return None
    return X[-1] + E[-1]


@dataclass
class _Clock:
    """Start, deadline and the phase timings of one solve (``Solution.runtime_s``)."""

    budget_s: float | None
    start: float = field(default_factory=time.perf_counter)
    times: dict = field(default_factory=dict)

    @property
    def deadline(self) -> float | None:
        return None if self.budget_s is None else self.start + self.budget_s

    def lap(self, name: str, since: float) -> float:
        """Add the time since ``since`` to phase ``name`` (a phase may run again:
        ``_resolve``); returns now."""
        now = time.perf_counter()
        self.times[name] = self.times.get(name, 0.0) + now - since
        return now


@dataclass
class _Start:
    """The iterate the homotopy starts from (after the restoration, if any)."""

    X: np.ndarray
    U: np.ndarray
    restored: newton.NewtonResult | None = None   # a converged restoration
    restore_iterations: int = 0
    F: object = None                             # DA stage maps at (X, U), if known


@dataclass
class _End:
    """The final iterate and how the solve ended."""

    X: np.ndarray
    U: np.ndarray
    maps: StageMaps | None
    converged: bool
    reason: str
    newton_iterations: int
    optimality: Optimality | None = None
    kkt_iterations: int = 0
    kkt_reason: str = ""
    restore_iterations: int = 0   # Newton's on the start (``SolverOptions.restore_start``)
    form: ThrottleForm | None = None   # the exact fuel form whose optimality is reported
    cost: float | None = None          # the objective solved, when not the last step's


def solve(problem: Problem, u_guess=None, method: Method | str = Method.DYN,
          fuel_optimal: bool | None = None, polish: bool = True,
          options: SolverOptions | None = None, case_name: str | None = None,
          progress=None) -> Solution:
    """Solve ``problem`` with DADDy.

    Args:
        problem: a ``Problem``.
        u_guess: (N, nu) initial controls, a ``Solution`` to warm-start from, or a
            ``WarmStart`` (controls, duals, rho, stage maps); None: 1e-6 everywhere.
        method: a ``Method`` or its name: std, hess, q, dyn, hessdyn, qdyn (paper Table 1).
        fuel_optimal: run the whole homotopy of ``options.homotopy`` (True; the default
            ``fuel.FUEL_HOMOTOPY`` when the options name only the energy step, and a DaddyError
            when the stage cost ignores ``hom``) or only its first, energy-optimal step
            (False). None: the whole homotopy when it has more than one step.
        polish: finish with the Newton polishing (Alg. 11) to ``options.tol_newton``.
        options: ``SolverOptions``.
        progress: callable receiving progress lines (or None; ``options.verbose``: print).
    Returns:
        a ``Solution``. A solve that fails returns ``converged=False`` with the reason and the
        best feasible-so-far iterate (never NaN).
    """
    opts = options or SolverOptions()
    method = Method.parse(method)
    if progress is None and opts.verbose:
        progress = print
    sol = _solve(problem, u_guess, method, fuel_optimal, polish, opts, case_name, progress)
    if problem.g_path is None:
        return sol

    def resolve(p: Problem, warm: WarmStart, o: SolverOptions) -> Solution:
        return _solve(p, warm, method, None, polish, o, case_name, progress)
    return path_exchange.hold(problem, sol, resolve, opts, progress)


def _solve(problem: Problem, u_guess, method: Method, fuel_optimal: bool | None, polish: bool,
           opts: SolverOptions, case_name: str | None, progress) -> Solution:
    """``solve`` without the path constraints' exchange step: one run from the guess."""
    warm = WarmStart.of(u_guess, problem.stage_dt, opts.carry_rho, problem.t_start)
    U0 = problem.check_guess(np.full((problem.N, problem.nu), 1e-6) if warm.U is None else warm.U)
    steps = homotopy_steps(problem, U0, opts, fuel_optimal)
    if problem.g_path is not None:
        why = violated_at_start(problem, U0[0], opts.tol_newton)
        if why is not None:
            return _unsolved(problem, U0, why, steps, method, case_name)
    clock = _Clock(opts.time_budget_s)
    stats = DDPStats()
    start = _warm_start(problem, U0, warm, opts, clock, progress)
    t0 = time.perf_counter()
    exact = _exact_wanted(problem, steps, polish, opts)
    hres = continuation(problem, start.X, start.U, steps[:1] if exact else steps, method, opts,
                        stats, clock.deadline, progress, rho=warm.rho, duals=warm.duals,
                        F=start.F, numbering=(0, len(steps)))
    clock.lap("ddp", t0)
    end = _finish(problem, hres, start, polish, opts, clock, progress)
    if exact:
        hres, end = _exact_end(problem, hres, end, start, steps, method, opts, stats, clock,
                               progress, warm.rho)
    else:
        hres, end = _pseudo_huber_end(problem, hres, end, steps, polish, method, opts, stats,
                                      clock, progress)
    return _assemble(problem, end, hres, steps, method, stats, clock, opts, case_name, polish)


def _pseudo_huber_end(problem: Problem, hres: HomotopyResult, end: _End, steps: tuple,
                      polish: bool, method: Method, opts: SolverOptions, stats: DDPStats,
                      clock: _Clock, progress) -> tuple[HomotopyResult, _End]:
    """The end game at the last homotopy step's own cost: the KKT polishing (``_kkt``) and, if
    it stalls, re-solves of the step (``_resolve``)."""
    end = _kkt(problem, end, hres.stages.hom, polish, opts, clock, progress)
    for _ in range(opts.kkt_resolves):
        if not _stalled_polishing(end, polish, opts, clock):
            break
        hres, end = _resolve(problem, hres, end, steps[-1], method, opts, stats, clock,
                             progress)
    return hres, end


def _warm_start(problem: Problem, U0, warm: WarmStart, opts: SolverOptions, clock: _Clock,
                progress) -> _Start:
    """The initial rollout (through the warm start's maps where they reach) and, with
    ``opts.restore_start``, Newton's restoration of feasibility."""
    maps = warm.maps
    if maps is not None and maps.N != problem.N:
        raise DaddyError(f"maps cover {maps.N} stages, the problem has {problem.N}")
    # a start for the Newton restoration only needs to be near (its residuals are exact): the
    # maps then serve stages up to map_reach radii
    reach = opts.map_reach if opts.restore_start else 1.0
    X = problem.rollout(U0) if maps is None else maps.rollout(problem, U0, reach)[0]
    t0 = clock.lap("rollout", clock.start)
    if not np.all(np.isfinite(X)):
        raise DaddyError("the initial guess propagates to a non-finite state")
    start = _Start(X, U0)
    if opts.restore_start:
        cold = maps is None and warm.duals is None
        res, start.restore_iterations = _restore(problem, X, U0, maps, cold, opts, clock,
                                                 progress)
        relaxed = False
        if not res.converged and problem.g_path is not None:
            # a start that meets everything but the path constraint: the augmented Lagrangian
            # takes it from there, where DDP from the raw guess would start far off (halo with
            # a 20,000 km keep-out from random guesses: restorations that dive inside the
            # sphere stall, and DDP from those guesses ran into the time cap)
            alt, n = _restore(replace(problem, g_path=None), X, U0, maps, cold, opts, clock,
                              progress)
            start.restore_iterations += n
            if alt.converged:
                res, relaxed = alt, True
        if res.converged:
            start.X, start.U = res.X, res.U
            if not relaxed:   # (a feasible iterate to fall back on)
                start.restored = res
            if res.maps is not None:
                # the DDP starts from the Newton model's maps, re-centred as Newton re-centres
                # them, with the restored flows as their values
                start.F = newton.exact_valued_maps(problem, res.maps, res.X, res.U, res.X[1:].T,
                                                   opts.map_reach)
        elif maps is not None and reach > 1:
            start.X = maps.rollout(problem, U0)[0]   # DDP starts from a consistent trajectory
        else:   # DDP starts from the guess, where Newton's first model expanded the stages
            start.F = res.start_F
        if progress:
            progress(f"start {'restored' if res.converged else 'not restored'} by Newton"
                     f"{' (without g_path)' if relaxed else ''}: "
                     f"{res.iterations} iterations, max violation {res.max_violation:.2e} "
                     f"({res.reason})")
    clock.lap("restore", t0)
    return start


def _restore(problem: Problem, X, U0, maps, cold: bool, opts: SolverOptions, clock: _Clock,
             progress) -> tuple[newton.NewtonResult, int]:
    """Newton's restoration of (X, U0) and, for a cold start it cannot restore, of the
    ballistic trajectory (``_restore_ballistic``): the result to start from and the Newton
    iterations spent."""
    res = newton.restore(problem, X, U0, opts, clock.deadline, maps=maps)
    spent = res.iterations
    if not res.converged and cold:
        ballistic = _restore_ballistic(problem, X, U0, res, opts, clock.deadline, progress)
        if ballistic is not None:
            spent += ballistic.iterations
            res = ballistic if ballistic.converged else res
    return res, spent


# a ballistic trajectory within this fraction of the state's size (max |x|, normalised units)
# of the guess's is the guess itself as far as the restoration can tell (``_restore_ballistic``;
# the catalogue's 1e-6 N guesses: <= 8e-4; the robustness harness's random guesses: >= 0.07)
_SAME_START_RTOL = 1e-2


def _restore_ballistic(problem: Problem, X, U0, stalled: newton.NewtonResult,
                       opts: SolverOptions, deadline: float | None,
                       progress) -> newton.NewtonResult | None:
    """A cold guess (X, U0) that Newton could not restore: Newton's restoration of the
    ballistic trajectory (zero control) instead, which DDP starts from if it converged (else
    DDP starts from the guess); None when skipped.

    Why: a random guess that thrusts into a region where the constraint model is poor (on
    DRO->DRO, a lunar flyby) stalls the restoration and then takes DDP's first
    augmented-Lagrangian solves through the same region, where they crawl to the time budget;
    the ballistic trajectory stays near the departure orbit, and its restoration converged on
    every such guess measured (DRO->DRO, halo). Skipped when the guess flies the ballistic
    trajectory already (the default 1e-6 guess), where it would only repeat the stall."""
    Ub = np.zeros_like(U0)
    Xb = problem.rollout(Ub)
    if (not np.all(np.isfinite(Xb))
            or np.max(np.abs(Xb - X)) <= _SAME_START_RTOL * np.max(np.abs(X))):
        return None
    res = newton.restore(problem, Xb, Ub, opts, deadline)
    if progress:
        progress(f"guess not restored ({stalled.reason}); ballistic start: {res.iterations} "
                 f"iterations, max violation {res.max_violation:.2e} ({res.reason})")
    return res


def _finish(problem: Problem, hres: HomotopyResult, start: _Start, polish: bool,
            opts: SolverOptions, clock: _Clock, progress) -> _End:
    """The homotopy's last finite iterate, or the restored warm start when the homotopy failed
    after a restoration, then the Newton polishing (Alg. 11)."""
    X, U, st = hres.X, hres.U, hres.stages
    maps = start.restored.maps if start.restored is not None else None
    if np.array_equal(st.X, X):
        maps = StageMaps.of(st.F, st.X, st.U, opts.eps_da)
    end = _End(X, U, maps, hres.converged, hres.reason, newton_iterations=0,
               restore_iterations=start.restore_iterations)
    fallback = start.restored is not None and not hres.converged
    if fallback:  # DDP did not finish: return the feasible, Newton-restored start
        end.X, end.U = start.restored.X, start.restored.U
        end.reason += "; returned the Newton-restored start"
    # a DDP that took no step from the Newton-restored start (ddp_stop_on_prediction) leaves a
    # trajectory that meets the constraints to tol_newton: polishing would repeat its residual
    untouched = (start.restored is not None and np.array_equal(end.X, start.restored.X)
                 and np.array_equal(end.U, start.restored.U))
    t0 = time.perf_counter()
    if polish and not fallback and not untouched and not hres.diverged:
        # fresh expansions unless asked otherwise (see SolverOptions.polish_from_ddp_maps)
        res = newton.polish(problem, end.X, end.U, opts, clock.deadline,
                            maps=end.maps if opts.polish_from_ddp_maps else None)
        end.newton_iterations += res.iterations
        if progress:
            progress(f"newton: {res.iterations} iterations, max violation {res.max_violation:.2e}"
                     f" ({res.reason})")
        if res.improved:
            end.X, end.U = res.X, res.U
            end.maps = res.maps or end.maps
        if not res.converged:   # (after a stalled AUL: the constraints cannot be met here)
            end.converged, end.reason = False, "; ".join(
                filter(None, (hres.stalled, f"newton polishing: {res.reason}")))
        clock.lap("newton", t0)
    else:
        clock.times.setdefault("newton", 0.0)
        if hres.stalled and end.converged:   # nothing else can meet the constraints
            end.converged, end.reason = False, hres.stalled
    t0 = time.perf_counter()
    if end.converged and math.isfinite(opts.tol_optimality):   # (of a feasible iterate only)
        end.optimality = optimality(problem, end.X, end.U, hres.stages.hom, end.maps)
    clock.lap("optimality", t0)
    return end


def _kkt(problem: Problem, end: _End, hom: tuple, polish: bool, opts: SolverOptions,
         clock: _Clock, progress) -> _End:
    """The KKT polishing (``kkt_polish``) of a polished, converged end whose KKT residual is
    above ``opts.tol_optimality``."""
    opt = end.optimality
    if not (polish and end.converged and opt is not None
            and opt.kkt_residual > opts.tol_optimality):
        return end
    t0 = time.perf_counter()
    res = kkt_polish(problem, end.X, end.U, hom, opts, opt, clock.deadline)
    clock.lap("kkt", t0)
    if progress:
        progress(f"KKT polishing: {res.iterations} iterations, KKT residual "
                 f"{opt.kkt_residual:.2e} -> {res.optimality.kkt_residual:.2e} ({res.reason})")
    end.X, end.U, end.optimality, end.maps = res.X, res.U, res.optimality, res.maps or end.maps
    end.newton_iterations += res.newton_iterations
    end.kkt_iterations += res.iterations
    end.kkt_reason = res.reason
    return end


# the stage cost's (h, delta) argument for the exact fuel form, whose cost ignores it
_EXACT = (1.0, 0.0)


def _exact_wanted(problem: Problem, steps: tuple, polish: bool, opts: SolverOptions) -> bool:
    """A polished fuel-optimal solve of a problem with an exact fuel form (``throttle``) whose
    options ask for it (``SolverOptions.exact_fuel``) and for a KKT residual."""
    return (opts.exact_fuel and polish and steps[-1][0] > 0
            and math.isfinite(opts.tol_optimality) and has_throttle_form(problem))


def _exact_end(problem: Problem, hres: HomotopyResult, end: _End, start: _Start, steps: tuple,
               method: Method, opts: SolverOptions, stats: DDPStats, clock: _Clock, progress,
               rho: float | None) -> tuple[HomotopyResult, _End]:
    """The end game of a fuel-optimal solve whose continuation ran the first homotopy step only
    (``hres``, polished to ``end``), three tries, each from a feasible end and kept when it
    meets tol_optimality: the KKT polishing of the exact fuel form (``throttle``) from there,
    stopped when it stalls (``exact_fuel_stall_iter``); the same from the end of the rest of
    the homotopy (``homotopy.resume``; ``exact_fuel_end_stall_iter``); the pseudo-Huber end
    game of that last step (``_pseudo_huber_end``), whose result stands whatever it reaches.

    Why: from the energy optimum the exact form converged on every catalogue case but two, in
    12-23 KKT iterations (GTO->GEO: 95), at the optima the whole homotopy reaches (Earth-Mars,
    halo, DRO, DRO 2 revolutions, NRHO: the same masses), and it skips the pseudo-Huber steps
    whose DDP crawls at the kink on the Earth-centred transfers (LEO->LEO: 93 s of CPU in all,
    where the homotopy was unconverged after 30 minutes); on the Lyapunov and DRO
    3-revolution transfers it creeps (the residual 0.115 -> 0.101 in 100 iterations) where the
    homotopy's path leads to the optimum (DRO 3 revolutions: the exact form from there
    converges in 15 iterations). On Lyapunov it creeps from the homotopy's end too (3.1e-4
    after 100 iterations, a resumed homotopy's end; the end of one continuation over all
    steps meets tol_optimality as it is), and the pseudo-Huber end game is what converges."""
    if len(steps) > 1:
        spent = end   # (the work so far, counted in the end of the rest of the homotopy)
        if end.converged:
            spent = _exact_fuel(problem, end, opts, clock, progress, opts.exact_fuel_stall_iter)
            if _meets_tol(spent, opts):
                return hres, spent
        if progress:
            progress("the rest of the homotopy from the first step's solution")
        t0 = time.perf_counter()
        hres = resume(problem, hres, steps[1:], method, opts, stats, clock.deadline, progress,
                      rho)
        clock.lap("ddp", t0)
        end = _finish(problem, hres, start, True, opts, clock, progress)
        end.newton_iterations += spent.newton_iterations
        end.kkt_iterations += spent.kkt_iterations
    if end.converged:
        tried = _exact_fuel(problem, end, opts, clock, progress, opts.exact_fuel_end_stall_iter)
        if _meets_tol(tried, opts):
            return hres, tried
        end.newton_iterations, end.kkt_iterations = tried.newton_iterations, tried.kkt_iterations
    return _pseudo_huber_end(problem, hres, end, steps, True, method, opts, stats, clock,
                             progress)


def _meets_tol(end: _End, opts: SolverOptions) -> bool:
    """A feasible end whose KKT residual is at most tol_optimality."""
    return (end.converged and end.optimality is not None
            and end.optimality.kkt_residual <= opts.tol_optimality)


def _exact_fuel(problem: Problem, end: _End, opts: SolverOptions, clock: _Clock, progress,
                stall_iter: int) -> _End:
    """A copy of the feasible, polished ``end`` KKT-polished in the exact fuel form
    (``throttle``: thrust as throttle and direction): its thrust, the form's optimality, fresh
    stage maps of ``problem`` and the exact propellant cost."""
    t0 = time.perf_counter()
    form = throttle_form(problem, end.U)
    fuel = form.problem
    V = form.controls(end.U)
    opt = optimality(fuel, end.X, V, _EXACT)
    if opt is None:
        clock.lap("kkt", t0)
        return replace(end, converged=False, reason="the exact fuel problem's KKT residual "
                       "could not be evaluated at the homotopy's end")
    res = kkt_polish(fuel, end.X, V, _EXACT, opts.with_(kkt_max_iter=opts.exact_fuel_max_iter),
                     opt, clock.deadline, stall_iter)
    if progress:
        progress(f"exact fuel (throttle and direction): {res.iterations} KKT iterations, "
                 f"residual {opt.kkt_residual:.2e} -> {res.optimality.kkt_residual:.2e} "
                 f"({res.reason})")
    U = form.thrust(res.U)
    clock.lap("kkt", t0)
    return replace(
        end, X=res.X, U=U, optimality=res.optimality,
        maps=StageMaps.of(expand_dynamics(problem, res.X[:-1], U), res.X, U, opts.eps_da),
        newton_iterations=end.newton_iterations + res.newton_iterations,
        kkt_iterations=end.kkt_iterations + res.iterations, kkt_reason=res.reason, form=form,
        cost=objective(fuel, res.X, res.U, _EXACT))


def _stalled_polishing(end: _End, polish: bool, opts: SolverOptions, clock: _Clock) -> bool:
    """A feasible, polished end whose KKT polishing stopped above tol_optimality, with time
    left for ``_resolve``."""
    opt = end.optimality
    return (polish and end.converged and opt is not None
            and opt.kkt_residual > opts.tol_optimality
            and (clock.deadline is None or time.perf_counter() < clock.deadline))


def _resolve(problem: Problem, hres: HomotopyResult, end: _End, hom: tuple, method: Method,
             opts: SolverOptions, stats: DDPStats, clock: _Clock,
             progress) -> tuple[HomotopyResult, _End]:
    """The last homotopy step ``hom`` solved again (AUL + DDP, Newton, KKT polishing) from
    the KKT-polished end with its least-squares KKT multipliers; the new end is kept when it
    improves on it (``_improves``), else the old one (the work is counted either way).

    Why: the AUL ends a homotopy step when DDP meets its relative-decrease test with the
    constraints met, which on a flat stretch of the fuel cost happens far from stationarity
    (a halo solve from a random guess: KKT residual 0.18 after the last step's single AUL
    solve of 43 DDP iterations), and the KKT polishing, a local Newton method, then creeps
    (30 iterations: 0.18 -> 0.12, each restored to feasibility after a shifted step that
    changes the active set). DDP is the globalised method: from the polished iterate and
    with the KKT multipliers it starts where its first solve stopped, minimising the
    Lagrangian the KKT conditions are about, and the polishing then starts near the KKT
    point (that halo solve: 8 AUL solves, 3.7 s, then 3 KKT iterations to 4.4e-7)."""
    if progress:
        progress(f"KKT polishing stalled at {end.optimality.kkt_residual:.2e}: the last homotopy"
                 " step again from the polished iterate with its KKT multipliers")
    t0 = time.perf_counter()
    again = continuation(problem, end.X, end.U, (hom,), method, opts, stats, clock.deadline,
                         progress, duals=_duals(problem, end.X, end.U, end.optimality, hres,
                                                opts))
    clock.lap("ddp", t0)
    new = _kkt(problem, _finish(problem, again, _Start(end.X, end.U), True, opts, clock,
                                progress), hom, True, opts, clock, progress)
    new.newton_iterations += end.newton_iterations
    new.kkt_iterations += end.kkt_iterations
    new.restore_iterations = end.restore_iterations
    counted = dict(aul_iterations=hres.aul_iterations + again.aul_iterations,
                   history=hres.history + [dict(h, resolve=True) for h in again.history])
    if not _improves(problem, hom, new, end):
        end.newton_iterations, end.kkt_iterations = new.newton_iterations, new.kkt_iterations
        return replace(hres, **counted), end
    return replace(again, gains=again.gains or hres.gains, converged=hres.converged,
                   reason=hres.reason, stalled=hres.stalled, **counted), new


def _improves(problem: Problem, hom: tuple, new: _End, old: _End) -> bool:
    """A re-solved end (``_resolve``) replaces the KKT-polished one when it is feasible with a
    smaller KKT residual at no higher cost (the objective at ``hom``). The residual alone is not
    enough far from a KKT point: a LEO->LEO fuel re-solve (1800 s, with a homotopy change since
    reverted) ended at a cost of 29.21 (956.80 kg) where the polished end's was below the last
    AUL solve's 27.64 (the polishing only lowers it), and replaced it for a residual of 1.45
    against 1.57."""
    return (new.converged and new.optimality is not None
            and new.optimality.kkt_residual < old.optimality.kkt_residual
            and objective(problem, new.X, new.U, hom) <= objective(problem, old.X, old.U, hom))


def _assemble(problem: Problem, end: _End, hres: HomotopyResult, steps: tuple, method: Method,
              stats: DDPStats, clock: _Clock, opts: SolverOptions, case_name: str | None,
              polish: bool) -> Solution:
    """The Solution of the final iterate: figures of merit, the DOP853 re-propagation check,
    timings, and what a warm start needs."""
    X, U, converged, reason = end.X, end.U, end.converged, end.reason
    violations = problem.violation_report(X, U)   # one evaluation of the constraints
    gmax = largest(0.0, *(r["violation"] for r in violations))
    if not polish and not gmax <= opts.tol_aul:   # (NaN: not converged)
        converged = False
    N, nu, nx = problem.N, problem.nu, problem.nx
    t0 = time.perf_counter()
    miss = repropagation_miss(problem, U, X, end.maps)
    clock.lap("repropagation", t0)
    if miss is not None and not math.isfinite(miss):
        converged, reason = False, "the DOP853 re-propagation of the final controls failed"
    if not converged:   # say which constraints the returned iterate does not meet
        worst = [r for r in violations[:3] if r["violation"] > opts.tol_newton]
        if worst:
            reason += "; largest violations: " + ", ".join(_describe(r) for r in worst)
    opt = end.optimality
    if polish and converged and math.isfinite(opts.tol_optimality) and (
            opt is None or opt.kkt_residual > opts.tol_optimality):
        converged = False
        reason = ("the KKT residual could not be evaluated" if opt is None else
                  f"KKT residual {opt.kkt_residual:.2e} above tol_optimality "
                  f"{opts.tol_optimality:g} after {end.kkt_iterations} KKT iterations "
                  f"({end.kkt_reason})")
    t = clock.times
    gains = hres.gains
    return Solution(
        **_described(problem, X, U, steps, method, case_name, end.cost), converged=converged,
        reason=reason,
        gains_a=gains.a if gains else np.zeros((N, nu)),
        gains_b=gains.b if gains else np.zeros((N, nu, nx)), max_violation=gmax,
        kkt_residual=None if opt is None else opt.kkt_residual, repropagation_miss=miss,
        iterations={"restore": end.restore_iterations, "homotopy": len(hres.history),
                    "aul": hres.aul_iterations, "ddp": stats.iterations,
                    "newton": end.newton_iterations, "kkt": end.kkt_iterations},
        runtime_s={"total": time.perf_counter() - clock.start, "rollout": t["rollout"],
                   "restore": t["restore"], "ddp": t["ddp"], "newton": t["newton"],
                   "forward": stats.forward_s, "expansion": stats.expansion_s,
                   "backward": stats.backward_s, "repropagation": t["repropagation"],
                   "optimality": t["optimality"], "kkt": t.get("kkt", 0.0)},
        history=hres.history, polynomial_share=stats.polynomial_share,
        violations=violations,
        duals=_duals(problem, X, U, opt, hres, opts, end.form), rho=float(hres.rho),
        stage_maps=end.maps)


def _described(problem: Problem, X: np.ndarray, U: np.ndarray, steps: tuple, method: Method,
               case_name: str | None, cost: float | None = None) -> dict:
    """The Solution fields that describe (X, U) of ``problem`` whatever the solve did: what
    was solved, the trajectory, its cost (``cost``, the objective solved, or at the last
    homotopy step) and its mass figures."""
    m, units = problem.mass_index, problem.units
    return dict(
        case=case_name or problem.name, method=method.value,
        fuel_optimal=len(steps) > 1 or (steps[0][0] > 0), X=X, U=U,
        stage_dt=problem.stage_dt.copy(), t_start=problem.t_start,
        time_index=problem.time_index,
        cost=objective(problem, X, U, steps[-1]) if cost is None else cost,
        final_mass_kg=float(X[-1, m] * units.mu_kg) if m is not None else None,
        propellant_kg=float((X[0, m] - X[-1, m]) * units.mu_kg) if m is not None else None,
        units=units.as_dict())


def _unsolved(problem: Problem, U0: np.ndarray, reason: str, steps: tuple, method: Method,
              case_name: str | None) -> Solution:
    """The Solution of a problem refused before any iteration (``converged=False``, the reason):
    the guess's own rollout (finite: ``_warm_start`` checks it the same way)."""
    X = problem.rollout(U0)
    if not np.all(np.isfinite(X)):
        raise DaddyError("the initial guess propagates to a non-finite state")
    violations = problem.violation_report(X, U0)
    N, nu, nx = problem.N, problem.nu, problem.nx
    return Solution(
        **_described(problem, X, U0, steps, method, case_name), converged=False, reason=reason,
        gains_a=np.zeros((N, nu)), gains_b=np.zeros((N, nu, nx)),
        max_violation=largest(0.0, *(r["violation"] for r in violations)),
        repropagation_miss=None, violations=violations,
        iterations={"restore": 0, "homotopy": 0, "aul": 0, "ddp": 0, "newton": 0, "kkt": 0},
        runtime_s={"total": 0.0})


def _duals(problem: Problem, X, U, opt: Optimality | None, hres: HomotopyResult,
           opts: SolverOptions, form: ThrottleForm | None = None) -> dict:
    """The multipliers a warm start from this solution takes: the least-squares KKT
    multipliers of the returned (X, U) (``optimality``) when they were evaluated, else those
    the last AUL solve ran with.

    Why: an AUL whose penalty grows ends with multipliers that lag the problem's by the
    penalty's share mu g, and one that starts from a Newton-restored feasible trajectory can
    meet tol_aul with them still at zero: a LEO plan's terminal multipliers were 0 where
    the KKT ones are -106, 281, -197, ..., and each of its warm re-plans spent two more AUL
    solves (of three) learning them. An inequality inactive at (X, U) (below -newton_active_tol)
    gets 0, as complementarity wants (the least-squares ones are only small there, and the
    augmented cost of eq. 8 turns a positive multiplier into a penalty on the whole stage)."""
    if opt is None:
        return hres.mult.as_duals()
    if form is not None:   # opt is the exact fuel form's: its rows, less the throttle bound's
        problem, U = form.problem, form.controls(U)
    g, ni, gt, nti = problem.constraint_values(X, U)
    nc, nt = (0 if g is None else g.shape[0]), (0 if gt is None else gt.shape[0])
    split = opt.constraint_multipliers(problem.N, problem.nx, nc, nt)
    if split is None or not np.all(np.isfinite(opt.multipliers)):
        return hres.mult.as_duals()
    lam, lam_t = split
    if nc:
        lam[:ni][g[:ni] < -opts.newton_active_tol] = 0.0
    if nt:
        lam_t[:nti][gt[:nti] < -opts.newton_active_tol] = 0.0
    if form is not None:
        lam = form.stage_duals(lam)
    return {"lam": lam.tolist(), "lam_t": lam_t.tolist()}
