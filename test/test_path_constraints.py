"""Path constraints held between the nodes (``Problem.g_path``): a keep-out sphere around the
Moon on the L2 -> L1 halo transfer, checked against scipy's dense output, the exchange step,
the node-wise-only variant's dip, bad input and an infeasible radius, and the guidance
planner's refusal of plans that dip into the keep-out."""
from dataclasses import replace

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import minimize_scalar

from daddy_core.catalogue import load_case, problem_from_case
from daddy_core.catalogue.rendezvous import cw_rendezvous
from daddy_core.da import functions as dm
from daddy_core.errors import DaddyError
from daddy_core.path_constraints import PathMargin, dense_margin, tightened
from daddy_core.solver import Solution, SolverOptions, case_options, solve
from daddy_ros.assessment import assess
from daddy_ros.config import PLANS_DIR
from daddy_ros.planner import GuidancePlanner

HALO = load_case("halo_l2_l1")
PLAN = Solution.from_json(PLANS_DIR / "halo_l2_l1_fuel.json")   # solved without a keep-out


def moon_distance_km(problem, X, U):
    """Independent check: the minimum Moon distance [km] of every stage re-propagated from its
    own start with scipy's DOP853 and its dense output (500 instants per stage, then a bounded
    scalar minimisation around the closest one)."""
    mu, lu = problem.units.gm, problem.units.lu_km
    best = np.inf
    for k in range(problem.N):
        t0, h = problem.stage_t0[k], problem.stage_dt[k]
        r = solve_ivp(lambda t, x: np.asarray(problem.rhs(t, x, U[k]), float), (t0, t0 + h),
                      X[k], method="DOP853", rtol=1e-12, atol=1e-12, dense_output=True)

        def dist(t):
            x = r.sol(t)
            return float(np.linalg.norm(x[:3] - [1.0 - mu, 0.0, 0.0]))
        ts = np.linspace(t0, t0 + h, 500)
        i = int(np.argmin([dist(t) for t in ts]))
        lo, hi = ts[max(i - 1, 0)], ts[min(i + 1, ts.size - 1)]
        best = min(best, dist(ts[i]),
                   minimize_scalar(dist, bounds=(lo, hi), method="bounded",
                                   options={"xatol": 1e-12}).fun)
    return best * lu


def test_dense_margin_matches_scipy_dense_output():
    # the unconstrained plan against a 1 km keep-out: margin = minimum distance - 1 km
    problem = problem_from_case(HALO, r_min_km=1.0)
    pm = dense_margin(problem, PLAN.X, PLAN.U)
    true_min = pm.margin * problem.units.lu_km + 1.0
    assert true_min == pytest.approx(moon_distance_km(problem, PLAN.X, PLAN.U), abs=1e-4)
    # (the grid holds the samples: nothing rises above them by less than round-off)
    assert np.all(pm.excess >= -1e-12) and 0.0 <= pm.tau <= 1.0


@pytest.fixture(scope="module")
def free():
    """The transfer without a keep-out, solved as the keep-out ones are."""
    return solve(problem_from_case(HALO), options=case_options(HALO, True))


@pytest.fixture(scope="module")
def keep_out_25000():
    problem = problem_from_case(HALO, r_min_km=25_000.0)
    return problem, solve(problem, options=case_options(HALO, True))   # (solve's own guess)


def test_keep_out_holds_between_the_nodes(free, keep_out_25000):
    problem, sol = keep_out_25000
    lu = problem.units.lu_km
    # the transfer without the keep-out passes closer than 25,000 km: the constraint binds
    assert free.converged and moon_distance_km(problem, free.X, free.U) < 24_900.0
    assert sol.converged, sol.reason
    assert sol.max_violation <= 1e-10 and sol.repropagation_miss <= 1e-9
    assert sol.min_path_margin >= -1e-10
    true_min = moon_distance_km(problem, sol.X, sol.U)
    assert true_min >= 25_000.0 - 1e-5            # held along the trajectory (scipy's check)
    assert true_min <= 25_005.0                   # touching it: not a needlessly wide berth
    assert true_min == pytest.approx(25_000.0 + sol.min_path_margin * lu, abs=1e-4)
    # keeping out costs propellant (not much for 540 km: 4 g measured)
    assert free.final_mass_kg - 0.5 < sol.final_mass_kg < free.final_mass_kg
    assert sol.to_dict()["min_path_margin"] == sol.min_path_margin


@pytest.fixture(scope="module")
def node_wise():
    """One sample per stage (the stage end: the nodes) and no exchange."""
    problem = replace(problem_from_case(HALO, r_min_km=25_000.0), path_samples=1)
    return problem, solve(problem, options=case_options(
        HALO, True, end_game=dict(path_exchange_rounds=0)))


