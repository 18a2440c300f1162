"""DADDy orchestration (paper Fig. 1): fuel homotopy -> augmented Lagrangian -> DDP, then Newton
polishing; validation of inputs before any iteration; the Solution with its figures."""
from __future__ import annotations

import math
import time

import numpy as np

from ..errors import DaddyError
from ..integrators import dop853
from .aul import aul
from .ddp import DDPStats
from .expansion import Multipliers, StageMaps, max_violation, total_violation
from .newton import MAP_REACH, exact_valued_maps, polish as newton_polish
from .options import SolverOptions, parse_method
from .solution import Solution


def validate(problem, U0: np.ndarray) -> np.ndarray:
    """Check the initial guess and that every problem function returns finite values of the
    right shape at it, before any iteration. Returns U0 as a float (N, nu) array."""
    N, nu, nx = problem.N, problem.nu, problem.nx
    try:
        raw = np.asarray(U0)
        if raw.dtype.kind not in "iuf":   # no silent casts of complex, bool, text or objects
            raise TypeError(f"dtype {raw.dtype}")
        U0 = raw.astype(float)
    except (TypeError, ValueError) as exc:
        raise DaddyError(f"u_guess must be a real numeric array of shape (N, nu) = ({N}, {nu}):"
                         f" {exc}") from exc
    if U0.shape != (N, nu):
        raise DaddyError(f"u_guess must have shape (N, nu) = ({N}, {nu}), got {U0.shape}")
    if not np.all(np.isfinite(U0)):
        raise DaddyError("u_guess contains NaN or inf")
    if problem.spacecraft is not None and problem.mass_index is not None:
        m = problem.x0[problem.mass_index] * problem.units.mu_kg
        if m <= problem.spacecraft.dry_mass_kg:
            raise DaddyError(f"x0 mass ({m:.6g} kg) must exceed the dry mass "
                             f"({problem.spacecraft.dry_mass_kg:.6g} kg)")
    x = np.tile(problem.x0[:, None], (1, 2))
    u = U0[:2].T if N >= 2 else np.tile(U0[0][:, None], (1, 2))
    dt = problem.stage_dt[:2] if N >= 2 else np.repeat(problem.stage_dt, 2)
    checks = {
        "step": lambda: problem.step(x, u, dt),
        "stage_cost": lambda: problem.stage_cost(x, u, dt, (0.0, 1.0)),
        "path constraints": lambda: problem.path_constraints(x, u, dt)[0],
        "terminal_cost": lambda: problem.terminal_cost(problem.x0, problem.x_target),
        "terminal constraints": lambda: problem.terminal_constraints(problem.x0)[0],
    }
    shapes = {"step": (nx, 2), "stage_cost": (2,)}
    for name, fn in checks.items():
        try:
            val = fn()
        except DaddyError:
            raise
        except Exception as exc:  # a user function failing is reported as bad input
            raise DaddyError(f"problem {name} raised {type(exc).__name__}: {exc}") from exc
        if val is None:
            continue
        val = np.asarray(val, dtype=float)
        if name in shapes and val.shape != shapes[name]:
            raise DaddyError(f"problem {name} returned shape {val.shape}, expected {shapes[name]}")
        if not np.all(np.isfinite(val)):
            raise DaddyError(f"problem {name} returned NaN or inf at the initial guess")
    return U0


def repropagation_miss(problem, U: np.ndarray) -> float | None:
    """Terminal miss (max terminal-constraint violation) after re-propagating U from x0 with
    DOP853 at rtol = atol = 1e-12, stage by stage (``integrators.dop853``: solve_ivp's scheme and
    step control, 3x cheaper); inf when the re-propagation fails (NaN or inf dynamics).

    Each stage's first trial step is the whole stage (scipy's initial-step heuristic costs two
    rhs calls and usually picks a step that needs more steps: halo 62 -> 41 ms, Earth-Mars 24 ->
    18 ms per check with solve_ivp); the error control still accepts only steps within the
    tolerances."""
    if problem.rhs is None:
        x = problem.rollout(U)[-1]
    else:
        x = problem.x0.copy()
        try:
            for k in range(problem.N):
                x = dop853(problem.rhs, x, U[k], 0.0, problem.stage_dt[k], rtol=1e-12,
                           atol=1e-12)
        except DaddyError:
            return math.inf
    gt, nti = problem.terminal_constraints(x)
    if gt is None:
        return None
    return max_violation(gt, nti)


def objective(problem, X, U, hom) -> float:
    """The problem's own cost sum l + phi (no augmented-Lagrangian terms)."""
    return float(np.sum(problem.stage_cost(X[:-1].T, U.T, problem.stage_dt, hom))
                 + problem.terminal_cost(X[-1], problem.x_target))


