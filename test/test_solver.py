"""The DADDy solver on the paper's validation cases, and its input checks."""
import json
import pathlib

import numpy as np
import pytest

from daddy_core.da import functions as dm
from daddy_core.errors import DaddyError
from daddy_core.problem import Problem
from daddy_core.catalogue import load_case, problem_from_case
from daddy_core.catalogue.infeasible import INFEASIBLE, double_integrator
from daddy_core.solver import METHODS, Solution, SolverOptions, case_options, solve
from daddy_core.solver.infeasibility import contradicted_end
from daddy_core.solver.optimality import optimality

DI = load_case("double_integrator")
# copies of ../shared/reference (independent CasADi + IPOPT solutions), kept with the tests
DATA = pathlib.Path(__file__).with_name("data")


def solve_case(name, method="dyn", fuel=False, **kw):
    case = load_case(name)
    prob = problem_from_case(case)
    u0 = np.full((prob.N, prob.nu), float(case.units.thrust(case.solver["u_guess_n"]))
                 if case.spacecraft else case.solver["u_guess_n"])
    return solve(prob, u0, method=method, fuel_optimal=fuel, options=case_options(case, fuel, **kw))


def di_closed_form():
    """Minimum of sum |u_k|^2 s.t. Euler double integrator reaches r_t: a least-norm problem."""
    N = DI.stages
    x0, xt = DI.x0, DI.x_target
    # r_N = r0 + N v0 + sum_k (N - 1 - k) u_k  (dt = 1)
    w = np.array([N - 1 - k for k in range(N)], dtype=float)
    rhs = xt[:3] - x0[:3] - N * x0[3:]
    # per axis: min |u|^2 s.t. w.u = rhs  ->  u = w rhs / |w|^2
    return float(np.sum(rhs ** 2) / (w @ w))


@pytest.mark.parametrize("method", METHODS)
def test_double_integrator_all_methods(method):
    sol = solve_case("double_integrator", method)
    assert sol.converged, sol.reason
    assert sol.cost == pytest.approx(1.1273, abs=5e-5)          # paper Table 2
    assert sol.cost == pytest.approx(di_closed_form(), rel=1e-9)
    assert sol.max_violation <= 1e-12
    assert sol.repropagation_miss <= 1e-12


def test_earth_mars_energy_dyn_matches_reference_oracle():
    """A solve whose KKT residual is within tol_optimality (1e-4; by DDP itself or with the
    KKT polishing) is at the optimum the independent direct transcription (CasADi + IPOPT)
    found: thrust within 2e-5 N of its 0.5 N bound's profile (measured: 1.6e-5 N where DDP
    ends at a residual of 4.5e-5, 1e-6 N after a polishing to 1.2e-6) and the final mass within
    1e-3 kg (the DDP stopped by tol_ddp alone, unchecked: 4.6e-4 N and 4e-3 kg off)."""
    sol = solve_case("earth_mars", "dyn")
    assert sol.converged, sol.reason
    assert sol.max_violation <= 1e-10 and sol.kkt_residual <= 1e-4
    assert sol.final_mass_kg == pytest.approx(556.413, abs=0.05)  # C++ reference / CasADi 556.41
    assert sol.repropagation_miss < 1e-8
    ref = np.loadtxt(DATA / "earth_mars_energy__cylindrical.csv", delimiter=",", skiprows=1,
                     max_rows=40)   # (line 1: the column header comment)
    m_final = float((DATA / "earth_mars_energy__cylindrical.csv").read_text().splitlines()[-1]
                    .split(",")[8])   # the last row: the final state, no thrust
    thrust = np.linalg.norm(sol.thrust_n, axis=1)
    # single optimum: the thrust profile agrees with the independent direct-transcription solve
    assert np.max(np.abs(thrust - ref[:, 12])) < 2e-5
    assert sol.final_mass_kg == pytest.approx(m_final, abs=1e-3)
    assert np.all(thrust <= 0.5 * (1 + 1e-9))
    unpolished = solve_case("earth_mars", "dyn", kkt=dict(tol=np.inf))
    assert unpolished.converged and unpolished.kkt_residual is None
    assert np.max(np.abs(np.linalg.norm(unpolished.thrust_n, axis=1) - ref[:, 12])) > 1e-4


@pytest.mark.slow
@pytest.mark.parametrize("method", [m for m in METHODS if m != "dyn"])
def test_earth_mars_energy_other_methods(method):
    sol = solve_case("earth_mars", method)
    assert sol.converged, sol.reason
    assert sol.final_mass_kg == pytest.approx(556.413, abs=0.05)


@pytest.mark.slow
@pytest.mark.parametrize("method", ["std", "dyn"])
def test_earth_mars_fuel(method):
    sol = solve_case("earth_mars", method, fuel=True)
    assert sol.converged, sol.reason
    assert 603.25 <= sol.final_mass_kg <= 603.56
    assert sol.max_violation <= 1e-10
    assert sol.repropagation_miss < 1e-8


# the paper's final masses (Table 9, Dyn column: m_N + 500 kg dry mass; three revolutions:
# its Hess / Q / QDyn columns, 995.55-995.56 kg -- the Std / Dyn columns' 996.86 kg is another
# optimum)
CR3BP_PAPER_KG = {"halo_l2_l1": 973.93, "dro_dro": 996.32, "lyapunov_l1_l2": 997.49,
                  "dro_dro_2rev": 996.77, "dro_dro_3rev": 995.56, "nrho_dro": 977.39}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(CR3BP_PAPER_KG))
def test_cr3bp_fuel_reaches_the_papers_mass_with_default_settings(name):
    """`daddy solve CASE --fuel --method dyn`: the case file's paper settings and the solver's
    defaults only (no per-case solver options)."""
    sol = solve_case(name, "dyn", fuel=True)
    assert sol.converged, sol.reason
    assert sol.final_mass_kg == pytest.approx(CR3BP_PAPER_KG[name], abs=0.5)
    assert sol.max_violation <= 1e-10


def test_solution_round_trips_and_warm_starts(tmp_path):
    sol = solve_case("double_integrator")
    again = Solution.from_json(sol.to_json())
    np.testing.assert_array_equal(again.U, sol.U)
    assert again.iterations == sol.iterations
    p = tmp_path / "s.npz"
    sol.to_npz(p)
    np.testing.assert_array_equal(Solution.from_npz(p).gains_b, sol.gains_b)
    d = json.loads(sol.to_json())
    for key in ("case", "method", "fuel_optimal", "converged", "final_mass_kg", "propellant_kg",
                "cost", "max_violation", "repropagation_miss", "iterations", "runtime_s", "X", "U"):
        assert key in d
    prob = problem_from_case(DI)
    warm = solve(prob, sol, method="dyn", options=case_options(DI, False))
    assert warm.converged and warm.iterations["ddp"] <= sol.iterations["ddp"]
    assert warm.cost == pytest.approx(sol.cost, rel=1e-9)


# the node's Earth-Mars nominal before its plans were solved in the exact fuel form: the last
# pseudo-Huber step's optimum at the derated bound (599.25 kg), thrust at every stage (none at
# zero): what the tests of stage maps and Newton steps below need (a coasting stage's map at
# zero thrust has a tiny radius)
SMOOTH_PLAN = pathlib.Path(__file__).parent / "data" / "earth_mars_pseudo_huber_plan.json"


def test_stage_maps_roll_out_and_restore_like_integration():
    # a smooth Earth-Mars plan's stage maps: a Dyn rollout (polynomials inside their radius)
    # follows the integrated one, and a Newton restoration from a perturbed start that
    # re-centres them ends as feasible as one that expands afresh
    from daddy_core.solver.stage_maps import StageMaps, expand_dynamics
    from daddy_core.solver.newton import polish
    case = load_case("earth_mars")
    prob = problem_from_case(case)
    plan = Solution.from_json(SMOOTH_PLAN)
    opts = case_options(case, True)
    maps = StageMaps.of(expand_dynamics(prob, plan.X[:-1], plan.U), plan.X, plan.U,
                        opts.eps_da)
    assert maps.N == prob.N and np.all(maps.radius > 0)
    X_int = prob.rollout(plan.U)
    X_dyn, served = maps.rollout(prob, plan.U)
    assert served == prob.N
    np.testing.assert_allclose(X_dyn, X_int, atol=1e-10)     # at the expansion point: exact
    U = plan.U * (1 + 1e-4)
    X_int, (X_dyn, served) = prob.rollout(U), maps.rollout(prob, U)
    assert served > prob.N // 2
    assert np.max(np.abs(X_dyn - X_int)) < 1e-4                # within eps_da per stage
    _, inside = maps.deviation(X_int, U)
    _, inside10 = maps.deviation(X_int, U, reach=10.0)         # SolverOptions.newton.map_reach
    assert inside.sum() < inside10.sum() and np.all(inside10[inside])
    X_far, served_far = maps.rollout(prob, U, reach=10.0)      # a start for the restoration
    assert served_far > served and np.max(np.abs(X_far - X_int)) < 1e-8   # (measured 6e-13)
    tail = maps.tail(3, first_valid=False)
    assert tail.N == prob.N - 3 and tail.radius[0] == 0 and tail.radius[1] == maps.radius[4]
    moved = prob.with_x0(plan.X[0] + np.r_[1e-6, -1e-6, 0, 0, 0, 0, 0])
    X0 = prob.rollout(plan.U, x0=moved.x0)
    fresh = polish(moved, X0, plan.U, opts)
    reused = polish(moved, X0, plan.U, opts, maps=maps)
    assert fresh.converged and reused.converged
    assert reused.max_violation <= opts.newton.tol
    assert isinstance(reused.maps, StageMaps)


def _earth_mars_plan_moved(dr_m: float, dv_m_s: float):
    """A smooth Earth-Mars fuel-optimal plan (``SMOOTH_PLAN``), and its problem started
    dr_m metres / dv_m_s m/s off the plan's first state (directions (0.6, -0.8, 0) and
    (0.6, 0.8, 0)) with the plan's controls rolled out from there: (plan, problem, X0, opts)."""
    case = load_case("earth_mars")
    prob = problem_from_case(case)
    plan = Solution.from_json(SMOOTH_PLAN)
    u = case.units
    moved = prob.with_x0(plan.X[0] + np.r_[u.length([0.6 * dr_m, -0.8 * dr_m, 0.0]),
                                           u.speed([0.6 * dv_m_s, 0.8 * dv_m_s, 0.0]), 0.0])
    return plan, moved, prob.rollout(plan.U, x0=moved.x0), case_options(case, True)


