"""PDDP (issue 48): its answers and CPU beside the thrust-controlled fuel solve, and its
robustness from random costate guesses beside single shooting (scipy), the paper's Table 3.

    .venv/bin/python bench/bench_pddp.py table [--cases dro_dro_pddp dro_dro_2rev_pddp]
    .venv/bin/python bench/bench_pddp.py robustness [--case dro_dro_pddp] [--guesses 100]
                                         [--half-width 1.0] [--seed 0] [--cap 120] [--jobs 2]

``table``: for each case, PDDP (``pddp.solve_pddp``, default options) and its polish
(``pddp.polish``) beside the case's thrust-controlled fuel solve from the catalogue guess, run
one after the other in this process: final masses, switches, CPU, and the ratio of CPUs.

``robustness``: ``--guesses`` random initial costates sigma_0 (7, scaled: ``costate_scale``)
drawn uniformly in [-h, h]^7 (h = ``--half-width``), each given to
- PDDP (default options, its rho continuation included): the guess is the costates sigma_0
  flown continuously through the stages (each stage starts from the costates the previous one
  ended with), so both methods start from the same trajectory; ``--cap`` bounds its whole
  continuation (wall clock);
- single shooting: scipy.optimize.root (MINPACK hybrd) on the 7 unknowns sigma_0 of one stage
  spanning the flight, through the same rho continuation (each rho's root from the last), the
  residual [r(tf) - r_t, v(tf) - v_t, lambda_m(tf)] (the transversality of the free final
  mass), its Jacobian from the DA flow (first order).
Success: converged at the last rho -- PDDP with max violation <= 1e-9; shooting: MINPACK's
success with the residual <= 1e-9. Masses of the successes are printed, and the ratio of
success rates.
"""
from __future__ import annotations

import argparse
import concurrent.futures
import os
import platform
import time

import numpy as np

from daddy_core.catalogue import load_case, problem_from_case
from daddy_core.costate import costate_problem
from daddy_core.da import functions as dm
from daddy_core.da.core import constant, variables
from daddy_core.errors import DaddyError
from daddy_core.pddp import PDDPOptions, polish, solve_pddp, throttle_switches
from daddy_core.solver import case_options, solve

SUCCESS_VIOLATION = 1e-9


def table(cases) -> None:
    print(f"{'case':18s} {'PDDP kg':>9s} {'sw':>3s} {'CPU s':>7s} | {'polished kg':>11s} {'sw':>3s} "
          f"{'CPU s':>6s} | {'thrust-ctl kg':>13s} {'sw':>3s} {'CPU s':>6s} | PDDP+polish / thrust")
    for name in cases:
        case = load_case(name)
        u_max = float(case.units.thrust(case.spacecraft.max_thrust_n))
        r = solve_pddp(case)
        t = time.process_time()
        p = polish(case, r)
        t_polish = time.process_time() - t
        problem = problem_from_case(case)
        t = time.process_time()
        d = solve(problem, case.cold_guess(problem.N), fuel_optimal=True,
                  options=case_options(case, True))
        t_direct = time.process_time() - t
        print(f"{name:18s} {r.final_mass_kg:9.3f} {r.switches:3d} {r.cpu_s:7.1f} | "
              f"{p.final_mass_kg:11.3f} {throttle_switches(p, u_max):3d} {t_polish:6.1f} | "
              f"{d.final_mass_kg:13.3f} {throttle_switches(d, u_max):3d} {t_direct:6.1f} | "
              f"{(r.cpu_s + t_polish) / t_direct:.1f}x"
              + ("" if r.solution.converged and p.converged and d.converged else
                 f"  (converged: PDDP {r.solution.converged}, polish {p.converged}, "
                 f"thrust {d.converged})"))


def _continuous(problem, sigma0) -> np.ndarray:
    """(N, 7): sigma_0 flown through the stages without jumps (each stage's costates where the
    last one's ended)."""
    step = problem.step
    x, lam, out = np.asarray(problem.x0, float), step.costates(sigma0), []
    for dt in problem.stage_dt:
        out.append(lam / step.scale)
        z = np.asarray(step.flow14.flow(np.r_[x, lam], lam, dt))
        x, lam = z[:7], z[7:]
    return np.array(out)


def _pddp(case_name: str, sigma0, cap: float) -> tuple:
    case = load_case(case_name)
    o = PDDPOptions()
    guess = _continuous(costate_problem(case, o.stages, o.sharpness[0]), sigma0)
    opts = PDDPOptions(solver=o.solver.with_(run=dict(time_budget_s=cap)))
    t = time.process_time()
    try:
        r = solve_pddp(case, guess, opts)
    except Exception as exc:  # noqa: BLE001  a crash is a failed run, reported
        return False, float("nan"), time.process_time() - t, f"{type(exc).__name__}: {exc}"
    ok = (r.solution.converged and r.solution.max_violation <= SUCCESS_VIOLATION
          and r.rho == o.sharpness[-1])
    return ok, r.final_mass_kg, time.process_time() - t, ""


