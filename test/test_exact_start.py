"""The exact warm start (``solver.exact_start``): a warm re-plan of an exact fuel optimum from a
state off it is restored in the exact fuel form -- bang-bang, at the re-optimised propellant --
and a state its switching structure cannot reach falls back to the continuation."""
import numpy as np
import pytest

from daddy_core.catalogue import load_case, problem_from_case
from daddy_core.errors import DaddyError
from daddy_core.solver import SolverOptions, WarmStart, case_options, solve
from daddy_core.throttle import intermediate_stages

EARTH_MARS = load_case("earth_mars")
K = 6   # the re-plan starts at this stage of the optimum


@pytest.fixture(scope="module")
def optimum():
    """Earth-Mars fuel-optimal, solved cold (the exact end game): (problem, solution)."""
    prob = problem_from_case(EARTH_MARS)
    sol = solve(prob, EARTH_MARS.cold_guess(prob.N), fuel_optimal=True,
                options=case_options(EARTH_MARS, True))
    assert sol.converged, sol.reason
    return prob, sol


def _replan(prob, sol, dx: np.ndarray, **changes):
    """The remaining problem from stage K with its start moved by dx, solved warm from the
    optimum's tail with the guidance node's warm preset (``changes`` on top)."""
    sub = prob.with_x0(sol.X[K] + dx, prob.stage_dt[K:], prob.stage_t0[K])
    cold = case_options(EARTH_MARS, True)
    opts = SolverOptions.warm_replan(cold, 1e-5, 1e-4, restore_first=True).with_(**changes)
    lam = np.asarray(sol.duals["lam"])[:, K:]
    warm = WarmStart(sol.U[K:], {"lam": lam, "lam_t": sol.duals["lam_t"]}, sol.rho, None,
                     sol.X[K:])
    return sub, solve(sub, warm, options=opts)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_re_plan_off_the_optimum_is_bang_bang_at_the_re_optimised_propellant(optimum, seed):
    """Earth-Mars at stage 6, the state 1000 km / 1 m/s off (random directions): the warm
    re-plan is feasible, keeps the optimum's switching structure, and spends what the KKT
    polishing of the same problem to tol_optimality 1e-5 spends (to 1 g in 600 kg: the
    restoration's loss is second order in its correction)."""
    prob, sol = optimum
    rng = np.random.default_rng(seed)
    e1, e2 = rng.normal(size=3), rng.normal(size=3)
    dx = np.zeros(prob.nx)
    dx[:3] = EARTH_MARS.units.length(1e6) * e1 / np.linalg.norm(e1)
    dx[3:6] = EARTH_MARS.units.speed(1.0) * e2 / np.linalg.norm(e2)
    sub, warm = _replan(prob, sol, dx)
    assert warm.converged, warm.reason
    assert warm.max_violation <= 1e-9 and warm.repropagation_miss <= 1e-8
    assert intermediate_stages(warm.U, prob.u_max) <= intermediate_stages(sol.U[K:],
                                                                          prob.u_max) + 1
    _, polished = _replan(prob, sol, dx, kkt=dict(tol=1e-5))
    assert polished.converged and polished.kkt_residual <= 1e-5, polished.reason
    assert warm.final_mass_kg == pytest.approx(polished.final_mass_kg, abs=1e-3)
    assert warm.fuel_optimal and np.all(np.isfinite(warm.U))


def test_a_state_the_switching_structure_cannot_reach_falls_back_to_the_continuation(optimum):
    """200 m/s off the plan at stage 6: the plan's thrust arcs and coasts cannot absorb it in
    the exact start's Newton iterations; the solve goes on (restoration, DDP, Newton) and still
    returns a feasible plan."""
    prob, sol = optimum
    dx = np.zeros(prob.nx)
    dx[3:6] = EARTH_MARS.units.speed(200.0) * np.array([0.0, 1.0, 0.0])
    sub, warm = _replan(prob, sol, dx, end_game=dict(exact_start_iter=1))
    assert warm.iterations["homotopy"] >= 1      # the continuation ran
    assert warm.converged, warm.reason
    assert warm.max_violation <= 1e-9


def test_exact_start_options_are_checked():
    with pytest.raises(DaddyError, match="exact_start_iter"):
        SolverOptions(end_game=dict(exact_start_iter=0))
