"""The exact fuel form (``daddy_core.throttle``): thrust as throttle and direction, the
propellant linear in the throttle, and the fuel-optimal solves that end in it."""
from pathlib import Path

import numpy as np
import pytest

from daddy_core.catalogue import load_case, problem_from_case
from daddy_core.fuel import PseudoHuberCost
from daddy_core.solver import case_options, solve
from daddy_core.throttle import LABEL, has_throttle_form, intermediate_stages, throttle_form

# copies of ../shared/reference (independent CasADi + IPOPT solutions), kept with the tests
DATA = Path(__file__).with_name("data")
EARTH_MARS = load_case("earth_mars")


def _random_thrust(problem, rng, coast=0.3):
    """(N, 3) thrust of random directions and magnitudes up to the bound, a share coasting."""
    N = problem.N
    d = rng.normal(size=(N, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    s = rng.uniform(0.0, 1.0, N) * (rng.uniform(size=N) > coast)
    return d * (s * problem.u_max)[:, None]


def test_controls_and_thrust_are_inverse_and_the_pole_is_the_least_used_direction():
    prob = problem_from_case(load_case("leo_leo"))
    rng = np.random.default_rng(3)
    U = _random_thrust(prob, rng)
    U[:, 0] *= 1e-3                        # hardly any radial thrust (axis 0: R of RTN)
    form = throttle_form(prob, U)
    V = form.controls(U)
    np.testing.assert_allclose(form.thrust(V), U, rtol=0, atol=1e-15 * prob.u_max)
    assert np.all((V[:, 0] >= 0) & (V[:, 0] <= 1 + 1e-15))
    assert abs(form.frame[0, 0]) == pytest.approx(1.0, abs=1e-5)       # the pole: radial
    np.testing.assert_allclose(form.frame.T @ form.frame, np.eye(3), atol=1e-14)
    V[:5, 0] = -1e-12                      # (a throttle the polishing left below zero)
    assert np.all(form.thrust(V)[:5] == 0.0)


def test_the_form_flies_and_costs_as_the_original_at_the_same_thrust():
    """Same dynamics (the mass flow from |u| = u_max s exactly), the pseudo-Huber cost's
    h -> 1, delta -> 0 limit as stage cost, the original's constraints plus -s <= 0."""
    for name in ("earth_mars", "leo_leo_j2"):
        case = load_case(name)
        prob = problem_from_case(case, stages=40)
        rng = np.random.default_rng(7)
        U = _random_thrust(prob, rng)
        form = throttle_form(prob, U)
        fuel = form.problem
        V = form.controls(U)
        X = prob.rollout(U)
        np.testing.assert_allclose(fuel.rollout(V), X, rtol=1e-10, atol=1e-12)   # (RK78 at 1e-13)
        exact = fuel.stage_cost(X[:-1].T, V.T, prob.stage_dt)
        near = prob.stage_cost(X[:-1].T, U.T, prob.stage_dt, (1.0, 1e-9))
        np.testing.assert_allclose(exact, near, rtol=1e-6, atol=1e-12)
        g, ni, _, _ = fuel.constraint_values(X, V)
        g0, ni0, _, _ = prob.constraint_values(X, U)
        assert ni == ni0 + 1 and fuel.labels["g_ineq"][ni0] == LABEL
        np.testing.assert_allclose(g[:ni0], g0[:ni0], atol=1e-13)
        np.testing.assert_allclose(g[form.throttle_row], -V[:, 0])


def test_problems_without_what_the_form_needs_have_none():
    from test_solver import _rest_to_rest          # one control, a plain step function
    assert not has_throttle_form(_rest_to_rest())
    assert throttle_form(_rest_to_rest(), np.zeros((20, 1))) is None
    prob = problem_from_case(EARTH_MARS)
    assert has_throttle_form(prob)
    from dataclasses import replace
    assert not has_throttle_form(replace(prob, stage_cost=lambda x, u, dt, hom=(0, 1): u[0]))
    assert not has_throttle_form(replace(prob, u_max=None))
    assert isinstance(prob.stage_cost, PseudoHuberCost)


def test_earth_mars_fuel_optimal_is_the_true_fuel_optimum_of_the_oracle():
    """`daddy solve earth_mars --fuel`: the exact fuel end game lands on the independent
    transcription's true-propellant optimum (CasADi + IPOPT, |T| unsmoothed, 603.5498 kg) --
    the pseudo-Huber homotopy alone stops 0.08 kg short of it -- bang-bang (at most a switching
    stage between each thrust arc and coast), with the thrust per stage of the oracle's."""
    prob = problem_from_case(EARTH_MARS)
    sol = solve(prob, EARTH_MARS.cold_guess(prob.N), fuel_optimal=True,
                options=case_options(EARTH_MARS, True))
    assert sol.converged, sol.reason
    assert sol.max_violation <= 1e-10 and sol.kkt_residual <= 1e-4
    path = DATA / "earth_mars_fuel__cylindrical.csv"
    ref = np.loadtxt(path, delimiter=",", skiprows=1, max_rows=prob.N)   # (line 1: header)
    oracle_kg = float(path.read_text().splitlines()[-1].split(",")[8])   # 603.5498
    assert sol.final_mass_kg == pytest.approx(oracle_kg, abs=2e-3)
    thrust_n = EARTH_MARS.units.thrust_n(np.linalg.norm(sol.U, axis=1))
    assert np.median(np.abs(thrust_n - ref[:, 12])) <= 1e-4
    s = np.linalg.norm(sol.U, axis=1) / prob.u_max
    switches = np.count_nonzero(np.diff(s > 0.5))
    assert intermediate_stages(sol.U, prob.u_max, tol=1e-6) <= switches
    assert sol.cost == pytest.approx(np.sum(prob.stage_cost.propellant(
        sol.X[:-1].T, np.linalg.norm(sol.U, axis=1), prob.stage_dt)), rel=1e-9)
    # the duals a warm start takes are the original problem's (thrust bound, dry mass)
    assert np.asarray(sol.duals["lam"]).shape == (2, prob.N)


def test_a_warm_re_solve_from_the_exact_optimum_ends_there_again():
    """A fuel-optimal solve warm-started from its own solution (controls, duals, maps) ends
    at the same exact optimum (one DDP solve of the energy step, then the exact end game)."""
    prob = problem_from_case(EARTH_MARS)
    opts = case_options(EARTH_MARS, True)
    sol = solve(prob, EARTH_MARS.cold_guess(prob.N), fuel_optimal=True, options=opts)
    again = solve(prob, sol, fuel_optimal=True, options=opts)
    assert again.converged, again.reason
    assert again.final_mass_kg == pytest.approx(sol.final_mass_kg, abs=1e-3)


def test_a_users_own_dynamics_declared_as_thrust_get_the_exact_fuel_end_game():
    """Earth-Mars with the two-body dynamics written here, as a user would (numpy and the DA
    functions, the mass flow from ``thrust_norm``), the catalogue's costs and constraints:
    declared with ``thrust_dynamics`` the fuel solve ends in the exact fuel form at the
    independent transcription's optimum; the same function as a plain ``Dynamics`` has no
    exact form and ends at the pseudo-Huber optimum, below it."""
    from daddy_core.da import functions as dm
    from daddy_core.dynamics import Dynamics, thrust_dynamics, thrust_norm
    from daddy_core.problem import FlowStep

    c = EARTH_MARS.spacecraft.exhaust_speed(EARTH_MARS.units)   # normalised

    def rhs(t, x, u):                      # r'' = -r / |r|^3 + u / m,  m' = -|u| / c
        r3 = (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]) ** 1.5
        return dm.stack([x[3], x[4], x[5], u[0] / x[6] - x[0] / r3, u[1] / x[6] - x[1] / r3,
                         u[2] / x[6] - x[2] / r3, -thrust_norm(u) / c])

    base = problem_from_case(EARTH_MARS)
    oracle_kg = float((DATA / "earth_mars_fuel__cylindrical.csv").read_text()
                      .splitlines()[-1].split(",")[8])                  # 603.5498

    def users(dynamics):
        s = base.step
        step = FlowStep(dynamics, s.integrator, s.tol, s.rk4_steps, s.derivative_tol)
        return base.__class__(**{**{f: getattr(base, f) for f in base.__dataclass_fields__},
                                 "step": step, "rhs": dynamics})
    opts = case_options(EARTH_MARS, True)
    declared = users(thrust_dynamics(rhs))
    assert has_throttle_form(declared)
    sol = solve(declared, EARTH_MARS.cold_guess(base.N), fuel_optimal=True, options=opts)
    assert sol.converged and sol.exact_fuel, sol.reason
    assert sol.final_mass_kg == pytest.approx(oracle_kg, abs=2e-3)
    plain = users(Dynamics(rhs))
    assert not has_throttle_form(plain)
    smooth = solve(plain, EARTH_MARS.cold_guess(base.N), fuel_optimal=True, options=opts)
    assert not smooth.exact_fuel and smooth.final_mass_kg < sol.final_mass_kg
