"""The global option (``solver/multistart.py``): many starts in parallel, the best converged
optimum and every distinct one, checked against a problem whose local optima are known in
closed form; the blended-state start; the halo transfer's better basin."""
import math

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from daddy_core.da import functions as dm
from daddy_core.errors import DaddyError
from daddy_core.problem import Problem
from daddy_core.solver import SolverOptions, WarmStart, solve
from daddy_core.solver.multistart import (Start, blended_states, multistart, random_starts,
                                          structured_starts)

N, DT, W, TILT = 10, 0.1, 10.0, 0.3


def _double_well() -> Problem:
    """A double integrator from rest whose terminal cost W ((x_N^2 - 1)^2 + TILT x_N) has two
    wells, the deeper at x_N < 0; energy stage cost, no constraints."""
    def step(x, u, dt):
        return dm.stack([x[0] + x[1] * dt + u[0] * (0.5 * dt * dt), x[1] + u[0] * dt])

    def well(x, xt):
        return W * ((x[0] * x[0] - 1.0) * (x[0] * x[0] - 1.0) + TILT * x[0])

    return Problem(name="double_well", nu=1, x0=np.zeros(2), x_target=np.zeros(2),
                   stage_dt=np.full(N, DT), step=step,
                   stage_cost=lambda x, u, dt, hom: u[0] * u[0] * dt, terminal_cost=well)


def _local_optima() -> list:
    """The problem's local minima, independently: reaching x_N = a from rest costs
    DT a^2 / |b|^2 at least (b: the controls' effect on x_N), so J(a) = that + the well; its
    two local minima over a, deeper first."""
    b = DT * DT * (N - np.arange(N) - 0.5)
    J = lambda a: DT * a * a / float(b @ b) + W * ((a * a - 1.0) ** 2 + TILT * a)   # noqa: E731
    return sorted(minimize_scalar(J, bounds=bounds, method="bounded",
                                  options={"xatol": 1e-12}).fun
                  for bounds in ((-3.0, 0.0), (0.0, 3.0)))


@pytest.mark.parametrize("jobs", [1, 2])
def test_multistart_finds_both_wells_and_returns_the_deeper(jobs):
    """From the structured and 6 random starts, in this process or two forked workers: both
    local optima found (each to 1e-6 of the closed form: the default tolerances' precision,
    1.2e-7 measured), the deeper one returned as best."""
    deep, shallow = _local_optima()
    res = multistart(_double_well(), random=6, seed=1, jobs=jobs)
    assert len(res.runs) == len(structured_starts(_double_well())) + 6
    values = [o.value for o in res.optima]
    assert len(values) == 2, res.summary()
    assert values[0] == pytest.approx(deep, abs=1e-6) and values[1] == pytest.approx(shallow,
                                                                                       abs=1e-6)
    assert res.best is res.optima[0].solution and res.best.converged
    assert res.best.X[-1, 0] < 0 < res.optima[1].solution.X[-1, 0]
    assert sum(len(o.starts) for o in res.optima) == sum(r.converged for r in res.runs)
    assert "2 distinct optima" in res.summary()


def test_a_start_the_problem_refuses_is_a_failed_run_not_an_error():
    """A guess of the wrong shape is one failed run, reported with its reason; the other
    starts still give the optimum."""
    starts = [Start("bad", np.zeros((N + 1, 1))), Start("cold", np.full((N, 1), 1e-6))]
    res = multistart(_double_well(), starts)
    bad = res.runs[0]
    assert not bad.converged and math.isnan(bad.value) and "guess" in bad.reason
    assert res.best is not None and res.best.converged
    with pytest.raises(DaddyError, match="at least one start"):
        multistart(_double_well(), [])
    with pytest.raises(DaddyError, match="jobs"):
        multistart(_double_well(), jobs=0)


def test_blended_states_join_the_departure_and_arrival_orbits():
    """The blend is the ballistic departure at the start, the arrival orbit (x_target
    propagated backwards) at the end, and their smooth-step mix between."""
    p = _double_well()
    p = Problem(**{**p.__dict__, "x0": np.array([0.0, 1.0]), "x_target": np.array([2.0, -1.0])})
    X = blended_states(p)
    t = np.arange(N + 1) * DT
    departure = np.stack([t, np.ones_like(t)], axis=1)                  # x = t, v = 1
    T = N * DT
    arrival = np.stack([2.0 - (t - T), -np.ones_like(t)], axis=1)       # x = 2 - (t - T), v = -1
    s = (t / T) ** 2 * (3 - 2 * t / T)
    assert np.allclose(X, (1 - s)[:, None] * departure + s[:, None] * arrival, atol=1e-14)
    assert len(random_starts(p, 3, seed=0)) == 3


