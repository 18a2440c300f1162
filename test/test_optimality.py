"""First-order optimality: the KKT residual a solve reports, and the KKT polishing that drives
it below tol_optimality (daddy_core.solver.optimality, kkt_polish)."""
import json

import numpy as np
import pytest

from daddy_core.catalogue import load_case, problem_from_case
from daddy_core.solver import Solution, SolverOptions, case_options, solve
from daddy_core.solver.kkt_polish import kkt_polish
from daddy_core.solver.optimality import objective, optimality

DI = load_case("double_integrator")
HOM = (0.0, 1e-2)


def _di_optimum():
    """The double integrator's solution (its closed form: test_solver.di_closed_form)."""
    prob = problem_from_case(DI)
    return prob, solve(prob, np.zeros((prob.N, 3)), options=case_options(DI, False))


def _feasible_detour(prob, U, scale):
    """Controls moved off the optimum in a direction that keeps the terminal constraint: a
    mode of the Euler double integrator's (dt = 1) position map sum_k (N - 1 - k) u_k that sums
    to zero against it."""
    N = prob.N
    w = np.arange(N - 1, -1, -1, dtype=float)
    d = np.sin(np.arange(N))[:, None] * np.array([1.0, -0.5, 0.25])
    d -= np.outer(w, w @ d) / (w @ w)                      # w . d = 0 on every axis
    U2 = U + scale * d
    return prob.rollout(U2), U2


def test_the_residual_vanishes_at_the_optimum_and_not_beside_it():
    prob, sol = _di_optimum()
    assert sol.converged and sol.kkt_residual <= 1e-8
    X2, U2 = _feasible_detour(prob, sol.U, 1e-2)
    assert prob.violation(X2, U2) <= 1e-10                  # feasible, but not optimal
    assert objective(prob, X2, U2, HOM) > sol.cost
    assert optimality(prob, X2, U2, HOM).kkt_residual > 1e-3


def test_kkt_polishing_returns_to_the_optimum_feasible_and_never_costlier():
    """From a feasible detour, Newton on the KKT conditions returns to the closed-form optimum
    (to 1e-9 in the cost), every iterate feasible, in a few iterations (the problem is a QP:
    one step, up to the restoration)."""
    prob, sol = _di_optimum()
    X2, U2 = _feasible_detour(prob, sol.U, 5e-2)
    start = optimality(prob, X2, U2, HOM)
    opts = SolverOptions(kkt=dict(tol=1e-8))
    res = kkt_polish(prob, X2, U2, HOM, opts, start)
    assert res.converged and res.iterations <= 3
    assert prob.violation(res.X, res.U) <= 1e-10
    assert objective(prob, res.X, res.U, HOM) == pytest.approx(sol.cost, rel=1e-9)
    assert res.optimality.kkt_residual <= 1e-8


def test_a_kkt_steps_restoration_runs_while_newton_converges_fast_and_no_longer(monkeypatch):
    """Earth-Mars fuel-optimal: each KKT step's Newton restoration gets at most
    kkt.restore_iter iterations and stops once its residual has not halved over
    kkt.restore_stall_iter of them (Newton converges fast or not at all: design notes,
    restoration stall); with them the exact end game still lands on the transcription's
    603.5498 kg, feasible and KKT-converged."""
    from daddy_core.solver import kkt_polish as kp
    from daddy_core.solver.options import KKTOptions
    from daddy_core.solver.results import Status
    seen, real = [], kp.polish

    def spy(problem, X, U, opts, deadline=None, maps=None):
        res = real(problem, X, U, opts, deadline, maps=maps)
        seen.append((opts.newton.max_iter, opts.newton.stall_iter, res))
        return res

    monkeypatch.setattr(kp, "polish", spy)
    case = load_case("earth_mars")
    prob = problem_from_case(case)
    sol = solve(prob, case.cold_guess(prob.N), fuel_optimal=True,
                options=case_options(case, True))
    assert sol.converged and sol.final_mass_kg == pytest.approx(603.5498, abs=2e-3)
    kkt = KKTOptions()
    assert kkt.restore_stall_iter < kkt.restore_iter
    assert seen and all((m, st) == (kkt.restore_iter, kkt.restore_stall_iter)
                        for m, st, _ in seen)
    assert any(r.status is Status.NEWTON_STALLED for _, _, r in seen)   # the rule acted


def test_a_kkt_step_that_cannot_be_flown_refuses_its_shift_not_the_polishing(monkeypatch):
    """A KKT step whose point the stage integration cannot fly (on a small LEO raise a lightly
    shifted step left the elements' domain, NaN from a square root in the dynamics, and rk78
    raised) is refused like a step whose model failed: the next shift's shorter step is tried,
    and the polishing goes on from the point it reaches, feasible and cheaper (it stopped with
    "no KKT step lowered the cost")."""
    from daddy_core.errors import DaddyError
    from daddy_core.solver import kkt_polish as kp
    prob, sol = _di_optimum()
    X2, U2 = _feasible_detour(prob, sol.U, 5e-2)
    start = optimality(prob, X2, U2, HOM)
    restore, calls = kp._restore, []

    def unflyable_first(problem, model, X, U, *args):
        calls.append(1)
        if len(calls) == 1:
            raise DaddyError("rk78: dynamics returned NaN or inf")
        return restore(problem, model, X, U, *args)

    monkeypatch.setattr(kp, "_restore", unflyable_first)
    res = kkt_polish(prob, X2, U2, HOM, SolverOptions(kkt=dict(tol=1e-8, max_iter=5)), start)
    assert len(calls) >= 2                                  # a larger shift was tried
    assert res.iterations >= 1 and prob.violation(res.X, res.U) <= 1e-10
    assert objective(prob, res.X, res.U, HOM) < objective(prob, X2, U2, HOM)
    assert res.optimality.kkt_residual < start.kkt_residual