def _shoot(case_name: str, sigma0) -> tuple:
    """Single shooting through PDDP's continuation: each rho's root from the last one's."""
    case = load_case(case_name)
    t = time.process_time()
    s, ok, mass = np.asarray(sigma0, float), False, float("nan")
    for rho in PDDPOptions().sharpness:
        ok, mass, s = _shoot_at(case, rho, s)
        if not ok:
            break
    return ok, mass, time.process_time() - t


def _shoot_at(case, rho: float, sigma0) -> tuple:
    from scipy.optimize import root
    problem = costate_problem(case, 1, rho)
    step, x0, T = problem.step, problem.x0, float(problem.stage_dt[0])
    target = problem.x_target[:6]

    def residual(s):
        lam = step.costates(s)
        z = np.asarray(step.flow14.flow(np.r_[x0, lam], lam, T))
        return np.r_[z[:6] - target, z[13]], z

    def jacobian(s):
        sig = variables(np.asarray(s, float)[:, None], order=1, n=7)
        lam = step.costates(sig)
        x = constant(np.asarray(x0, float)[:, None], 7, 1)
        Z = step.flow14(dm.concatenate([x, lam]), lam, np.array([T]), 0.0)
        J = Z.linear()[:, 0, :]
        return np.r_[J[:6], J[13:14]]

    try:
        sol = root(lambda s: residual(s)[0], np.asarray(sigma0, float), jac=jacobian,
                   method="hybr", options=dict(maxfev=200))
        res, z = residual(sol.x)
        ok = bool(sol.success) and float(np.max(np.abs(res))) <= SUCCESS_VIOLATION
        return ok, float(z[6] * case.spacecraft.wet_mass_kg), sol.x
    except (DaddyError, ArithmeticError, ValueError):   # a flow that blew up
        return False, float("nan"), sigma0


def robustness(case_name: str, n: int, half_width: float, seed: int, cap: float,
               jobs: int) -> None:
    rng = np.random.default_rng(seed)
    draws = rng.uniform(-half_width, half_width, size=(n, 7))
    t = time.perf_counter()
    with concurrent.futures.ProcessPoolExecutor(jobs) as pool:
        pddp = list(pool.map(_pddp, [case_name] * n, draws, [cap] * n))
        shoot = list(pool.map(_shoot, [case_name] * n, draws))
    for label, runs in (("PDDP", pddp), ("single shooting", shoot)):
        ok = [r for r in runs if r[0]]
        masses = np.array([r[1] for r in ok])
        cpu = np.array([r[2] for r in runs])
        spread = (f", final masses {masses.min():.3f}-{masses.max():.3f} kg (median "
                  f"{np.median(masses):.3f})" if len(ok) else "")
        print(f"{label:16s} {len(ok):4d} / {n} converged ({100 * len(ok) / n:.1f} %){spread}; "
              f"CPU median {np.median(cpu):.1f} s, max {cpu.max():.1f} s")
    for i, r in enumerate(pddp):
        if r[3]:
            print(f"PDDP guess {i} raised {r[3]}")
    both = sum(a[0] and b[0] for a, b in zip(pddp, shoot))
    n_pddp, n_shoot = sum(r[0] for r in pddp), sum(r[0] for r in shoot)
    print(f"both {both}, PDDP alone {n_pddp - both}, shooting alone {n_shoot - both}; "
          f"ratio PDDP / shooting {n_pddp / max(n_shoot, 1):.2f}")
    print(f"guesses sigma_0 ~ U[-{half_width:g}, {half_width:g}]^7 (seed {seed}), rho "
          f"{PDDPOptions().sharpness}, {PDDPOptions().stages} costate stages, PDDP cap "
          f"{cap:g} s; machine {platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} cores, {jobs} jobs; {time.perf_counter() - t:.0f} s wall")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="command", required=True)
    a = sub.add_parser("table")
    a.add_argument("--cases", nargs="+", default=["dro_dro_pddp", "dro_dro_2rev_pddp"])
    b = sub.add_parser("robustness")
    b.add_argument("--case", default="dro_dro_pddp")
    b.add_argument("--guesses", type=int, default=100)
    b.add_argument("--half-width", type=float, default=1.0)
    b.add_argument("--seed", type=int, default=0)
    b.add_argument("--cap", type=float, default=120.0)
    b.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    if args.command == "table":
        table(args.cases)
    else:
        robustness(args.case, args.guesses, args.half_width, args.seed, args.cap, args.jobs)


if __name__ == "__main__":
    main()