def test_node_wise_constraint_dips_between_nodes(node_wise):
    # the constraint holds at every node and the trajectory still passes inside the keep-out
    # between two of them
    problem, sol = node_wise
    assert not sol.converged and "between them" in sol.reason
    assert sol.max_violation <= 1e-10                      # the nodes meet it
    dip = -sol.min_path_margin * problem.units.lu_km
    assert dip > 10.0                                       # km inside the keep-out
    assert moon_distance_km(problem, sol.X, sol.U) == pytest.approx(25_000.0 - dip, abs=1e-3)
    assert [r["label"] for r in sol.violations if r["name"] == "g_path[0]"] == ["keep-out"]


def test_the_exchange_tightens_the_stage_whose_samples_hold_the_worst_point():
    """``tightened``: a stage whose dense maximum lies between its samples is tightened by 1.25
    times its excess (or its old offset plus 1.25 times the violation); one whose maximum is
    its start node -- the previous stage's last sample -- leaves its own samples alone and
    tightens the previous stage by 1.25 times the violation. (Before, the keep-out rendezvous's
    stage 20 held its samples 5.3 m inside for a 6.9e-10 km violation at its start node: the
    swept solve's propellant 1.25770 instead of 1.25732.)"""
    worst = np.array([[-1.0, -1.0, 6.6e-4, 6.9e-10, -1.0]])
    excess = np.array([[0.0, 0.0, 6.6e-4, 5.3e-3, 0.0]])
    where = np.array([[0.5, 0.5, 0.875, 0.0, 0.5]])
    pm = PathMargin(excess, worst, where)
    offset = tightened(None, pm, 1e-10)
    np.testing.assert_allclose(offset, [[0.0, 0.0, 1.25 * 6.6e-4, 0.0, 0.0]])
    start = np.array([[0.0, 0.0, 1e-3, 0.0, 0.0]])      # an earlier round's offsets grow
    np.testing.assert_allclose(tightened(start, pm, 1e-10),
                               [[0.0, 0.0, 1e-3 + 1.25 * 6.6e-4, 0.0, 0.0]])
    node = replace(pm, worst=np.array([[-1.0, -1.0, -1.0, 6.9e-10, -1.0]]))
    np.testing.assert_allclose(tightened(None, node, 1e-10),
                               [[0.0, 0.0, 1.25 * 6.9e-10, 0.0, 0.0]], rtol=1e-12, atol=0)
    first = PathMargin(np.array([[5e-3, 0.0]]), np.array([[1e-9, -1.0]]),
                       np.array([[0.0, 0.5]]))           # stage 0's start is x0: no stage before
    np.testing.assert_allclose(tightened(None, first, 1e-10), [[1.25 * 5e-3, 0.0]])
    assert tightened(None, replace(pm, worst=np.minimum(worst, 0.0)), 1e-10) is None


def test_keep_out_around_the_start_is_infeasible_and_says_so_at_once():
    # x0 lies 81,514 km from the Moon: no control takes it out of a 90,000 km sphere
    problem = problem_from_case(HALO, r_min_km=90_000.0)
    sol = solve(problem, HALO.cold_guess(problem.N), options=case_options(HALO, True))
    assert not sol.converged and sol.infeasible and sol.reason.startswith("infeasible:")
    assert "x0" in sol.reason and "g_path[0]" in sol.reason
    assert sol.iterations["ddp"] == 0
    assert np.all(np.isfinite(sol.X)) and np.all(np.isfinite(sol.U))
    # the margin is the returned (guess's) trajectory's: at x0 alone 8,486 km inside
    assert sol.min_path_margin * problem.units.lu_km <= 81_513.7 - 90_000.0


def _with_g_path(g_path, **kw):
    return replace(problem_from_case(HALO), g_path=g_path, **kw)


@pytest.mark.parametrize("g_path, match", [
    (lambda x, u: dm.stack([x[0] * np.nan]), "g_path returned NaN"),
    (lambda x, u: x[0] - 2.0, r"g_path returned shape \(2,\)"),
    (lambda x, u: np.stack([x[0] - 2.0]), "g_path"),
    (lambda x, u: dm.stack([np.sqrt(x[0] * x[0]) - 2.0]), "g_path raised"),
])
def test_bad_g_path_is_refused_before_any_iteration(g_path, match):
    problem = _with_g_path(g_path)
    with pytest.raises(DaddyError, match=match):
        solve(problem, HALO.cold_guess(problem.N))


def test_g_path_needs_the_continuous_dynamics():
    with pytest.raises(DaddyError, match="rhs"):
        replace(problem_from_case(HALO), g_path=lambda x, u: dm.stack([x[0]]), rhs=None)
    with pytest.raises(DaddyError, match="path_samples"):
        _with_g_path(lambda x, u: dm.stack([x[0]]), path_samples=0)
    with pytest.raises(DaddyError, match="r_min_km"):
        problem_from_case(HALO, r_min_km=-5.0)