def solve(problem, u_guess=None, method: str = "dyn", fuel_optimal: bool | None = None,
          polish: bool = True, options: SolverOptions | None = None, case_name: str | None = None,
          progress=None, duals: dict | None = None, rho: float | None = None,
          maps: StageMaps | None = None) -> Solution:
    """Solve ``problem`` with DADDy.

    Args:
        problem: a ``Problem``.
        u_guess: (N, nu) initial controls, or a ``Solution`` to warm-start from (its U).
        method: one of std, hess, q, dyn, hessdyn, qdyn (paper Table 1).
        fuel_optimal: run the whole homotopy of ``options.homotopy`` (True) or only its first,
            energy-optimal step (False). None: True when the homotopy has more than one step.
        polish: finish with the Newton polishing (Alg. 11) to ``options.tol_newton``.
        options: ``SolverOptions``.
        progress: callable receiving progress lines (or None).
        duals: warm-start multipliers {"lam": (n_c, N), "lam_t": (n_t,)} (default: those of a
            Solution given as ``u_guess``, when their shapes fit).
        rho: warm-start Quu regularisation (default: that of a Solution given as ``u_guess``
            when ``options.carry_rho``, else ``options.rho_init``).
        maps: stage maps of a nearby trajectory with this problem's stages (default: those of
            a Solution given as ``u_guess`` when its stage durations are this problem's). The
            initial rollout then evaluates them where a stage lies inside their radius (Alg. 8)
            and the Newton restoration re-centres them instead of expanding.
    Returns:
        a ``Solution``. A solve that fails returns ``converged=False`` with the reason and the
        best feasible-so-far iterate (never NaN).
    """
    opts = options or SolverOptions()
    sweep, dyn = parse_method(method)
    if isinstance(u_guess, Solution):
        duals = duals if duals is not None else u_guess.duals
        if maps is None and np.array_equal(u_guess.stage_dt, problem.stage_dt):
            maps = u_guess.stage_maps
        if rho is None and opts.carry_rho:
            rho = u_guess.rho
        u_guess = u_guess.U
    if u_guess is None:
        u_guess = np.full((problem.N, problem.nu), 1e-6)
    U0 = validate(problem, u_guess)
    hom_seq = opts.homotopy if (fuel_optimal or (fuel_optimal is None and len(opts.homotopy) > 1)) \
        else opts.homotopy[:1]
    fuel = len(hom_seq) > 1 or (hom_seq[0][0] > 0)
    if progress is None and opts.verbose:
        progress = print
    t_start = time.perf_counter()
    deadline = None if opts.time_budget_s is None else t_start + opts.time_budget_s
    stats = DDPStats()
    if maps is not None and maps.N != problem.N:
        raise DaddyError(f"maps cover {maps.N} stages, the problem has {problem.N}")
    # a start for the Newton restoration only needs to be near (its residuals are exact): the
    # maps then serve stages up to MAP_REACH radii (Earth-Mars bench re-plan: all 38 stages
    # instead of 22, the other 16 integrated one by one; states within 1.1e-10 either way)
    reach = MAP_REACH if opts.restore_warm_start else 1.0
    X = problem.rollout(U0) if maps is None else maps.rollout(problem, U0, reach)[0]
    t_rollout = time.perf_counter() - t_start
    if not np.all(np.isfinite(X)):
        raise DaddyError("the initial guess propagates to a non-finite state")
    U = U0
    restored, restore_iters, F0, final_maps = None, 0, None, None
    t0 = time.perf_counter()
    if opts.restore_warm_start:
        # a feasible iterate first (Newton, Alg. 11), so that a solve stopped by its time budget
        # still returns a trajectory that meets every constraint
        pres = newton_polish(problem, X, U, opts, deadline, maps=maps)
        restore_iters = pres.iterations
        if pres.converged:
            X, U = pres.X, pres.U
            restored = (X, U)
            final_maps = pres.maps
            if pres.maps is not None:
                # the DDP starts from the Newton model's maps, re-centred as Newton re-centres
                # them (up to MAP_REACH radii: Earth-Mars re-plans, Jacobians within 1.5e-6 of
                # fresh expansions either way), with the restored flows as their values
                F0 = exact_valued_maps(problem, pres.maps, X, U, X[1:].T)
        elif maps is not None and reach > 1:
            X = maps.rollout(problem, U)[0]   # DDP starts from a consistent trajectory
        if progress:
            progress(f"warm start restored by Newton: {pres.iterations} iterations, max violation"
                     f" {pres.max_violation:.2e} ({pres.reason})")
    t_restore = time.perf_counter() - t0
    t_aul = time.perf_counter()
    best = (X, U)
    aul_iters = 0
    history = []
    converged = True
    reason = "converged"
    st = gains = None
    rho_last = opts.rho_init if rho is None else rho
    mult = Multipliers.initial(problem, opts.mu_init)
    if duals:
        lam, lam_t = np.asarray(duals.get("lam", []), float), np.asarray(duals.get("lam_t", []), float)
        if lam.shape == mult.lam.shape and lam_t.shape == mult.lam_t.shape and \
                np.all(np.isfinite(lam)) and np.all(np.isfinite(lam_t)):
            mult.lam[...] = lam
            mult.lam_t[...] = lam_t
    for i, hom in enumerate(hom_seq):
        if progress:
            progress(f"homotopy {i + 1}/{len(hom_seq)}: h = {hom[0]}, delta = {hom[1]}")
        # each homotopy step is warm-started: controls and duals carry over, penalties restart
        mult.mu[...] = opts.mu_init
        mult.mu_t[...] = opts.mu_init
        res = aul(problem, X, U, mult, hom, sweep, dyn, opts, stats, deadline, progress,
                  rho0=rho, F=F0 if st is None else st.F)
        gains = res.gains or gains
        rho_last = res.rho
        aul_iters += res.iterations
        st = res.stages
        mult = res.mult
        X, U = st.X, st.U
        if np.all(np.isfinite(X)) and np.all(np.isfinite(U)):
            best = (X, U)
        history.append({"h": hom[0], "delta": hom[1], "aul_iterations": res.iterations,
                        "max_violation": res.max_violation, "cost": st.cost,
                        "converged": res.converged, "reason": res.reason})
        if not res.converged:
            converged, reason = False, f"homotopy step {i + 1}: {res.reason}"
            if res.reason == "time budget exceeded":
                break
    t_ddp = time.perf_counter() - t_aul
    X, U = best
    if st is not None and np.array_equal(st.X, X):
        final_maps = StageMaps.of(st.F, st.X, st.U, opts.eps_da)
    fallback = restored is not None and not converged
    if fallback:  # DDP did not finish: return the feasible, Newton-restored warm start
        X, U = restored
        reason += "; returned the Newton-restored warm start"
    newton_iters, t_newton = restore_iters, 0.0
    # a DDP that took no step from the Newton-restored start (ddp_stop_on_prediction) leaves a
    # trajectory that meets the constraints to tol_newton: polishing would repeat its residual
    untouched = (restored is not None and np.array_equal(X, restored[0])
                 and np.array_equal(U, restored[1]))
    if polish and not fallback and not untouched:
        t0 = time.perf_counter()
        # fresh expansions first unless asked otherwise: the Dyn pass's maps, re-centred again
        # and again, carry derivative errors (see SolverOptions.polish_from_ddp_maps)
        pres = newton_polish(problem, X, U, opts, deadline,
                             maps=final_maps if opts.polish_from_ddp_maps else None)
        t_newton = time.perf_counter() - t0
        newton_iters += pres.iterations
        if progress:
            progress(f"newton: {pres.iterations} iterations, max violation {pres.max_violation:.2e}"
                     f" ({pres.reason})")
        if pres.improved:
            X, U = pres.X, pres.U
            final_maps = pres.maps or final_maps
        if not pres.converged:
            converged = False
            reason = f"newton polishing: {pres.reason}"
    gmax = total_violation(problem, X, U)
    if not polish and gmax > opts.tol_aul:
        converged = False
    hom_last = hom_seq[-1]
    units = problem.units
    m_idx = problem.mass_index
    final_mass = float(X[-1, m_idx] * units.mu_kg) if m_idx is not None else None
    propellant = float((X[0, m_idx] - X[-1, m_idx]) * units.mu_kg) if m_idx is not None else None
    N, nu, nx = problem.N, problem.nu, problem.nx
    t0 = time.perf_counter()
    miss = repropagation_miss(problem, U)
    t_repro = time.perf_counter() - t0
    if miss is not None and not math.isfinite(miss):
        converged, reason = False, "the DOP853 re-propagation of the final controls failed"
    sol = Solution(
        case=case_name or problem.name, method=method, fuel_optimal=fuel, converged=converged,
        reason=reason, X=X, U=U, stage_dt=problem.stage_dt.copy(),
        gains_a=gains.a if gains else np.zeros((N, nu)),
        gains_b=gains.b if gains else np.zeros((N, nu, nx)),
        cost=objective(problem, X, U, hom_last), max_violation=gmax, final_mass_kg=final_mass,
        propellant_kg=propellant, repropagation_miss=miss,
        iterations={"homotopy": len(history), "aul": aul_iters, "ddp": stats.iterations,
                    "newton": newton_iters},
        runtime_s={"total": time.perf_counter() - t_start, "rollout": t_rollout,
                   "restore": t_restore, "ddp": t_ddp, "newton": t_newton,
                   "forward": stats.forward_s, "expansion": stats.expansion_s,
                   "backward": stats.backward_s, "repropagation": t_repro},
        history=history,
        units={"system": units.name, "lu_km": units.lu_km, "tu_s": units.tu_s,
               "mu_kg": units.mu_kg, "thrust_unit_n": units.thrust_unit_n},
        polynomial_share=stats.polynomial_share,
        duals={"lam": mult.lam.tolist(), "lam_t": mult.lam_t.tolist()},
        rho=float(rho_last), stage_maps=final_maps,
    )
    return sol