def test_a_state_guess_starts_the_restoration_and_a_wrong_one_is_named():
    """``WarmStart.X`` without maps: Newton's restoration starts from those states. Controls
    that lead into the deep well, with states that end in the shallow one, end in the shallow
    one; a wrong shape names the field."""
    deep, shallow = _local_optima()
    p = _double_well()
    U = np.full((N, 1), -1e-3)
    assert solve(p, U).cost == pytest.approx(deep, abs=1e-6)
    t = np.arange(N + 1) * DT / (N * DT)
    X = np.stack([0.9 * t * t, 0.9 * 2 * t / (N * DT)], axis=1)      # to x = 0.9 from rest
    warm = solve(p, WarmStart(U=U, X=X))
    assert warm.converged and warm.cost == pytest.approx(shallow, abs=1e-6)
    with pytest.raises(DaddyError, match=r"WarmStart.X must be \(11, 2\)"):
        solve(p, WarmStart(U=U, X=np.zeros((N, 2))), options=SolverOptions())


def test_multistart_finds_the_halo_transfers_better_basin():
    """The halo L2 -> L1 fuel transfer: the paper's guess ends at 973.9447 kg; the blended
    start at the independent transcription's better optimum, 981.4255 kg
    (../shared/reference/halo_l2_l1_fuel__blend.csv)."""
    from daddy_core.catalogue import load_case, problem_from_case
    from daddy_core.solver import case_options
    case = load_case("halo_l2_l1")
    p = problem_from_case(case)
    res = multistart(p, structured_starts(p), fuel_optimal=True, jobs=2,
                     options=case_options(case, True))
    assert res.best.final_mass_kg == pytest.approx(981.4255, abs=2e-3), res.summary()
    assert "blend" in res.optima[0].starts and any(
        abs(o.value - 973.9447) < 2e-3 for o in res.optima)