def test_weighted_newton_steps_keep_coasting_arcs_and_converge_in_one_iteration():
    # Earth-Mars nominal plan from a start 1000 km / 1 m/s off (the re-plan benchmark's size):
    # plain minimum-norm steps move the coasting stages' small controls and converge linearly
    # on their mass-flow model error; steps weighted by the thrust level do not
    from daddy_core.solver.newton import BandedSigma, ConstraintModel, column_weights, polish
    plan, moved, X0, opts = _earth_mars_plan_moved(1e6, 1.0)
    assert opts.newton.control_weight_floor == 1e-2            # the default
    plain = polish(moved, X0, plan.U, opts.with_(newton=dict(control_weight_floor=0.0)))
    weighted = polish(moved, X0, plan.U, opts)
    assert plain.converged and weighted.converged
    assert weighted.iterations <= 2 < plain.iterations
    coast = np.linalg.norm(plan.U, axis=1) < 1e-2 * moved.u_max
    assert coast.sum() >= 5
    moved_by = {name: np.max(np.linalg.norm(r.U - plan.U, axis=1)[coast])
                for name, r in (("plain", plain), ("weighted", weighted))}
    assert moved_by["weighted"] < 0.1 * moved_by["plain"]
    # the weighted step solves the same linearised constraints: D dY = -d
    model = ConstraintModel(moved, X0, plan.U, opts.newton.active_tol)
    d = model.residual()
    scale = column_weights(moved, plan.U, 1e-2)
    dY = BandedSigma(model.D, opts.newton.regularisation, scale).step(d)
    np.testing.assert_allclose(model.D @ dY, -d, atol=1e-9 * np.max(np.abs(d)))
    assert column_weights(moved, plan.U, 0.0) is None
    assert column_weights(problem_from_case(DI), np.ones((11, 3)), 1e-2) is None


@pytest.mark.parametrize("dr_m, dv_m_s, corrected", [(1e3, 1.0, False), (3e6, 3e3, True)])
def test_newton_corrects_a_step_that_its_second_order_term_undoes(dr_m, dv_m_s, corrected):
    """Earth-Mars nominal plan from a start dr_m / dv_m_s off: the Newton step meets the
    model's linearisation, and what is left at the full step is the model's second-order term.
    1 km / 1 m/s off that term is 1e-3 of the residual and the step is kept as it is; 3000 km
    / 3 km/s off it exceeds the residual itself, and the second-order correction on the same
    factorisation takes the full step below it (measured: 0.535 -> 1.07 uncorrected, 0.296
    corrected)."""
    from daddy_core.solver.newton import (BandedSigma, ConstraintModel, _corrected,
                                          _inner_iterations, column_weights)
    plan, moved, X0, opts = _earth_mars_plan_moved(dr_m, dv_m_s)
    model = ConstraintModel(moved, X0, plan.U, opts.newton.active_tol)
    sigma = BandedSigma(model.D, opts.newton.regularisation,
                        column_weights(moved, plan.U, opts.newton.control_weight_floor))
    d = model.residual()
    dmax = np.max(np.abs(d))
    step = sigma.step(d)
    full = np.max(np.abs(model.residual(step)))
    chosen, there = _corrected(model, sigma, np.zeros_like(step), step, dmax)
    np.testing.assert_array_equal(there, model.residual(chosen))
    after = np.max(np.abs(there))
    if corrected:
        assert full > dmax and after < 0.75 * dmax and not np.array_equal(chosen, step)
    else:
        assert full < 1e-2 * dmax and np.array_equal(chosen, step)
    # the inner iterations advance by the step they chose: the model residual they report is
    # the one at the step they return
    dY, inner, model_max = _inner_iterations(model, sigma, dmax, opts)
    assert inner >= 1 and model_max == np.max(np.abs(model.residual(dY)))


def test_feedback_gains_shape():
    sol = solve_case("double_integrator")
    assert sol.gains_a.shape == (11, 3) and sol.gains_b.shape == (11, 3, 6)
    assert np.all(np.isfinite(sol.gains_b))


# ------------------------------------------------------------------------------- bad input
def test_bad_guess_shapes_and_values():
    prob = problem_from_case(DI)
    with pytest.raises(DaddyError, match="u_guess must have shape"):
        solve(prob, np.zeros((3, 3)))
    with pytest.raises(DaddyError, match="u_guess contains NaN"):
        solve(prob, np.full((11, 3), np.nan))
    with pytest.raises(DaddyError, match="method"):
        solve(prob, method="newton")


def test_bad_problem_fields():
    prob = problem_from_case(DI)
    with pytest.raises(DaddyError, match="stage_dt"):
        Problem(name="x", x0=prob.x0, x_target=prob.x_target, stage_dt=np.array([1.0, -1.0]),
                step=prob.step, stage_cost=prob.stage_cost, terminal_cost=prob.terminal_cost)
    with pytest.raises(DaddyError, match="x_target"):
        Problem(name="x", x0=prob.x0, x_target=np.zeros(2), stage_dt=np.ones(3), step=prob.step,
                stage_cost=prob.stage_cost, terminal_cost=prob.terminal_cost)
    nan_cost = Problem(name="x", x0=prob.x0, x_target=prob.x_target, stage_dt=np.ones(11),
                       step=prob.step, stage_cost=lambda x, u, dt, hom: u[0] * np.nan,
                       terminal_cost=prob.terminal_cost)
    with pytest.raises(DaddyError, match="stage_cost returned NaN"):
        solve(nan_cost, np.zeros((11, 3)))


def test_infeasible_mass_bound():
    case = load_case("earth_mars")
    prob = problem_from_case(case)
    heavy_dry = prob.with_x0(np.concatenate([prob.x0[:6], [0.4]]))
    with pytest.raises(DaddyError, match="dry mass"):
        solve(heavy_dry, np.zeros((40, 3)))


def test_options_are_validated():
    with pytest.raises(DaddyError, match="options.ddp.tol"):
        SolverOptions(ddp=dict(tol=-1.0))
    with pytest.raises(DaddyError, match="homotopy"):
        SolverOptions(homotopy=((2.0, 0.1),))
    with pytest.raises(DaddyError, match="options.newton.control_weight_floor"):
        SolverOptions(newton=dict(control_weight_floor=2.0))
    with pytest.raises(DaddyError, match="options.kkt.tol"):
        SolverOptions(kkt=dict(tol=0.0))


@pytest.mark.parametrize("nu", [1, 2, 3, 4])
def test_regularised_inverse_matches_numpy_and_rejects_indefinite(nu):
    """The Q_uu + rho I inverse of the backward sweep (plain Python; unrolled for nu = 3)."""
    from daddy_core.solver.linalg import regularised_inverse as _regularised_inverse
    rng = np.random.default_rng(nu)
    for _ in range(50):
        M = rng.normal(size=(nu, nu))
        Q = M @ M.T
        rho = 1e-3
        np.testing.assert_allclose(_regularised_inverse(Q, rho),
                                   np.linalg.inv(Q + rho * np.eye(nu)), rtol=1e-9, atol=0)
    indefinite = np.eye(nu)
    indefinite[-1, -1] = -1.0
    assert _regularised_inverse(indefinite, 0.5) is None
    assert _regularised_inverse(indefinite, 1.5) is not None
    assert _regularised_inverse(np.full((nu, nu), np.nan), 1.0) is None