def test_planner_refuses_plans_that_dip_into_the_keep_out(keep_out_25000, node_wise):
    problem, sol = keep_out_25000
    planner = GuidancePlanner("halo_l2_l1", r_min_km=25_000.0)
    # the bundled plan passes 24,391 km from the Moon: not adopted as a nominal
    with pytest.raises(DaddyError, match="keep-out between the nodes by 608"):
        planner.load_plan(PLANS_DIR / "halo_l2_l1_fuel.json", 0.0)
    assert planner.plan is None
    verdict = assess(PLAN, planner.base_problem, 1e-8)   # (its samples show it already)
    assert not verdict.safe and "path constraint" in verdict.reason
    # a plan that meets the constraint at every node and dips in between: the dense check
    verdict = assess(node_wise[1], node_wise[0], 1e-8)
    assert not verdict.safe and "between the nodes" in verdict.reason
    verdict = assess(sol, planner.rated_problems[-1], 1e-8)   # (solved at the full rating)
    assert verdict.safe and verdict.feasible and verdict.path_margin >= -1e-10


@pytest.mark.slow
@pytest.mark.parametrize("r_min_km, closest_km, mass_kg", [
    (20_000.0, 24_456.0, 973.9447),    # does not bind: the free transfer's closest approach
    (30_000.0, 30_000.0, 973.4195),    # binds by 5,500 km: 0.5 kg of propellant
])
def test_keep_out_from_the_case_guess(r_min_km, closest_km, mass_kg):
    """The r_min table as ``daddy solve halo_l2_l1 --r-min-km`` solves it (the case's guess)."""
    problem = problem_from_case(HALO, r_min_km=r_min_km)
    sol = solve(problem, HALO.cold_guess(problem.N), options=case_options(HALO, True))
    assert sol.converged, sol.reason
    assert sol.max_violation <= 1e-10 and sol.min_path_margin >= -1e-10
    true_min = moon_distance_km(problem, sol.X, sol.U)
    assert true_min >= r_min_km - 1e-5
    assert true_min == pytest.approx(closest_km, abs=5.0)
    assert sol.final_mass_kg == pytest.approx(mass_kg, abs=0.01)


def test_ddp_blames_a_stage_once_between_accepted_steps():
    """A Clohessy-Wiltshire rendezvous past a 1.5 km keep-out (``catalogue.rendezvous``; its
    energy-optimal free path passes 1.31 km from the target), from the free optimum: the
    augmented Lagrangian's first DDP solve (mu = 1) trades the terminal conditions for the
    keep-out and ends 0.47 off; the second's first trial fails at four stages whose keep-out samples the other stages'
    steps push into the sphere (the penalty's curvature there is the keep-out's, not the
    quadratic model's). Bounding those stages' controls cannot mend that: blamed again and
    again they held DDP at its nominal for all of ddp_max_iter, the violation frozen at 0.47
    through every penalty up to mu_max. Blamed once between accepted steps, the next failure
    is a shorter step for every stage, and the loop makes progress
    (``globalization.blamed_stages``, design notes: blame once)."""
    from daddy_core.solver.aul import aul
    from daddy_core.solver.ddp import DDPStats
    from daddy_core.solver.lagrangian import Multipliers
    from daddy_core.solver.options import Method
    from daddy_core.solver.sweeps import Stages

    free = solve(cw_rendezvous(), fuel_optimal=False)
    assert free.converged
    problem = cw_rendezvous(keep_out_km=1.5)
    assert dense_margin(problem, free.X, free.U).margin < -0.15   # the free path is inside
    opts = SolverOptions(aul=dict(max_iter=3))
    st = Stages(problem, free.X, free.U, Multipliers.initial(problem, opts.aul.mu_init),
                (0.0, 1e-2), opts.eps_da)
    lines = []
    res = aul(st, Method.DYN, opts, DDPStats(), progress=lines.append)
    violations = [line.figures["max_violation"] for line in lines
                  if getattr(line, "figures", {}).get("max_violation") is not None]
    first, last = violations[0], res.max_violation
    assert first > 0.3                       # the trade of the first solve (0.47 measured)
    assert last < 0.5 * first                # then on its way back (0.15 measured; 0.47 before)


def test_the_free_rendezvous_meets_its_independent_fuel_optimum():
    """A user's problem with a declared thrust (``catalogue.rendezvous``: ``thrust_dynamics``,
    pseudo-Huber cost, no keep-out) solved fuel-optimal from the default guess ends in the
    exact fuel form at the optimum of the same discrete problem that scipy's SLSQP finds
    (``rendezvous_reference``, no daddy solver code): 0.81892196 km/(1/n) both, measured."""
    from daddy_core.catalogue.rendezvous import propellant
    from daddy_core.catalogue.rendezvous_reference import slsqp_reference
    problem = cw_rendezvous()
    sol = solve(problem, fuel_optimal=True)
    assert sol.converged and sol.exact_fuel, sol.reason
    free, _, _ = slsqp_reference(cw_rendezvous(), None)
    assert propellant(sol.U, problem.stage_dt) == pytest.approx(free, rel=1e-6)