def test_daddy_solve_multistart_keeps_the_best_and_lists_the_optima(tmp_path, capsys):
    """``daddy solve CASE --multistart R``: the summary, the best written as the solution;
    a negative count is bad input (exit 2) naming the option."""
    from daddy_core.cli import main
    from daddy_core.solver import Solution
    out = tmp_path / "best.json"
    assert main(["solve", "double_integrator", "--multistart", "1", "--jobs", "1", "--quiet",
                 "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "4 starts, 4 converged, 1 distinct optima" in text
    assert Solution.from_json(str(out)).converged
    assert main(["solve", "double_integrator", "--multistart", "-1"]) == 2
    assert "--multistart" in capsys.readouterr().err


def test_multistart_on_a_dask_cluster_gives_the_local_optima():
    """The starts on a loopback Dask LocalCluster (the problem's lambdas go by cloudpickle):
    the same optima as in this process."""
    pytest.importorskip("distributed", reason="the campaigns extra (make test installs it)")
    from daddy_sim.campaign_executors import Executor, open_executor
    deep, shallow = _local_optima()
    with open_executor(Executor.DASK, 1) as (pool, what):
        assert "127.0.0.1" in what
        res = multistart(_double_well(), random=6, seed=1, executor=pool)
    assert [o.value for o in res.optima] == pytest.approx([deep, shallow], abs=1e-6)


def test_a_solve_stalled_short_of_its_target_is_restarted_from_the_blend():
    """``blend.restart_from_blend``: the Lyapunov L1 -> L2 transfer from zero thrust stalls
    0.205 from its target with the penalty at its cap (a local minimum of the violation); the
    solve then starts again from the blended states and returns the paper's optimum
    (997.49 kg), saying so. The guidance node's warm preset never restarts."""
    from daddy_core.catalogue import load_case, problem_from_case
    from daddy_core.solver import case_options
    case = load_case("lyapunov_l1_l2")
    p = problem_from_case(case)
    sol = solve(p, np.zeros((p.N, p.nu)), fuel_optimal=True, options=case_options(case, True))
    assert sol.converged and sol.max_violation <= 1e-10, sol.reason
    assert sol.final_mass_kg == pytest.approx(997.487, abs=0.01)
    assert "restarted from the blended states" in sol.reason and "max violation" in sol.reason
    warm = SolverOptions.warm_replan(case_options(case, True), 1e-6, 1e-3, True)
    assert not warm.end_game.blend_restart and not warm.end_game.certify_infeasibility


def test_an_unmet_end_or_one_far_from_stationary_is_worth_a_restart_from_the_blend():
    """``blend.worth_restarting``: unmet constraints, and also a feasible end whose KKT
    polishing stalled far from a stationary point (Lyapunov from random guesses: 991-997 kg
    with a KKT residual of 1.4-1.7, converged at 997.4874 kg from the blend) are restarted; a
    converged solve, a polishing stalled near a stationary point (tight tolerances), and one
    stopped by its budget or a cancel are not."""
    from types import SimpleNamespace

    from daddy_core.solver import SolverOptions
    from daddy_core.solver.blend import FAR_FROM_STATIONARY, worth_restarting
    opts = SolverOptions()
    unmet = SimpleNamespace(converged=False, max_violation=0.2, kkt_residual=None)
    far = SimpleNamespace(converged=False, max_violation=0.0, kkt_residual=1.5)
    near = SimpleNamespace(converged=False, max_violation=0.0,
                           kkt_residual=0.5 * FAR_FROM_STATIONARY)
    done = SimpleNamespace(converged=True, max_violation=0.0, kkt_residual=1e-9)
    assert worth_restarting(unmet, opts, False) and worth_restarting(far, opts, False)
    assert not worth_restarting(near, opts, False) and not worth_restarting(done, opts, False)
    assert not worth_restarting(unmet, opts, True) and not worth_restarting(far, opts, True)
    # the blend is a guess for the restoration: without it there is nothing to restart from
    unrestored = opts.with_(start=dict(restore=False))
    assert not worth_restarting(unmet, unrestored, False)
    assert not worth_restarting(far, unrestored, False)


@pytest.mark.parametrize("error", [ZeroDivisionError("float division by zero"),
                                   DaddyError("rk78 exceeded max_steps=10000")])
def test_a_blend_the_dynamics_cannot_fly_is_none(error):
    """Dynamics that raise while the blend is flown (PDDP's costate flow from its target's
    placeholder mass divides by zero; an integration through a singularity runs out of steps)
    give no blend, not an exception out of the solve's fallback."""
    p = _double_well()

    def step(x, u, dt):
        if dt < 0:
            raise error
        return p.step(x, u, dt)
    assert blended_states(Problem(**{**p.__dict__, "step": step})) is None


def test_a_restart_that_would_repeat_its_solve_stops_where_the_blend_is_not_restored():
    """``blend.restart_from_blend`` after a solve from the paper's cold guess (or zero
    thrust, the same start): where the blend is not restored, the restart would fly on from
    that same rollout and repeat the solve, so it stops there (``UnrestoredStates.STOP``);
    after a solve from another guess it goes on from the controls as before. A solve told to
    stop at an unrestored state guess ends at once, unconverged, its reason naming the
    option; the double integrator with too weak a thrust (not restorable) is still called
    infeasible."""
    from daddy_core.catalogue.infeasible import INFEASIBLE, double_integrator
    from daddy_core.solver.blend import PAPER_GUESS, restart_from_blend
    from daddy_core.solver.options import UnrestoredStates
    p = double_integrator(**INFEASIBLE["thrust too weak for the time"][0])
    first = solve(p, np.zeros((p.N, p.nu)),
                  options=SolverOptions().with_(end_game=dict(blend_restart=False,
                                                              certify_infeasibility=False)))
    assert not first.converged
    seen = []

    def spy(problem, guess, o):
        seen.append(o.start.unrestored_states)
        return solve(problem, guess, options=o)
    for guess, expected in ((np.zeros((p.N, p.nu)), UnrestoredStates.STOP),
                            (np.full((p.N, p.nu), PAPER_GUESS), UnrestoredStates.STOP),
                            (np.full((p.N, p.nu), 0.3), UnrestoredStates.FROM_CONTROLS)):
        seen.clear()
        assert restart_from_blend(p, first, SolverOptions(), spy, None, guess) is None
        assert seen == [expected]
    blend = WarmStart(U=np.full((p.N, p.nu), PAPER_GUESS), X=blended_states(p))
    stop = SolverOptions().with_(start=dict(unrestored_states="stop"),
                                 end_game=dict(blend_restart=False))
    sol = solve(p, blend, options=stop)
    assert not sol.converged and "start.unrestored_states" in sol.reason
    assert solve(p, np.zeros((p.N, p.nu))).infeasible
    with pytest.raises(DaddyError, match="unrestored_states"):
        SolverOptions().with_(start=dict(unrestored_states="sometimes"))