def test_repropagation_miss_is_inf_when_the_check_fails():
    """The DOP853 check cannot vouch for a schedule it cannot fly: NaN controls (or dynamics)
    give an infinite miss, never a miss computed on a partial trajectory."""
    from daddy_core.solver import repropagation_miss
    prob = problem_from_case(load_case("earth_mars"))
    U = np.zeros((prob.N, 3))
    assert np.isfinite(repropagation_miss(prob, U))
    U[prob.N // 2, 0] = np.nan
    assert repropagation_miss(prob, U) == np.inf
    # a Solution that records it keeps it through strict JSON
    sol = solve_case("double_integrator")
    sol.repropagation_miss = np.inf
    assert Solution.from_json(sol.to_json()).repropagation_miss == np.inf


def test_the_linearised_repropagation_is_the_stage_by_stage_one():
    """With the solved states and their stage maps, ``repropagation_miss`` integrates every
    stage at once from its own start and carries the stage defects to the end through the maps'
    Jacobians: the stage-by-stage DOP853 miss to round-off. States that stray from the flow
    (a 1e-4 defect), or NaN controls, take the stage-by-stage path (its exact result)."""
    from daddy_core.solver import repropagation_miss
    from daddy_core.solver.stage_maps import StageMaps, expand_dynamics
    case = load_case("earth_mars")
    prob = problem_from_case(case)
    sol = solve_case("earth_mars")
    maps = StageMaps.of(expand_dynamics(prob, sol.X[:-1], sol.U), sol.X, sol.U, 1e-6)
    seq = repropagation_miss(prob, sol.U)
    assert 0 < seq < 1e-8
    # (round-off: 40 stages of O(1) states, each integrated once in either order)
    assert abs(repropagation_miss(prob, sol.U, sol.X, maps) - seq) <= 1e-13
    assert abs(sol.repropagation_miss - seq) <= 1e-13
    strayed = sol.X.copy()
    strayed[prob.N // 2] += 1e-4
    assert repropagation_miss(prob, sol.U, strayed, maps) == seq
    U = sol.U.copy()
    U[3, 0] = np.nan
    assert repropagation_miss(prob, U, sol.X, maps) == np.inf


def test_methods_are_an_enum_of_a_sweep_and_a_forward_pass():
    from daddy_core.solver import METHODS, Method, Sweep
    assert METHODS == ("std", "hess", "q", "dyn", "hessdyn", "qdyn")        # paper Table 1
    table = {m: (Method.parse(m).sweep, Method.parse(m).dyn) for m in METHODS}
    assert table == {"std": (Sweep.STD, False), "hess": (Sweep.HESS, False),
                     "q": (Sweep.Q, False), "dyn": (Sweep.STD, True),
                     "hessdyn": (Sweep.HESS, True), "qdyn": (Sweep.Q, True)}
    assert Method.parse(Method.QDYN) is Method.QDYN
    with pytest.raises(DaddyError, match="method must be one of"):
        Method.parse("newton")


def test_a_warm_start_object_carries_what_a_solution_lends():
    # WarmStart is solve()'s one warm-start channel: from a Solution it takes U and the duals,
    # the maps only for the same stage durations, rho only with carry_rho
    from daddy_core.solver import WarmStart
    case = load_case("double_integrator")
    prob = problem_from_case(case)
    sol = solve(prob, np.zeros((prob.N, 3)), method="dyn", options=case_options(case, False))
    w = WarmStart.of(sol, prob.stage_dt, carry_rho=False)
    np.testing.assert_array_equal(w.U, sol.U)
    assert w.duals is sol.duals and w.rho is None and w.maps is sol.stage_maps
    other = WarmStart.of(sol, prob.stage_dt * 2, carry_rho=True)
    assert other.maps is None and other.rho == sol.rho
    assert WarmStart.of(w, prob.stage_dt, True) is w
    again = solve(prob, w, method="dyn", options=case_options(case, False))
    assert again.converged and again.cost == pytest.approx(sol.cost, rel=1e-9)


def _landing(**kw):
    """A 1-D landing written as a new user would, with one function replaced by ``kw``."""
    from daddy_core.da import functions as dm
    from daddy_core.problem import flow_step

    def rhs(t, x, u):
        return dm.stack([x[1], u[0] / x[2] - 1.62, -u[0] / 3000.0])

    fields = dict(name="landing", nu=1, x0=np.array([1500.0, -30.0, 10.0]),
                  x_target=np.zeros(3), stage_dt=np.full(10, 2.0),
                  step=flow_step(rhs, "rk4", rk4_steps=2),
                  stage_cost=lambda x, u, dt, hom: u[0] * u[0],
                  terminal_cost=lambda x, xt: -x[2],
                  g_ineq=lambda x, u, dt: dm.stack([u[0] - 45.0, -u[0]]),
                  g_teq=lambda x, xt: x[:2] - xt[:2])
    fields.update(kw)
    return Problem(**fields)


@pytest.mark.parametrize("mistake, field, hint", [
    ("np.sqrt in the rhs", "step", "dm.sqrt"),
    ("np.stack in the rhs", "step", "dm.stack"),
    ("a list from g_teq", "g_teq", r"dm.stack\(\[\.\.\.\]\)"),
    ("a bare expression from g_ineq", "g_ineq", "shape"),
    ("np.sin in the stage cost", "stage_cost", "dm.sin"),
])
def test_functions_written_for_floats_only_are_named_before_any_iteration(mistake, field, hint):
    """Every problem function runs once on DA at the initial guess: a first mistake that works on
    floats but not on DA is a DaddyError naming the function and the fix, not a raw exception
    from inside the solver."""
    from daddy_core.da import functions as dm
    from daddy_core.problem import flow_step
    bad = {
        "np.sqrt in the rhs": dict(step=flow_step(
            lambda t, x, u: dm.stack([x[1], np.sqrt(u[0] * u[0]) / x[2] - 1.62, -u[0] / 3e3]),
            "rk4", rk4_steps=2)),
        "np.stack in the rhs": dict(step=flow_step(
            lambda t, x, u: np.stack([x[1], u[0] / x[2] - 1.62, -u[0] / 3000.0]), "rk4",
            rk4_steps=2)),
        "a list from g_teq": dict(g_teq=lambda x, xt: [x[0] - xt[0], x[1] - xt[1]]),
        "a bare expression from g_ineq": dict(g_ineq=lambda x, u, dt: u[0] - 45.0),
        "np.sin in the stage cost": dict(stage_cost=lambda x, u, dt, hom: np.sin(u[0]) ** 2),
    }[mistake]
    good = _landing()
    U0 = np.full((10, 1), 16.0)
    good.check_guess(U0)                        # the well-written problem passes
    with pytest.raises(DaddyError, match=f"problem {field}.*{hint}"):
        solve(_landing(**bad), U0)


def _rest_to_rest(stage_cost=None):
    """Move 10 m from rest to rest in 10 s with |u| <= 1 m/s^2 (exact zero-order hold)."""
    from daddy_core.da import functions as dm
    from daddy_core.fuel import pseudo_huber_stage_cost
    N, dt = 20, 0.5

    def step(x, u, dt):
        return dm.stack([x[0] + x[1] * dt + u[0] * (0.5 * dt * dt), x[1] + u[0] * dt])

    return Problem(name="rest_to_rest", nu=1, x0=np.zeros(2), x_target=np.array([10.0, 0.0]),
                   stage_dt=np.full(N, dt), step=step,
                   stage_cost=stage_cost or pseudo_huber_stage_cost(u_max=1.0, dt_ref=dt),
                   terminal_cost=lambda x, xt: x[0] * 0.0,
                   g_ineq=lambda x, u, dt: dm.stack([u[0] * u[0] - 1.0]),
                   g_teq=lambda x, xt: x - xt, u_max=1.0)


def test_fuel_optimal_user_problem_runs_the_default_homotopy_to_the_lp_optimum():
    """fuel_optimal=True on a user problem with default options runs fuel.FUEL_HOMOTOPY on the
    library's pseudo-Huber cost; the propellant lands on the optimum of the same discrete
    problem solved independently as a linear program (scipy linprog), within the smoothing of
    the last step (delta = 1e-3)."""
    from scipy.optimize import linprog

    from daddy_core.fuel import FUEL_HOMOTOPY
    prob = _rest_to_rest()
    sol = solve(prob, np.zeros((prob.N, 1)), fuel_optimal=True)
    assert sol.converged and sol.fuel_optimal and sol.max_violation <= 1e-10
    assert [(h["h"], h["delta"]) for h in sol.history] == list(FUEL_HOMOTOPY)
    dt = prob.stage_dt[0]
    fuel = float(np.sum(np.abs(sol.U[:, 0])) * dt)
    k = np.arange(prob.N)
    effect = np.vstack([dt * dt * (prob.N - k - 0.5), np.full(prob.N, dt)])  # on x_N, v_N
    lp = linprog(np.full(2 * prob.N, dt), A_eq=np.hstack([effect, -effect]), b_eq=[10.0, 0.0],
                 bounds=[(0, 1.0)] * (2 * prob.N))
    assert lp.status == 0
    assert lp.fun - 1e-9 <= fuel <= lp.fun * (1 + 2e-3)
    energy = solve(prob, np.zeros((prob.N, 1)), fuel_optimal=False)
    assert not energy.fuel_optimal and float(np.sum(np.abs(energy.U)) * dt) > fuel * 1.05


def test_fuel_optimal_with_a_stage_cost_that_ignores_the_homotopy_is_an_error():
    prob = _rest_to_rest(stage_cost=lambda x, u, dt, hom: u[0] * u[0])
    with pytest.raises(DaddyError, match="stage_cost ignores its hom"):
        solve(prob, np.zeros((prob.N, 1)), fuel_optimal=True)
    assert solve(prob, np.zeros((prob.N, 1)), fuel_optimal=False).converged


def test_an_infeasible_problem_fails_fast_and_names_the_constraints_it_cannot_meet():
    """10 m from rest to rest in 2 s at |u| <= 1 m/s^2 is impossible (the most the bound allows
    is 1 m): the solve ends not converged, quickly, and its reason and ``violations`` name the
    terminal constraints -- the position most of all -- and the thrust bound it pushed past."""
    import time

    prob = _rest_to_rest()
    short = Problem(**{**{f: getattr(prob, f) for f in prob.__dataclass_fields__},
                       "stage_dt": np.full(20, 0.1)})
    t0 = time.process_time()
    sol = solve(short, np.zeros((20, 1)))
    assert time.process_time() - t0 < 30.0
    assert not sol.converged and np.all(np.isfinite(sol.X)) and np.all(np.isfinite(sol.U))
    names = [r["name"] for r in sol.violations]
    assert set(names) == {"g_ineq[0]", "g_teq[0]", "g_teq[1]"}
    assert sol.violations[0]["violation"] == pytest.approx(sol.max_violation)
    assert "largest violations: g_teq[0]" in sol.reason
    # the augmented Lagrangian says it stalled (the violation unmoved while the penalty grew,
    # or not falling with the penalty at its cap) instead of running its aul_max_iter
    # iterations, and the polishing stops as fast
    assert ("unmoved while the penalty grew" in sol.reason
            or "stalled with the penalty at mu_max" in sol.reason)
    assert sol.iterations["aul"] < SolverOptions().aul.max_iter
    # (by its stall or no-descent rule, far from its newton_max_iter), and so does the
    # restoration of the start (SolverOptions.start.restore), which DDP then does without
    assert sol.iterations["newton"] <= 2 * SolverOptions().newton.stall_iter
    assert 0 < sol.iterations["restore"] <= SolverOptions().newton.stall_iter + 1
    assert sol.violations[0]["name"] == "g_teq[0]" and sol.violations[0]["stage"] is None
    again = Solution.from_json(sol.to_json())
    assert again.violations == sol.violations and again.infeasible
    # certified (solver.infeasibility): the least-violation point is returned, within the bound
    assert sol.infeasible and sol.reason.startswith("infeasible: the least-violation point")
    assert np.max(np.abs(sol.U)) <= 1.0 + 1e-9
    assert {r["name"]: r["violation"] for r in sol.violations}["g_ineq[0]"] <= 1e-9
    # ... and it is the least miss: the terminal residual is linear in U here, so the least
    # 1/2 |psi|^2 with |u| <= 1 is a bounded linear least-squares problem (scipy's lsq_linear)
    from scipy.optimize import lsq_linear
    psi = lambda U: short.rollout(U.reshape(20, 1))[-1] - short.x_target   # noqa: E731
    b = psi(np.zeros(20))
    A = np.column_stack([psi(np.eye(20)[i]) - b for i in range(20)])
    ref = lsq_linear(A, -b, bounds=(-1.0, 1.0), tol=1e-12)
    assert 0.5 * np.sum(psi(sol.U.ravel()) ** 2) == pytest.approx(0.5 * np.sum((A @ ref.x + b) ** 2),
                                                               rel=1e-6)


def test_a_transfer_too_short_for_its_thruster_is_certified_infeasible():
    """Earth-Mars in 100 days instead of 349 at 0.5 N (not a case anything was tuned on): the
    solve says infeasible, and the answer it returns never exceeds the thrust bound (the
    unconverged iterate before the certification asked for 25x it)."""
    import json

    from daddy_core.catalogue.cases import CASES_DIR, case_from_dict
    d = json.loads((CASES_DIR / "earth_mars.json").read_text())
    case = case_from_dict({**d, "tof_days": 100.0})
    prob = problem_from_case(case)
    sol = solve(prob, case.cold_guess(prob.N), fuel_optimal=False,
                options=case_options(case, False))
    assert not sol.converged and sol.infeasible and sol.reason.startswith("infeasible:")
    assert np.max(np.linalg.norm(sol.thrust_n, axis=1)) <= 0.5 * (1 + 1e-9)
    assert np.all(np.isfinite(sol.X)) and sol.max_violation > 1.0


@pytest.mark.parametrize("kind", list(INFEASIBLE))
def test_three_kinds_of_infeasible_problem_are_called_infeasible_within_the_bounds(kind):
    """Each is called infeasible, its answer within the thrust bound and its stage
    constraints. Where the end's own rows contradict (the keep-out containing the target, the
    contradictory rows: ``infeasibility.contradicted_end``) that is known before any
    iteration, with the least miss of the end in closed form (the keep-out's radius; half the
    distance between x = 1 and x = 2); the weak thrust needs the dynamics: its least-violation
    trajectory is returned."""
    changes, least_miss = INFEASIBLE[kind]
    feasible = solve(double_integrator(), np.zeros((20, 3)))
    assert feasible.converged and not feasible.infeasible
    prob = double_integrator(**changes)
    sol = solve(prob, np.zeros((20, 3)))
    assert not sol.converged and sol.infeasible and sol.reason.startswith("infeasible:"), kind
    assert np.all(np.isfinite(sol.X))
    assert np.max(np.linalg.norm(sol.U, axis=1)) <= prob.u_max * (1 + 1e-9)
    stage_rows = [r for r in sol.violations if r["name"].startswith(("g_ineq", "g_path"))]
    assert stage_rows and max(r["violation"] for r in stage_rows) <= 1e-8
    if prob.g_path is not None:   # held between the nodes too (dense re-propagation)
        assert sol.min_path_margin is not None and sol.min_path_margin >= -1e-9
    end = contradicted_end(prob, SolverOptions())
    if least_miss is None:
        assert end is None and sol.iterations["ddp"] > 0
        return
    assert end is not None and end.miss == pytest.approx(least_miss, rel=1e-6)
    assert f"{end.miss:.3e}" in sol.reason and sol.iterations["ddp"] == 0


def test_an_end_the_rows_allow_is_not_called_contradicted():
    """``contradicted_end`` on ends that can be met: nonlinear terminal rows with a
    placeholder target the rows are undefined at (the orbit raise's |r| = 1.5, r.v = 0,
    r x v = sqrt(1.5); a zero x_target, sqrt(0) raising: met from x0 by the least squares), a
    keep-out sphere whose surface the target lies 0.1 mm outside, and the catalogue's cases;
    and on one that cannot, the target 0.1 inside a keep-out sphere of radius 0.3: the least
    miss 0.2, at a final state on the sphere."""
    from daddy_core.solver.infeasibility import _EndRows
    raise_ = _orbit_raise_problem(12)
    assert contradicted_end(raise_, SolverOptions()) is None
    near = double_integrator(g_path=lambda x, u: dm.stack(
        [0.09 - ((x[0] - 1.3001) ** 2 + x[1] ** 2 + x[2] ** 2)]))
    assert contradicted_end(near, SolverOptions()) is None
    shifted = double_integrator(g_path=lambda x, u: dm.stack(
        [0.09 - ((x[0] - 1.1) ** 2 + x[1] ** 2 + x[2] ** 2)]))   # the target 0.1 inside
    end = contradicted_end(shifted, SolverOptions())
    assert end is not None and end.miss == pytest.approx(0.2, rel=1e-6)
    z = np.r_[end.x, np.zeros(3)]
    assert _EndRows(shifted).ineq(z)[0].max() <= 1e-8   # on the sphere, not inside it
    for name in ("halo_l2_l1", "earth_mars", "gto_geo", "two_phase_lq"):
        assert contradicted_end(problem_from_case(load_case(name)), SolverOptions()) is None


def _with_constant(problem: Problem, c: float, where: str) -> Problem:
    """``problem`` with a constant c added to its terminal cost, or c dt to every stage cost."""
    from dataclasses import replace
    if where == "terminal":
        phi = problem.terminal_cost
        return replace(problem, terminal_cost=lambda x, xt: phi(x, xt) + c)
    l = problem.stage_cost
    return replace(problem, stage_cost=lambda x, u, dt, hom: l(x, u, dt, hom) + c * dt)


@pytest.mark.parametrize("name, c, where, options", [
    ("orbit raise", 1e3, "terminal", SolverOptions()),
    ("orbit raise", 1e3, "terminal", SolverOptions(kkt=dict(tol=np.inf))),   # DDP's stop
    ("orbit raise", -0.5, "stage", SolverOptions(kkt=dict(tol=np.inf))),
    ("rest to rest", 1e3, "stage", SolverOptions()),
])
def test_a_constant_in_the_cost_changes_nothing(name, c, where, options):
    """A cost J + c takes the steps J takes (``cost_scale``: DDP's relative tests divide by
    the part of the cost the controls change): the same controls to 1e-8, with or without the
    KKT polishing. Relative to |J + 1e3|, DDP's own stop ended the orbit raise after 24
    iterations 84 % above its optimum (260 iterations without the constant)."""
    prob, fuel = ((_orbit_raise_problem(12), False) if name == "orbit raise"
                  else (_rest_to_rest(), True))
    U0 = np.full((prob.N, prob.nu), 1e-3)
    plain = solve(prob, U0, fuel_optimal=fuel, options=options)
    offset = solve(_with_constant(prob, c, where), U0, fuel_optimal=fuel, options=options)
    assert plain.converged and offset.converged
    assert np.max(np.abs(offset.U - plain.U)) <= 1e-8
    constant = c if where == "terminal" else c * float(np.sum(prob.stage_dt))
    assert offset.cost - constant == pytest.approx(plain.cost, rel=1e-9)


def test_the_cost_scale_is_the_cost_for_costs_without_constants():
    """``cost_scale``: the catalogue's costs (energy or fuel, 0 at zero control, and a terminal
    miss penalty largest at x_0) divide their relative tests by |J| as ever; a landing that
    maximises its final mass divides by the propellant spent, not by the mass; a
    least-violation cost by the miss left, not the miss removed."""
    from daddy_core.solver.cost_scale import anchor, scale
    prob = problem_from_case(load_case("halo_l2_l1"))
    for hom in ((0.0, 1.0), (1.0, 1e-3)):
        assert anchor(prob, hom) == pytest.approx(prob.terminal_cost(prob.x0, prob.x_target))
        assert scale(0.0123, anchor(prob, hom)) == 0.0123
    landing = _landing()
    assert anchor(landing, None) == -10.0                           # -m_0, no thrust
    assert scale(-9.48, anchor(landing, None)) == pytest.approx(0.52)
    assert scale(1e-6, 0.5) == 1e-6
    assert scale(1e3, 1e3) == pytest.approx(1e-9)   # never below the cost's round-off


def test_a_feasible_problem_the_solver_failed_is_called_feasible():
    """The double integrator with its augmented Lagrangian cut to one iteration of three DDP
    steps, no restoration of the start and no polishing ends unconverged on its terminal rows; the least-violation solve meets them, so
    the problem is not called infeasible: its point (feasible, not optimal) is returned and the
    reason says the failure was the solver's."""
    case = load_case("double_integrator")
    prob = problem_from_case(case)
    opts = case_options(case, False).with_(aul=dict(max_iter=1), ddp=dict(max_iter=3),
                                           start=dict(restore=False))
    sol = solve(prob, np.zeros((prob.N, 3)), options=opts, polish=False)
    assert not sol.converged and not sol.infeasible
    assert "the problem is feasible" in sol.reason
    assert sol.max_violation <= opts.aul.tol
    off = solve(prob, np.zeros((prob.N, 3)), polish=False,
                options=opts.with_(end_game=dict(certify_infeasibility=False)))
    assert not off.converged and off.max_violation > opts.aul.tol and "feasible" not in off.reason


def test_a_converged_solution_reports_every_constraint_met():
    case = load_case("double_integrator")
    prob = problem_from_case(case)
    sol = solve(prob, np.zeros((prob.N, 3)), options=case_options(case, False))
    assert sol.converged and "largest violations" not in sol.reason
    assert {r["name"] for r in sol.violations} == {"g_teq[0]", "g_teq[1]", "g_teq[2]"}
    assert max(r["violation"] for r in sol.violations) <= 1e-10


_R1, _A_MAX = 1.5, 0.05   # the orbit raise's target radius and thrust acceleration bound


def _on_circle(x, xt):
    """The orbit raise's terminal constraints: |r| - r1, r.v, h - sqrt(r1)."""
    return dm.stack([dm.sqrt(x[0] * x[0] + x[1] * x[1]) - _R1, x[0] * x[2] + x[1] * x[3],
                     x[0] * x[3] - x[1] * x[2] - np.sqrt(_R1)])


def _orbit_raise_problem(N: int) -> Problem:
    """Arrive anywhere on a circular orbit (the README's example) on N stages."""
    from daddy_core.dynamics import Dynamics
    from daddy_core.problem import flow_step

    def rhs(t, x, u):
        k = (x[0] * x[0] + x[1] * x[1]) ** -1.5
        return dm.stack([x[2], x[3], -x[0] * k + u[0], -x[1] * k + u[1]])

    return Problem(name="orbit_raise", nu=2, x0=np.array([1.0, 0.0, 0.0, 1.0]),
                   x_target=np.zeros(4), stage_dt=np.full(N, 3 * np.pi / N),
                   step=flow_step(Dynamics(rhs, scalar_components=True)),
                   stage_cost=lambda x, u, dt, hom: (u[0] * u[0] + u[1] * u[1]) * dt,
                   terminal_cost=lambda x, xt: x[0] * 0.0, g_teq=_on_circle,
                   g_ineq=lambda x, u, dt: dm.stack([(u[0] * u[0] + u[1] * u[1])
                                                     * (1 / _A_MAX ** 2) - 1.0]))


def _orbit_raise(N: int):
    """The orbit raise on N stages and the optimum of the same discrete problem found
    independently by scipy's SLSQP over the controls: (problem, SLSQP result)."""
    from scipy.optimize import minimize
    prob = _orbit_raise_problem(N)
    dt = prob.stage_dt[0]
    ref = minimize(lambda z: np.sum(z * z) * dt, np.full(2 * N, 1e-3), jac=lambda z: 2 * z * dt,
                   method="SLSQP", options={"maxiter": 500, "ftol": 1e-15},
                   constraints=[{"type": "eq", "fun": lambda z: np.asarray(
                                     _on_circle(prob.rollout(z.reshape(N, 2))[-1], None))},
                                {"type": "ineq", "fun": lambda z: _A_MAX ** 2 - np.sum(
                                     z.reshape(N, 2) ** 2, axis=1)}])
    assert ref.success
    return prob, ref


def test_nonlinear_terminal_constraints_from_a_cold_start_against_slsqp():
    """From a cold guess the solve converges, meets the constraints to 1e-10 and, polished on
    the KKT conditions to tol_optimality (1e-4), reaches SLSQP's optimum of the same discrete
    problem to 1e-7 (measured 3.9e-8 at a residual of 5.3e-5; 1e-13 when the polishing went on
    to 1e-9). DDP's own test, a relative decrease below tol_ddp, stops 3.4e-4 above it (on
    40 stages: 1.5e-3): the KKT residual says so, and only the polishing reaches it."""
    N = 12
    prob, ref = _orbit_raise(N)
    sol = solve(prob, np.full((N, 2), 1e-3))
    assert sol.converged and sol.max_violation <= 1e-10 and sol.kkt_residual <= 1e-4
    assert sol.cost == pytest.approx(ref.fun, rel=1e-7)
    ddp_only = solve(prob, np.full((N, 2), 1e-3), options=SolverOptions(kkt=dict(tol=np.inf)))
    assert ddp_only.converged and ddp_only.cost > ref.fun * (1 + 1e-4)
    assert optimality(prob, ddp_only.X, ddp_only.U, (0.0, 1e-2)).kkt_residual > 1e-4


def test_a_trial_step_dividing_by_zero_mass_is_rejected_not_raised():
    """Earth-Mars in one stage (no feasible control: the target is out of reach): DDP trial
    steps run the mass to zero, where the scalar-component models divide by a Python 0.0; such a
    step is rejected like one that ran the mass negative, and the solve ends not converged with
    its reason and finite values, never with a raw ZeroDivisionError."""
    case = load_case("earth_mars")
    prob = problem_from_case(case, stages=1)
    sol = solve(prob, np.zeros((1, 3)), fuel_optimal=True,
                options=case_options(case, True, run=dict(time_budget_s=3.0)))
    assert not sol.converged and sol.reason
    assert np.all(np.isfinite(sol.X)) and np.all(np.isfinite(sol.U))


def test_an_answer_cut_off_by_its_budget_keeps_the_thrust_bound():
    """Earth-Mars from a guess at ten times the thrust bound with a budget that ends the solve
    at once: the returned answer is its controls scaled onto the bound and the states flown
    from x0 with them (``assemble.within_thrust_bound``), not the guess (which broke the bound
    by 99 in g: Lyapunov from a random guess returned an iterate 41 times over the bound when
    its 120 s ran out), and the reason says so."""
    case = load_case("earth_mars")
    prob = problem_from_case(case)
    U0 = np.full((prob.N, 3), 10.0 * prob.u_max / np.sqrt(3.0))
    sol = solve(prob, U0, fuel_optimal=True,
                options=case_options(case, True, run=dict(time_budget_s=1e-6)))
    assert not sol.converged
    assert "scaled onto it" in sol.reason
    np.testing.assert_allclose(np.linalg.norm(sol.U, axis=1), prob.u_max, rtol=1e-12)
    np.testing.assert_allclose(sol.X, prob.rollout(sol.U), rtol=0, atol=1e-12)
    bound = [r for r in sol.violations if r["label"] == "thrust bound"]
    assert all(r["violation"] <= 1e-10 for r in bound)


def test_a_continuation_is_judged_by_its_last_step():
    """``homotopy.joined``: the rest of the homotopy that converged from the end of a first step
    that diverged gives the continuation's verdict (Lyapunov from random guesses, seed 2,
    guesses 5 and 6: the rest converged at 997.4874 kg, polished to 1e-13, and the solve was
    reported "diverged" without its KKT test; now it converges with the exact fuel form's
    KKT residual 5.2e-5); a rest that failed keeps its own reason."""
    from daddy_core.solver.homotopy import HomotopyResult, joined

    def result(converged, reason, history):
        return HomotopyResult(np.zeros((2, 1)), np.zeros((1, 1)), None, None, None, 0.0, 1,
                              history, converged, reason, "", False)

    first = result(False, "homotopy step 1: DDP diverged", [{"h": 0.0}])
    rest = joined(first, result(True, "converged", [{"h": 0.5}, {"h": 0.999}]))
    assert rest.converged and rest.reason == "converged"
    assert rest.aul_iterations == 2 and [h["h"] for h in rest.history] == [0.0, 0.5, 0.999]
    failed = joined(first, result(False, "homotopy step 2: aul_max_iter reached", []))
    assert not failed.converged and failed.reason.startswith("homotopy step 2")


@pytest.mark.parametrize("nu", [1, 2, 3, 4])
def test_trust_region_inverse_puts_the_step_on_the_boundary(nu):
    """The trust-region subproblem's shifted inverse: the step -(Quu + lam I)^-1 Qu has norm
    radius (to 1e-3), lam >= rho, and the shifted matrix is the inverse of Quu + lam I, for
    well- and ill-conditioned Quu (a linear-in-u cost: eigenvalues down to 1e-8)."""
    from daddy_core.solver.linalg import trust_region_inverse as _trust_region_inverse
    rng = np.random.default_rng(10 + nu)
    for scale in (1.0, 1e-8):
        for _ in range(20):
            V, _ = np.linalg.qr(rng.normal(size=(nu, nu)))
            Q = (V * (scale * rng.uniform(0.1, 10.0, nu))) @ V.T
            Qu = rng.normal(size=nu)
            step = np.linalg.solve(Q, Qu)
            radius = 0.3 * np.linalg.norm(step)
            Minv = _trust_region_inverse(Q, Qu, 0.0, radius)
            assert np.linalg.norm(Minv @ Qu) == pytest.approx(radius, rel=1.1e-3)
            lam = 1.0 / np.linalg.eigvalsh(Minv).max() - np.linalg.eigvalsh(Q).min()
            assert lam > 0
            np.testing.assert_allclose(Minv, np.linalg.inv(Q + lam * np.eye(nu)), rtol=1e-6)


@pytest.mark.parametrize("nu", [2, 3, 7])
def test_an_indefinite_stages_trust_region_step_is_the_subproblems_minimiser(nu):
    """An indefinite Quu (``backward_sweep``'s indefinite stages): the step -(Quu + lam I)^-1 Qu
    lies on the boundary (to 1e-3) with Quu + lam I positive definite, and no point of the
    region sampled at random models a lower cost Qu.a + a.Quu.a / 2 (the TRQP's global
    minimiser, Conn, Gould & Toint Thm 7.2.1)."""
    from daddy_core.solver.linalg import trust_region_inverse
    rng = np.random.default_rng(40 + nu)
    for _ in range(20):
        V, _ = np.linalg.qr(rng.normal(size=(nu, nu)))
        w = rng.uniform(0.1, 10.0, nu) * np.where(np.arange(nu) < nu // 2, -1.0, 1.0)
        Q, Qu, radius = (V * w) @ V.T, rng.normal(size=nu), rng.uniform(0.05, 2.0)
        a = -trust_region_inverse(Q, Qu, 0.0, radius) @ Qu
        assert np.linalg.norm(a) == pytest.approx(radius, rel=1.1e-3)
        model = lambda d: Qu @ d + 0.5 * d @ Q @ d
        trial = rng.normal(size=(2000, nu))
        trial *= radius * rng.uniform(0, 1, (2000, 1)) ** (1 / nu) / np.linalg.norm(
            trial, axis=1, keepdims=True)
        assert model(a) <= min(model(d) for d in trial) + 1e-9


@pytest.mark.parametrize("stages", [17, 40])
def test_trust_region_reaches_the_same_optima_as_the_line_search(stages):
    """Globalization.TRUST_REGION on problems with an independent answer: the double
    integrator's closed form (every method), and the 1-D landing with a cost linear in the
    control (maximise the final mass, no control penalty: the quadratic model's steps are
    far too long there) at two stage counts, against its closed form."""
    from daddy_core.da import functions as dm
    for method in ("std", "dyn", "qdyn"):
        sol = solve_case("double_integrator", method, ddp=dict(globalization="trust_region"))
        assert sol.converged, sol.reason
        assert sol.cost == pytest.approx(di_closed_form(), rel=1e-9)
    prob = _landing(stage_dt=np.full(stages, 80.0 / stages),
                    stage_cost=lambda x, u, dt, hom: u[0] * 0.0,
                    g_ineq=lambda x, u, dt: dm.stack([u[0] - 45.0, -u[0]]))
    runs = [solve(prob, np.full((stages, 1), 16.0),
                  options=SolverOptions(ddp=dict(globalization=g)))
            for g in ("line_search", "trust_region")]
    # the rocket equation: every thrust history that lands in T ends at the same mass
    closed_form = 10.0 * np.exp(-(30.0 + 1.62 * 80.0) / 3000.0)
    for sol in runs:
        assert sol.converged and sol.max_violation <= 1e-10, sol.reason
        assert sol.X[-1, 2] == pytest.approx(closed_form, rel=1e-9)


def test_a_line_search_at_its_iteration_bound_falls_back_to_the_trust_region(capsys):
    """``SolverOptions.aul.tr_fallback``: a line-search DDP solve that runs into ddp_max_iter is
    solved again with the trust region, which the rest of the solve keeps; the landing with a
    cost linear in the control still reaches its closed-form mass (and without the fallback
    too: the switch changes the path, not the answer)."""
    from daddy_core.da import functions as dm
    prob = _landing(stage_dt=np.full(17, 80.0 / 17), stage_cost=lambda x, u, dt, hom: u[0] * 0.0,
                    g_ineq=lambda x, u, dt: dm.stack([u[0] - 45.0, -u[0]]))
    closed_form = 10.0 * np.exp(-(30.0 + 1.62 * 80.0) / 3000.0)
    for fallback in (True, False):
        sol = solve(prob, np.full((17, 1), 16.0),
                    options=SolverOptions(ddp=dict(max_iter=3), aul=dict(tr_fallback=fallback),
                                          run=dict(verbose=True)))
        fell_back = "again from its start with the trust region" in capsys.readouterr().out
        assert fell_back is fallback
        assert sol.converged and sol.max_violation <= 1e-10, sol.reason
        assert sol.X[-1, 2] == pytest.approx(closed_form, rel=1e-9)


def test_a_cold_start_is_restored_to_feasibility_before_ddp(capsys):
    """``SolverOptions.start.restore`` (default on): Newton drives a random guess to the
    terminal constraints and the thrust bound before DDP starts; the answer is the closed form
    with and without it (the restoration changes where DDP starts, not the optimum)."""
    case = load_case("double_integrator")
    prob = problem_from_case(case)
    U0 = np.random.default_rng(7).uniform(-1.0, 1.0, size=(prob.N, prob.nu))
    sols = {}
    for restore in (True, False):
        sols[restore] = solve(prob, U0, options=case_options(case, False, run=dict(verbose=True),
                                                              start=dict(restore=restore)))
        out = capsys.readouterr().out
        restored = [line for line in out.splitlines() if "start restored by Newton" in line]
        assert len(restored) == int(restore)
        # a converged restoration: DDP starts from a trajectory that meets every constraint
        assert all("active constraints below tol_newton" in line for line in restored)
        assert (sols[restore].iterations["restore"] > 0) is restore
        assert sols[restore].converged, sols[restore].reason
    assert sols[True].cost == pytest.approx(sols[False].cost, rel=1e-9)


def test_a_cold_guess_newton_cannot_restore_falls_back_to_the_restored_ballistic_start():
    """``start._restore_ballistic``: a random DRO->DRO guess (thrust up to u_max, uniform
    directions) whose restoration stalls gets the ballistic trajectory restored instead, and
    DDP from there reaches the paper guess's energy optimum; the paper's 1e-6 N guess, which
    flies the ballistic trajectory already, does not repeat its stalled restoration."""
    case = load_case("dro_dro")
    prob = problem_from_case(case)
    rng = np.random.default_rng(28)   # (a seed whose guess stalls the restoration: 6 of 100)
    d = rng.normal(size=(prob.N, prob.nu))
    U0 = d / np.linalg.norm(d, axis=1, keepdims=True) * rng.uniform(0, 1, (prob.N, 1)) * prob.u_max
    lines = []
    sol = solve(prob, U0, options=case_options(case, False), progress=lines.append)
    fallback = [line for line in lines if "ballistic start" in line]
    assert len(fallback) == 1 and "active constraints below tol_newton" in fallback[0], lines
    assert sol.converged, sol.reason
    paper_guess = np.full((prob.N, prob.nu), float(case.units.thrust(1e-6)))
    ref = solve(prob, paper_guess, options=case_options(case, False))
    assert sol.final_mass_kg == pytest.approx(ref.final_mass_kg, abs=1e-3)

    em = load_case("earth_mars")
    em_prob = problem_from_case(em)
    lines.clear()
    solve(em_prob, np.full((em_prob.N, em_prob.nu), float(em.units.thrust(1e-6))),
          options=case_options(em, False, run=dict(time_budget_s=5.0)), progress=lines.append)
    assert any("start not restored by Newton" in line for line in lines)   # it stalls ...
    assert not any("ballistic" in line for line in lines)   # ... and is not repeated

def test_a_newton_step_that_leaves_the_dynamics_domain_is_halved_not_the_end():
    """Newton's step from x = 4 towards sqrt(x_N) = 0.05 overshoots to x_N < 0, where the
    terminal constraint is NaN (as an equinoctial orbit's sqrt(1 - p^2 - q^2) is past e = 1):
    the step is halved until the residual is finite, and Newton converges."""
    from daddy_core.da import functions as dm
    from daddy_core.solver import newton
    from daddy_core.solver.results import Status

    prob = Problem(name="sqrt_target", nu=1, x0=np.array([4.0]), x_target=np.array([0.0025]),
                   stage_dt=np.ones(5), step=lambda x, u, dt: dm.stack([x[0] + u[0] * dt]),
                   stage_cost=lambda x, u, dt, hom: u[0] * u[0] * dt,
                   terminal_cost=lambda x, xt: x[0] * 0.0,
                   g_teq=lambda x, xt: dm.stack([dm.sqrt(x[0]) - 0.05]))
    U = np.zeros((5, 1))
    res = newton.polish(prob, prob.rollout(U), U, SolverOptions())
    assert res.status is Status.NEWTON_CONVERGED, res.reason
    assert abs(np.sqrt(res.X[-1, 0]) - 0.05) <= 1e-10
    # a NaN constraint is never read as met (Python's max drops a NaN in second place)
    U_past = np.full((5, 1), -1.0)
    with np.errstate(invalid="ignore"):
        assert np.isnan(prob.violation(prob.rollout(U_past), U_past))
        assert np.isnan(prob.violation_report(prob.rollout(U_past), U_past)[0]["violation"])


def test_a_restoration_thrown_where_a_fresh_model_cannot_descend_stops_there():
    """Newton stops when a fresh model at an iterate above its best residual cannot be taken
    down by 1 %: from the paper's guess the Earth-Mars restoration is thrown from 1.24 to 35.16
    by its second step and stops at the third iteration (it used to sit there for three more);
    the halo's restoration, thrown from 0.23 to 770, still converges."""
    from daddy_core.solver import newton
    from daddy_core.solver.results import Status

    for name, converges in (("earth_mars", False), ("halo_l2_l1", True)):
        case = load_case(name)
        prob = problem_from_case(case)
        U = np.full((prob.N, prob.nu), float(case.units.thrust(1e-6)))
        res = newton.polish(prob, prob.rollout(U), U, case_options(case, True))
        assert res.converged is converges, (name, res.reason)
        if not converges:
            assert res.status is Status.NEWTON_NO_DESCENT and res.iterations <= 3, res.reason


class _CountedModel:
    """A constraint model that counts its evaluations."""

    def __init__(self, model):
        self.model, self.calls = model, 0

    def residual(self, dY):
        self.calls += 1
        return self.model.residual(dY)


def test_newtons_backtracking_picks_the_step_a_trial_by_trial_search_picks():
    """``newton._backtrack`` reads every trial's model residual off the quadratic through
    alpha = 1, -1 (the model is a polynomial of degree 2): with at most three evaluations of
    the model it must choose the alpha, and return the residual, that evaluating the trials one
    by one (the search before it) gives -- on Earth-Mars and DRO models at random guesses
    whose first steps are cut several times."""
    from daddy_core.solver import newton

    def one_by_one(model, dY, step, dmax, opts):
        alpha = 1.0
        for _ in range(opts.newton.ls_max_halvings):
            cand = model.residual(dY + alpha * step)
            if np.max(np.abs(cand)) < dmax:
                return alpha, cand
            alpha *= opts.newton.ls_shrink
        return None

    rng = np.random.default_rng(3)
    cut = 0
    for name in ("earth_mars", "dro_dro"):
        case = load_case(name)
        prob, opts = problem_from_case(case), case_options(case, True)
        U = float(case.units.thrust(1e-6)) + 0.3 * prob.u_max * rng.uniform(-1, 1, (prob.N, 3))
        X = prob.rollout(U)
        model = newton.ConstraintModel(prob, X, U, opts.newton.active_tol)
        sigma = newton._factorise(model, newton.column_weights(
            prob, U, opts.newton.control_weight_floor), opts.newton.regularisation)
        dY, d = np.zeros(model.D.shape[1]), model.residual()
        for _ in range(6):   # the inner iterations' first steps, as _inner_iterations takes them
            dmax, step = float(np.max(np.abs(d))), sigma.step(d)
            want = one_by_one(model, dY, step, dmax, opts)
            counted = _CountedModel(model)
            got = newton._backtrack(counted, dY, step, d, dmax, opts)
            if want is None:
                assert got is None
                break
            assert got[0] == want[0] and np.array_equal(got[1], want[1]), (name, got[0], want[0])
            assert counted.calls <= 3, (name, want[0], counted.calls)   # alpha = 1, -1, chosen
            cut += want[0] < 1.0
            dY, d = dY + want[0] * step, want[1]
    assert cut >= 2   # (the quadratic was used, not only the full step)


def test_each_homotopy_step_starts_from_the_multipliers_estimated_at_the_last_solution(
        monkeypatch):
    """``continuation`` hands the next homotopy step eq. 9's update at the previous step's
    solution (lam + mu g), not the multipliers its last DDP solve ran with, which lag by
    mu g; the whole halo homotopy then converges at the pseudo-Huber optimum. (The number of
    AUL solves the last step takes depends on the last bits of the BLAS arithmetic: 2 with
    OpenBLAS's SkylakeX kernels, 7 with its Haswell and Zen ones -- not asserted.)"""
    from daddy_core.solver import homotopy
    from daddy_core.solver.aul import update_multipliers

    starts, ends = [], []
    real_aul = homotopy.aul

    def spy(stages, *args, **kw):
        starts.append((stages.mult.lam.copy(), stages.mult.lam_t.copy(),
                       stages.mult.mu.copy(), stages.mult.mu_t.copy()))
        res = real_aul(stages, *args, **kw)
        ends.append(res)
        return res
    monkeypatch.setattr(homotopy, "aul", spy)
    case = load_case("halo_l2_l1")
    prob = problem_from_case(case)
    opts = case_options(case, True, end_game=dict(exact_fuel=False))
    sol = solve(prob, np.full((prob.N, 3), float(case.units.thrust(1e-6))), fuel_optimal=True,
                options=opts)   # (the whole homotopy)
    assert sol.converged, sol.reason
    assert len(starts) == len(opts.homotopy) >= 2
    for k in range(1, len(starts)):
        prev = ends[k - 1]
        g, _, gt, _ = prob.constraint_values(prev.stages.X, prev.stages.U)
        want = update_multipliers(prev.mult, g, gt, opts)
        lam, lam_t, mu, mu_t = starts[k]
        assert np.array_equal(lam, want.lam) and np.array_equal(lam_t, want.lam_t), k
        assert not np.array_equal(lam_t, prev.mult.lam_t), k   # (the update moved them)
        assert np.all(mu == opts.aul.mu_init) and np.all(mu_t == opts.aul.mu_init), k
    assert sol.final_mass_kg == pytest.approx(973.941, abs=2e-3)


def test_ddp_starts_a_stalled_restorations_guess_from_its_first_expansion():
    """A cold restoration that stalls leaves DDP at the guess, where its first model expanded
    every stage afresh: ``NewtonResult.start_F`` hands those maps on, identical to the
    expansion DDP would make (Earth-Mars from the paper's guess: one expansion of 40 stages
    saved); a restoration given maps (a warm start) has none to hand on."""
    from daddy_core.solver import newton
    from daddy_core.solver.stage_maps import StageMaps, expand_dynamics

    case = load_case("earth_mars")
    prob, opts = problem_from_case(case), case_options(case, False)
    U = np.full((prob.N, prob.nu), float(case.units.thrust(1e-6)))
    X = prob.rollout(U)
    res = newton.polish(prob, X, U, opts)
    assert not res.converged
    assert np.array_equal(res.start_F.c, expand_dynamics(prob, X[:-1], U).c)
    warm = newton.polish(prob, X, U, opts, maps=StageMaps.of(res.start_F, X, U, opts.eps_da))
    assert warm.start_F is None


def test_a_newton_run_whose_residual_stays_put_has_stalled():
    """``newton._flat``: three outer iterations in a row that moved the exact residual by under
    1 % stop a run (the Earth-Mars restoration from the paper's guess sat at 35.16 for seven);
    a detour that comes back, or a slow but steady fall, does not."""
    from daddy_core.solver.newton import _flat
    assert _flat([1.25, 1.24, 35.16, 35.16, 35.16, 35.16])
    assert not _flat([35.16, 35.16, 35.16])                 # too few iterations to tell
    assert not _flat([0.23, 0.23, 770.0, 64.0, 12.0])       # the halo's converging detour
    assert not _flat([8.8, 8.5, 8.3, 8.0, 7.8])             # 2-4 % per iteration
    assert not _flat([2.0, 2.0, 2.0, 1.0])                  # moved in the last one


def test_a_feasible_iterate_whose_ddp_solve_ran_into_its_bound_gets_one_more_solve():
    """``aul_safeguards.ends_feasible``: the augmented Lagrangian stops on a feasible iterate
    when its DDP solve converged, or when the one before it ran into ddp_max_iter too -- never
    on the first feasible iterate that DDP's iteration bound cut off."""
    from types import SimpleNamespace

    from daddy_core.solver.aul_safeguards import ends_feasible as _ends_feasible
    from daddy_core.solver.results import Status
    opts = SolverOptions()
    bound, done = (SimpleNamespace(status=s) for s in (Status.DDP_MAX_ITER,
                                                       Status.DDP_CONVERGED))
    feasible, infeasible = 0.5 * opts.aul.tol, 2.0 * opts.aul.tol
    assert _ends_feasible(done, feasible, False, opts)
    assert not _ends_feasible(done, infeasible, False, opts)
    assert not _ends_feasible(bound, feasible, False, opts)
    assert _ends_feasible(bound, feasible, True, opts)
    assert not _ends_feasible(bound, infeasible, True, opts)
    assert not _ends_feasible(done, float("nan"), False, opts)   # a NaN is never feasible


def test_a_ddp_solve_whose_steps_stay_cut_short_without_progress_has_stalled():
    """``stopping.crawling``: ddp_stall_iter steps in a row, each cut below ddp_stall_alpha of the
    full step and each lowering the cost by less than tol_ddp, stop a DDP solve (the Lyapunov
    harness's guesses 8, 16, 27 crawled 150-200 iterations at alpha ~ 1e-5); a shorter stretch
    (guess 0's: 7 steps), a long step in between, or real progress does not."""
    from types import SimpleNamespace

    from daddy_core.solver.results import Status
    from daddy_core.solver.stopping import Stopping, crawling as _crawling
    opts = SolverOptions()
    k = opts.ddp.stall_iter

    def run(fractions, rel):
        steps, J = [(1e8, 1.0, 1e8)], 1e8
        for f in fractions:
            J *= 1.0 - rel
            steps.append((J, f, J))
        return steps

    def nominal(J):   # what ``after_rejection`` reads of a nominal: a cost without a constant
        return SimpleNamespace(cost=J, scale=J)

    assert _crawling(run([7.6e-6] * k, 1e-6), opts)
    assert _crawling(run([0.5] * 5 + [7.6e-6] * k, 1e-6), opts)   # the last k count
    assert not _crawling(run([7.6e-6] * (k - 1), 1e-6), opts)       # too few to tell
    assert not _crawling(run([7.6e-6] * (k // 2) + [0.5] + [7.6e-6] * (k // 2), 1e-6), opts)
    assert not _crawling(run([7.6e-6] * k, 10 * opts.ddp.tol), opts)   # short but progressing
    assert not _crawling(run([0.5] * k, 1e-6), opts)   # full steps: DDP's own test decides
    assert not _crawling(run([7.6e-6] * k, 1e-6), SolverOptions(ddp=dict(stall_iter=0)))
    # the trust-region retry of a failed line search: rejections after its first accepted step
    # are steps of length zero; before it, the region is still shrinking to where the model holds
    shrinking = Stopping(opts, True, [(1e8, 1.0, 1e8)])
    assert not any(shrinking.after_rejection(nominal(1e8)) for _ in range(2 * k))
    after_one = Stopping(opts, True, run([1e-7], 1e-7))   # with k - 1 rejections, k steps
    calls = [after_one.after_rejection(nominal(after_one.steps[-1][0])) for _ in range(k - 1)]
    assert calls == [None] * (k - 2) + [Status.DDP_STALLED]
    plain = Stopping(opts, False, run([1e-7], 1e-7))
    assert not any(plain.after_rejection(nominal(1e8)) for _ in range(2 * k))


def test_a_first_ddp_solve_that_leaves_an_infeasible_start_far_behind_has_diverged():
    """``aul_safeguards.diverged``: the first solve of an AUL loop diverged when both
    globalisations were cut off and the max violation grew a hundredfold over an infeasible
    start's; a feasible (restored) start, a smaller growth, or a solve that converged never
    count."""
    from daddy_core.solver.aul_safeguards import diverged as _diverged
    opts = SolverOptions()
    assert _diverged(358.0, 0.27, True, opts)           # Lyapunov guess 27
    assert not _diverged(358.0, 0.27, False, opts)      # a globalisation converged
    assert not _diverged(20.0, 0.27, True, opts)        # grew 74-fold
    assert not _diverged(1e-4, 1e-11, True, opts)       # left a restored start: the penalty's trade
    assert _diverged(float("inf"), 0.27, True, opts)


@pytest.mark.slow
def test_a_solve_that_diverges_from_a_random_guess_says_so_and_returns_its_start():
    """Lyapunov L1->L2 fuel from the robustness harness's guess 27 (seed 0: uniform directions,
    magnitudes up to the bound): its first DDP solve stalls under the line search and under
    the trust region with the thrust hundreds of times its bound; the solve ends there
    (``Status.AUL_DIVERGED``; 28-44 s where it used to run into any time cap) and returns the
    start, finite, with the reason -- not the diverged iterate, not a polished one. (With the
    default ``end_game.blend_restart`` that unmet end is then solved again from the blended
    states, which converges: checked last.)"""
    from daddy_core.solver.multistart import random_starts
    case = load_case("lyapunov_l1_l2")
    prob = problem_from_case(case)
    # (bench_robustness.guesses: two fixed guesses, then ``random_starts``)
    U0 = random_starts(prob, 28 - 2, seed=0)[-1].guess
    sol = solve(prob, U0, options=case_options(case, True, end_game=dict(blend_restart=False)))
    assert not sol.converged
    assert "DDP diverged from the start" in sol.reason, sol.reason
    assert np.all(np.isfinite(sol.X)) and np.all(np.isfinite(sol.U))
    assert sol.max_violation < 1.0   # the start (0.27), not the diverged iterate (~300)
    assert sol.iterations["newton"] == 0
    again = solve(prob, U0, options=case_options(case, True))
    assert again.converged and "restarted from the blended states" in again.reason
    assert "DDP diverged from the start" in again.reason


def test_globalization_is_validated():
    from daddy_core.solver import Globalization
    assert (SolverOptions(ddp=dict(globalization="trust_region")).ddp.globalization
            is Globalization.TRUST_REGION)
    with pytest.raises(DaddyError, match="options.ddp.globalization"):
        SolverOptions(ddp=dict(globalization="dogleg"))
    with pytest.raises(DaddyError, match="options.ddp.tr_kappa"):
        SolverOptions(ddp=dict(tr_kappa=1.0))


def _first_step_across_a_bound(bound: float):
    """Rest to rest (``_rest_to_rest``, energy-optimal profile peaking at 0.6 m/s^2) under
    |u| <= bound with a stiff penalty that the model of an inactive bound does not see:
    (problem, stages at the zero guess, gains, DDP's first full trial, its stage costs (N,),
    the expected decrease, the actual decrease)."""
    from daddy_core.da import functions as dm
    from daddy_core.solver import sweeps as D
    from daddy_core.solver.lagrangian import Multipliers, augmented_cost_terms
    from daddy_core.solver.options import Sweep

    base = _rest_to_rest(stage_cost=lambda x, u, dt, hom: u[0] * u[0] * dt)
    prob = Problem(**{**{f: getattr(base, f) for f in base.__dataclass_fields__},
                      "g_ineq": lambda x, u, dt: dm.stack([u[0] * u[0] / bound ** 2 - 1.0]),
                      "terminal_cost": lambda x, xt: dm.dot(x - xt, x - xt) * 100.0,
                      "g_teq": None})
    U = np.zeros((prob.N, 1))
    st = D.Stages(prob, prob.rollout(U), U, Multipliers.initial(prob, 1e8), (0.0, 1.0), 1e-6)
    gains = D.backward_sweep(st, Sweep.STD, 0.0)
    trial = D.forward_pass(st, gains, 1.0, dyn=False)
    stage_costs, terminal = augmented_cost_terms(prob, trial.X, trial.U, st.mult, st.hom)
    return (prob, st, gains, trial, stage_costs, -(gains.dv1 + gains.dv2),
            st.cost - float(np.sum(stage_costs) + terminal))


def test_a_line_search_that_fails_at_a_few_stages_bounds_those_stages_only():
    """A bound of 0.55 that the first full step crosses at the first and the last stage (a
    tenth of the stages: a failure that is local): the failure is pinned on stages that crossed
    the bound (``globalization.blamed_stages``), never on the middle ones; the forward pass
    then clamps those stages' control changes to their new bounds. With and without the
    per-stage trust region the solve reaches the same optimum. A bound of 0.45, crossed at 5 of
    20 stages, is a failure of the whole step: nothing is blamed (one shorter step for every
    stage)."""
    from daddy_core.solver import globalization as G
    from daddy_core.solver import sweeps as D

    tol = SolverOptions().ddp.tol
    prob, st, gains, trial, stage_costs, expected, actual = _first_step_across_a_bound(0.55)
    assert actual < 0                                    # the full step fails
    crossed = np.flatnonzero(np.abs(trial.U[:, 0]) > 0.55)
    assert 0 < crossed.size <= prob.N // 10
    blamed = G.blamed_stages(st, trial, stage_costs, expected, actual, tol)
    assert blamed.size and set(blamed) <= set(crossed)
    # blamed once between accepted steps: the same stages failing again are not blamed again
    # (a shorter step for every stage is next); a stage not blamed yet is
    once = np.zeros(prob.N, dtype=bool)
    once[blamed] = True
    assert G.blamed_stages(st, trial, stage_costs, expected, actual, tol, blamed=once).size == 0
    once[blamed[0]] = False
    np.testing.assert_array_equal(
        G.blamed_stages(st, trial, stage_costs, expected, actual, tol, blamed=once), blamed)
    bounds = np.full(prob.N, np.inf)
    bounds[blamed] = 0.5 * np.abs(trial.U[blamed, 0])
    clamped = D.forward_pass(st, gains, 1.0, dyn=False, clamp=bounds)
    np.testing.assert_allclose(np.abs(clamped.U[blamed, 0]), bounds[blamed])
    free = np.setdiff1d(np.arange(prob.N), blamed)
    assert np.all(np.abs(clamped.dz[prob.nx:, free]) > 0)
    a = solve(prob, st.U, options=SolverOptions(ddp=dict(stage_trust=True)))
    b = solve(prob, st.U, options=SolverOptions(ddp=dict(stage_trust=False)))
    assert a.converged and b.converged
    np.testing.assert_allclose(a.U, b.U, atol=1e-6)
    assert np.max(np.abs(a.U)) <= 0.55 * (1 + 1e-9)

    prob, st, gains, trial, stage_costs, expected, actual = _first_step_across_a_bound(0.45)
    assert actual < 0
    assert np.sum(np.abs(trial.U[:, 0]) > 0.45) > prob.N // 10
    assert G.blamed_stages(st, trial, stage_costs, expected, actual, tol).size == 0


def test_a_trust_region_step_that_fails_at_a_few_stages_bounds_those_stages_only():
    """The trust region's rejected step blames stages as the line search's first trial does
    (``globalization.trust_region_step``): the first full step across the 0.55 bound comes
    back as a ``Blame`` of stages that crossed it, not as a rejection that shrinks every
    stage's region; with and without it the trust region reaches the line search's optimum."""
    from daddy_core.solver import globalization as G

    prob, st, gains, trial, *_ = _first_step_across_a_bound(0.55)
    crossed = np.flatnonzero(np.abs(trial.U[:, 0]) > 0.55)
    opts = SolverOptions(ddp=dict(globalization="trust_region"))
    out = G.trust_region_step(st, gains, False, opts, st.cost)
    assert isinstance(out, G.Blame) and set(out.stages) <= set(crossed)
    unblamed = opts.with_(ddp=dict(stage_trust=False))
    assert G.trust_region_step(st, gains, False, unblamed, st.cost) is None
    ref = solve(prob, st.U)
    for stage_trust in (True, False):
        sol = solve(prob, st.U, options=opts.with_(ddp=dict(stage_trust=stage_trust)))
        assert sol.converged, sol.reason
        np.testing.assert_allclose(sol.U, ref.U, atol=1e-6)


def test_a_cancel_flag_stops_the_solve_within_one_iteration_with_a_finite_answer():
    """``solve(cancel=...)``: set by the solver's first progress line (a homotopy step's, which
    carries its figures), the solve stops before its next iteration and says why; its answer is
    finite and not called converged."""
    import threading

    from daddy_core.solver.progress import ProgressLine
    case = load_case("earth_mars")
    flag, lines = threading.Event(), []

    def progress(line):
        lines.append(line)
        if isinstance(line, ProgressLine) and "homotopy_step" in line.figures:
            flag.set()

    sol = solve(problem_from_case(case), options=case_options(case, True), progress=progress,
                cancel=flag)
    steps = [ln.figures for ln in lines if isinstance(ln, ProgressLine)]
    assert flag.is_set() and steps[0]["homotopy_step"] == 1 and steps[0]["homotopy_steps"] > 1
    assert not sol.converged and "cancelled by the caller" in sol.reason
    assert sol.iterations["ddp"] <= 1
    assert np.all(np.isfinite(sol.U)) and np.all(np.isfinite(sol.X))


def test_a_drift_check_whose_flows_do_not_integrate_keeps_the_nominal():
    """``aul_safeguards.without_drift`` where the stage maps have walked beyond their radius
    and neither the restoration nor the controls' exact rollout integrates (DRO 3 revolutions
    from a random guess: a near-collision the drifted states hid raised "rk78 exceeded
    max_steps" out of ``solve``): the nominal stays, and no exception leaves the safeguard."""
    from dataclasses import replace

    from daddy_core.solver.aul_safeguards import without_drift
    from daddy_core.solver.lagrangian import Multipliers
    from daddy_core.solver.sweeps import Stages
    prob = double_integrator()
    U = np.full((prob.N, 3), 0.5)
    st = Stages(prob, prob.rollout(U), U, Multipliers.initial(prob, 1.0), (0.0, 1.0), 1e-12)

    def singular(x, u, dt):
        raise DaddyError("rk78 exceeded max_steps=10000 (stiff or singular dynamics?)")
    st.problem = replace(prob, step=singular)
    st.radius, st.walked = np.zeros(prob.N), np.ones(prob.N)   # (linear maps: radius inf)
    assert without_drift(st, SolverOptions(), None) is st


def test_a_violation_the_growing_penalty_does_not_move_stalls_before_the_cap():
    """``aul_safeguards.unmoved``: the last aul_stall_iter + 1 max violations within 1 % of
    each other, far above tol_aul (10x), with the penalty outweighing the cost in each of the
    last aul_stall_iter solves, stall the augmented Lagrangian whatever its penalty; a
    violation still falling, a plateau near the tolerance (Newton's to finish), a plateau under
    a penalty still weaker than the cost (a LEO raise's first four solves: 8.17e-4 to 8.11e-4
    at mu = 1 to 1e3, then falling), too short a history, or the stall rules switched off
    (aul_stall_iter = 0, the node's warm re-plans) do not. On the weak-thrust double
    integrator the solve stalls so before the cap and is still called infeasible."""
    from daddy_core.solver.aul_safeguards import unmoved
    opts = SolverOptions()
    tol, strong = opts.aul.tol, [True] * 5
    assert unmoved([0.5, 0.287, 0.2871, 0.2869, 0.287], strong, opts)
    assert not unmoved([0.5, 0.287, 0.2871, 0.2869, 0.287], [True, True, False, True, True],
                       opts)                                            # (a weak penalty)
    assert not unmoved([8.17e-4, 8.17e-4, 8.16e-4, 8.11e-4], [False] * 4, opts)
    assert not unmoved([0.5, 0.30, 0.29, 0.28, 0.27], strong, opts)     # still falling (10 %)
    assert not unmoved([5 * tol] * 5, strong, opts)                      # near the tolerance
    assert unmoved([20 * tol] * 4, strong[:4], opts)
    assert not unmoved([0.287] * 3, strong[:3], opts)                    # too short
    assert not unmoved([0.287] * 5, strong, opts.with_(aul=dict(stall_iter=0)))
    p = double_integrator(**INFEASIBLE["thrust too weak for the time"][0])
    sol = solve(p, np.zeros((p.N, p.nu)))
    assert sol.infeasible and "unmoved while the penalty grew" in sol.reason