def test_infinite_tolerance_neither_evaluates_nor_polishes():
    prob = problem_from_case(DI)
    sol = solve(prob, np.zeros((prob.N, 3)),
                options=case_options(DI, False, kkt=dict(tol=np.inf)))
    assert sol.converged and sol.kkt_residual is None and sol.iterations["kkt"] == 0


def test_a_solve_that_cannot_reach_tol_optimality_says_so_and_keeps_its_best_iterate():
    """Earth-Mars energy-optimal: one KKT iteration cannot reach 1e-14; the solve is not
    converged, its reason names the KKT residual, and the iterate it returns is the polished
    one -- feasible, and no more costly than the DDP's."""
    case = load_case("earth_mars")
    prob = problem_from_case(case)
    u0 = np.full((prob.N, 3), float(case.units.thrust(case.solver["u_guess_n"])))
    ddp = solve(prob, u0, options=case_options(case, False, kkt=dict(tol=np.inf)))
    sol = solve(prob, u0, options=case_options(case, False, kkt=dict(tol=1e-14, max_iter=1),
                                               end_game=dict(resolves=0)))
    assert not sol.converged and "KKT residual" in sol.reason and "kkt_max_iter" in sol.reason
    assert sol.max_violation <= 1e-10 and np.all(np.isfinite(sol.U))
    assert sol.cost <= ddp.cost and sol.iterations["kkt"] == 1
    assert 1e-14 < sol.kkt_residual < 1e-4


@pytest.mark.parametrize("fuel", [False, True])
def test_a_stalled_kkt_polishing_hands_the_last_homotopy_step_back_to_ddp(fuel):
    """Earth-Mars with the KKT polishing switched off (kkt_max_iter=0: it stalls at once, as
    it does where its Newton steps creep) and the pseudo-Huber end game of the last homotopy
    step (exact_fuel=False: the end game of problems without an exact fuel form, and of those
    where it does not converge): each re-solve of the last homotopy step from the
    polished iterate with its KKT multipliers lowers the KKT residual (energy: 1e-2 -> 7e-4 ->
    1e-4 measured), one re-solve takes the fuel-optimal solve to tol_optimality, every end is
    feasible, and the re-solves' AUL iterations are counted and marked in the history."""
    case = load_case("earth_mars")
    prob = problem_from_case(case)
    runs = {n: solve(prob, None, fuel_optimal=fuel, options=case_options(
        case, fuel, kkt=dict(max_iter=0), end_game=dict(resolves=n, exact_fuel=False)))
        for n in (0, 1, 3)}
    for n, sol in runs.items():
        assert sol.max_violation <= 1e-10 and np.all(np.isfinite(sol.U))
        assert sum(bool(h.get("resolve")) for h in sol.history) == (0 if n == 0 else
                                                                    len(sol.history) - (4 if fuel else 1))
    assert not runs[0].converged and runs[0].kkt_residual > 1e-4
    assert runs[1].kkt_residual < runs[0].kkt_residual
    assert runs[3].kkt_residual <= runs[1].kkt_residual
    assert runs[1].iterations["aul"] > runs[0].iterations["aul"]
    if fuel:
        assert runs[1].converged and runs[1].final_mass_kg == pytest.approx(603.465, abs=1e-3)
    else:
        assert runs[3].kkt_residual < 0.1 * runs[0].kkt_residual


def test_a_re_solve_replaces_the_polished_end_only_when_no_costlier():
    """``end_game.improves``: a re-solve of the last homotopy step replaces the KKT-polished end
    when it is feasible with a smaller KKT residual at no higher cost. Far from a KKT point
    the residual alone misleads: LEO->LEO fuel kept a re-solve that ended at a cost of 29.21
    (956.80 kg) over a polished end below 27.64 for a residual of 1.45 against 1.57."""
    from daddy_core.solver.optimality import Optimality
    from daddy_core.solver.end_game import End, improves
    prob, sol = _di_optimum()
    X2, U2 = _feasible_detour(prob, sol.U, 5e-2)            # feasible, costlier

    def end(X, U, kkt, converged=True):
        return End(X, U, None, converged, "",
                   optimality=Optimality(kkt, 0.0, np.zeros(1), np.zeros(1)))
    assert objective(prob, X2, U2, HOM) > objective(prob, sol.X, sol.U, HOM)
    assert improves(prob, HOM, end(sol.X, sol.U, 0.5), end(X2, U2, 1.0))
    assert not improves(prob, HOM, end(X2, U2, 0.5), end(sol.X, sol.U, 1.0))   # costlier
    assert not improves(prob, HOM, end(sol.X, sol.U, 1.0), end(X2, U2, 0.5))   # residual
    assert not improves(prob, HOM, end(sol.X, sol.U, 0.5, False), end(X2, U2, 1.0))


def test_the_residual_round_trips_and_older_solutions_load():
    _, sol = _di_optimum()
    d = json.loads(sol.to_json())
    assert d["kkt_residual"] == sol.kkt_residual
    assert Solution.from_json(sol.to_json()).kkt_residual == sol.kkt_residual
    del d["kkt_residual"]   # a plan saved before the field existed
    assert Solution.from_dict(d).kkt_residual is None
