"""Command line: ``daddy solve CASE [...]`` (also ``python -m daddy_core solve ...``).

Exit status 0 when the solve converged, 1 when it did not (with a one-line reason on stderr),
2 for bad arguments or bad input.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from datetime import datetime, timedelta, timezone

import numpy as np

from . import trajectory_output
from .dynamics.units import DAY_S
from .errors import DaddyError
from .catalogue import list_cases, load_case, load_thrust_case, problem_from_case
from .catalogue.free_time import ANGLE
from .catalogue.revolutions import RevolutionSearch, search_revolutions
from .catalogue.sail_cases import (SAIL_METHOD, SailCase, SailGuess, sail_options, solve_sail,
                                   write_sail_csv)
from .catalogue.run_times import expected_run_time, measured_on, read_run_times
from .pddp import Parametrisation, PDDPOptions
from .solver import METHODS, Globalization, MultiplierUpdate, Solution, case_options, solve


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="daddy", description="DADDy low-thrust trajectory optimiser")
    sub = ap.add_subparsers(dest="command", required=True)
    s = sub.add_parser("solve", help="solve a catalogue case (or a case file)")
    s.add_argument("case", help=f"case name ({', '.join(list_cases())}) or path to a .json file")
    s.add_argument("--method", default=None, choices=METHODS,
                   help="DDP variant (default: dyn; hessdyn for solar-sail cases)")
    s.add_argument("--guess", choices=[g.value for g in SailGuess], default=None,
                   help="solar-sail cases: the initial controls (default: the steering law)")
    g = s.add_mutually_exclusive_group()
    g.add_argument("--energy", action="store_true", help="energy-optimal only (default for "
                   "the double integrator)")
    g.add_argument("--fuel", action="store_true", help="fuel-optimal homotopy (default)")
    s.add_argument("--no-polish", action="store_true", help="skip the Newton polishing")
    s.add_argument("--warm-start", metavar="JSON", help="initial controls from a solution file")
    s.add_argument("--stages", type=int, help="override the stage count N")
    s.add_argument("--r-min-km", type=float, metavar="KM",
                   help="keep the whole trajectory, between the nodes too, at least KM from "
                        "the Moon (Earth-Moon cases) or the Sun (Earth-Mars); reported as the "
                        "minimum distance of the dense re-propagation")
    s.add_argument("--free-tof", type=float, nargs=2, metavar=("LO", "HI"),
                   help="the time of flight free in [LO, HI] days (Earth-Mars: Mars moves on "
                        "its orbit to the arrival); a case file's problem.tof_window")
    s.add_argument("--policy", type=int, metavar="ORDER", default=0,
                   help="also build the solution's feedback laws of this order (1-5; the JSON "
                        "holds them): docs/policies.md")
    s.add_argument("--free-revolutions", type=float, nargs=2, metavar=("LO", "HI"),
                   help="Earth-centred cases: the arrival angle free in [LO, HI] revolutions, "
                        "one solve (a case file's problem.revolutions_window)")
    s.add_argument("--multistart", type=int, metavar="RANDOM", default=None,
                   help="the global option: solve from the cold guess, zero thrust, the "
                   "blended states and RANDOM random guesses in parallel; keep the best "
                   "converged optimum and list the distinct ones")
    s.add_argument("--jobs", type=int, default=2, help="--multistart's worker processes")
    s.add_argument("--seed", type=int, default=0, help="--multistart's random guesses' seed")
    s.add_argument("--json", metavar="FILE", help="write the solution as JSON")
    s.add_argument("--npz", metavar="FILE", help="write the solution as NPZ")
    _output_arguments(s)
    s.add_argument("--globalization", choices=[g.value for g in Globalization],
                   help="DDP step control (default: the solver's)")
    s.add_argument("--map-order", type=int, metavar="K",
                   help="the stage maps' order, 2-6 (default 2): docs/policies.md")
    s.add_argument("--multiplier-update", choices=[m.value for m in MultiplierUpdate],
                   help="how the augmented Lagrangian moves its multipliers (default "
                        "first_order; sweep: the terminal ones in every backward sweep)")
    s.add_argument("--time-budget", type=float, metavar="S", help="wall-clock budget in seconds")
    s.add_argument("--search-revolutions", type=float, metavar="SPAN",
                   help="Earth-centred cases: search the transfer's revolutions within SPAN "
                        "around the case's own for the heaviest final mass (golden section)")
    s.add_argument("--search-tol", type=float, default=None, metavar="REVS",
                   help="the search's final bracket in revolutions (default SPAN / 20)")
    s.add_argument("--parametrisation", choices=[p.value for p in Parametrisation],
                   default=Parametrisation.THRUST.value,
                   help="costate: Pontryagin-Bellman DDP over the costates of a few long stages, "
                        "then polished to the exact optimum (Earth-Moon CR3BP cases; "
                        "docs/costate-stages.md)")
    s.add_argument("--costate-stages", type=int, default=PDDPOptions.stages, metavar="N",
                   help="--parametrisation costate: the costate stages")
    s.add_argument("--sharpness", type=float, nargs="+", metavar="RHO",
                   default=list(PDDPOptions.sharpness),
                   help="--parametrisation costate: the throttle sharpness rho of each "
                        "continuation step")
    s.add_argument("--quiet", action="store_true", help="no progress lines")
    e = sub.add_parser("export", help="a solution file (daddy solve --json) as CSV, OEM or "
                       "the mission plot, without solving again")
    e.add_argument("solution", help="a solution JSON file")
    _output_arguments(e)
    sub.add_parser("list", help="list the catalogue cases")
    q = sub.add_parser("predict", help="a case's terminal dispersion from an initial-state "
                       "error: DA prediction beside a Monte Carlo (docs/policies.md)")
    q.add_argument("case", help="case name or path to a .json file (Cartesian cases)")
    q.add_argument("--energy", action="store_true", help="the energy optimum (default: fuel)")
    q.add_argument("--policy", type=int, default=1, metavar="ORDER",
                   help="fly the feedback laws of this order (0: the plan's controls)")
    q.add_argument("--sigma-km", type=float, default=10.0, help="initial position error, "
                   "1 sigma per axis [km]")
    q.add_argument("--sigma-m-s", type=float, default=0.01, help="initial velocity error, "
                   "1 sigma per axis [m/s]")
    q.add_argument("--samples", type=int, default=2000, help="Monte Carlo flights")
    q.add_argument("--seed", type=int, default=1)
    return ap


def _output_arguments(p: argparse.ArgumentParser) -> None:
    """The files a solution is written to (``daddy solve`` and ``daddy export``)."""
    p.add_argument("--csv", metavar="FILE", help="write the trajectory as CSV (node times, SI "
                   "states, Earth-centred cases' elements, thrust)")
    p.add_argument("--oem", metavar="FILE", help="write a CCSDS OEM 2.0 (km, km/s): EME2000 "
                   "(Earth-centred), ecliptic J2000 (Sun-centred), the Earth-Moon frame "
                   "--oem-frame (CR3BP)")
    p.add_argument("--oem-frame", choices=[f.value for f in trajectory_output.OemFrame],
                   default=trajectory_output.OemFrame.INERTIAL.value,
                   help="CR3BP cases: the OEM's frame (default inertial: the rotating frame's "
                        "axes at the epoch)")
    p.add_argument("--epoch", type=_utc, default=None, metavar="ISO",
                   help="start epoch of the OEM, UTC (default J2000, 2000-01-01T12:00:00)")
    p.add_argument("--plot", metavar="FILE", help="write a PNG: the mission plot (3-D "
                   "trajectory with the bodies to scale, thrust arrows, thrust, mass and orbit "
                   "histories; needs matplotlib)")


def _write_outputs(sol: Solution, args, case=None, u_max_n: float | None = None) -> None:
    """The --csv, --oem and --plot files of a thrust solution."""
    if args.csv:
        trajectory_output.write_csv(sol, args.csv)
    if args.oem:
        trajectory_output.write_oem(sol, args.oem, args.epoch or trajectory_output.J2000,
                                    frame=trajectory_output.OemFrame(args.oem_frame))
    if args.plot:
        if sol.units.get("system") in trajectory_output.OEM_SYSTEMS:
            from .mission_plot import plot_mission
            plot_mission(sol, args.plot, case=case, u_max_n=u_max_n)
        else:
            from .plotting import plot_solution
            plot_solution(sol, args.plot, u_max_n=u_max_n)


def _export(args) -> int:
    """``daddy export``: a saved solution's files."""
    try:
        sol = Solution.from_json(args.solution)
        try:
            case = load_case(sol.case)
        except DaddyError:
            case = None   # a case file no longer at hand: no departure/arrival orbits
        u_max = (case.spacecraft.max_thrust_n if case is not None and
                 getattr(case, "spacecraft", None) is not None else None)
        if not (args.csv or args.oem or args.plot):
            raise DaddyError("export: give --csv, --oem or --plot")
        _write_outputs(sol, args, case, u_max)
    except (DaddyError, OSError) as exc:
        print(f"daddy: error: {exc}", file=sys.stderr)
        return 2
    for what, f in (("csv", args.csv), ("oem", args.oem), ("plot", args.plot)):
        if f:
            print(f"{what}: {f}")
    return 0


def _utc(text: str) -> datetime:
    """--epoch: an ISO 8601 date-time, UTC unless it names its offset."""
    try:
        t = datetime.fromisoformat(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"not an ISO 8601 date-time: {text!r}") from exc
    return t if t.tzinfo else t.replace(tzinfo=timezone.utc)


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    if args.command == "list":
        run_times = read_run_times()
        for name in list_cases():
            c = load_case(name)
            revs = "" if c.revolutions is None else f", {c.revolutions:.1f} revolutions"
            expected = expected_run_time(run_times, name)
            print(f"{name:16s} N = {c.stages}{revs}: {c.description}"
                  + (f" [expected: {expected}]" if expected else ""))
        if measured_on(run_times):
            print(f"(expected run times {measured_on(run_times)}: bench/bench_catalogue.py)")
        return 0
    if args.command == "predict":
        return _predict(args)
    if args.command == "export":
        return _export(args)
    try:
        case = load_case(args.case)
        if isinstance(case, SailCase):
            return _solve_sail(case, args)
        if args.guess:
            raise DaddyError("--guess is for solar-sail cases; give a thrust case's initial "
                             "controls with --warm-start")
        if Parametrisation(args.parametrisation) is Parametrisation.COSTATE:
            return _solve_costate(case, args)
        args.method = args.method or "dyn"
        if args.oem:
            trajectory_output.check_oem(case.units.name,
                                        trajectory_output.OemFrame(args.oem_frame), case.name)
        fuel = not args.energy and case.system != "double_integrator"
        if args.fuel:
            fuel = True
        if args.multistart is not None and (args.search_revolutions or args.warm_start):
            raise DaddyError("--multistart makes its own starts: it takes neither "
                             "--search-revolutions nor --warm-start")
        if args.search_revolutions and args.free_revolutions:
            raise DaddyError("--search-revolutions and --free-revolutions: the search solves "
                             "fixed angles; the free angle is one solve: give one of them")
        problem = problem_from_case(case, stages=args.stages, r_min_km=args.r_min_km,
                                    tof_window=args.free_tof,
                                    revolutions_window=args.free_revolutions)
        opts = case_options(case, fuel, run=dict(time_budget_s=args.time_budget),
                            policy=dict(order=args.policy), **_solver_changes(args))
        if args.warm_start:
            u0 = Solution.from_json(args.warm_start).U
        else:
            u0 = case.cold_guess(problem.N)
        progress = None if args.quiet else (lambda line: print(line, flush=True))
        if args.search_revolutions:
            found = _search(case, fuel, args)
            if found.best is None:
                print("daddy: not converged: no solve of the search was feasible",
                      file=sys.stderr)
                return 1
            sol = found.best
            problem = problem_from_case(case.with_revolutions(found.revolutions))
        elif args.multistart is not None:
            sol = _multistart(problem, u0, fuel, opts, args, case.name)
            if sol is None:
                return 1
        else:
            sol = solve(problem, u0, method=args.method, fuel_optimal=fuel,
                        polish=not args.no_polish, options=opts, case_name=case.name,
                        progress=progress)
    except DaddyError as exc:
        print(f"daddy: error: {exc}", file=sys.stderr)
        return 2
    if trajectory_output.is_earth_centred(sol) and np.all(np.isfinite(sol.X)):
        sol.cartesian_miss = trajectory_output.cartesian_miss(sol, case.cartesian_rhs())
    _report(sol)
    if sol.parameters and "tof" in sol.parameters:
        T = sol.parameters["tof"]
        print("  time of flight (free) " + (f"{T:.6f} (normalised)" if case.system ==
              "double_integrator" else f"{float(case.units.time_s(T)) / DAY_S:.4f} d"))
    if sol.parameters and ANGLE in sol.parameters:
        print(f"  revolutions (free) {sol.parameters[ANGLE] / (2 * math.pi):.4f}")
    for ph in sol.phases or ():
        _report_phase(ph)
    if args.policy:
        print(f"  feedback laws of order {args.policy}: {int(sol.policy.has_law.sum())} of "
              f"{sol.N} stages" if sol.policy is not None
              else f"  no feedback laws: {sol.policy_error}")
    if args.json:
        sol.to_json(args.json)
    if args.npz:
        sol.to_npz(args.npz)
    _write_outputs(sol, args, case, u_max_n=problem.u_max and float(
        case.units.thrust_n(problem.u_max)))
    if not sol.converged:
        print(f"daddy: not converged: {sol.reason}", file=sys.stderr)
        return 1
    return 0


def _multistart(problem, u0, fuel: bool, opts, args, case_name: str):
    """``daddy solve --multistart``: the best converged optimum (its summary printed), or
    None (a line on stderr) when no start converged."""
    from .solver.multistart import multistart, random_starts, structured_starts
    if args.multistart < 0:
        raise DaddyError(f"--multistart: the random starts must be >= 0, got {args.multistart}")
    starts = structured_starts(problem, u0) + random_starts(problem, args.multistart, args.seed)
    res = multistart(problem, starts, method=args.method, fuel_optimal=fuel,
                     polish=not args.no_polish, options=opts, case_name=case_name, jobs=args.jobs)
    print(res.summary())
    if res.best is None:
        print("daddy: not converged: no start of the multi-start converged", file=sys.stderr)
    return res.best


def _predict(args) -> int:
    """``daddy predict`` (``prediction``): exit 0, or 2 for bad input / a case it cannot take."""
    from .prediction import predict_case, report
    try:
        case = load_thrust_case(args.case)
        r = predict_case(case, not args.energy, args.policy, args.sigma_km, args.sigma_m_s,
                         args.samples, args.seed)
    except DaddyError as exc:
        print(f"daddy: error: {exc}", file=sys.stderr)
        return 2
    print(report(r))
    return 0


def _report_phase(ph: dict) -> None:
    """One line per phase of a multi-phase solution (``Solution.phases``)."""
    last = ph["first_stage"] + len(ph["U"]) - 1
    values = ", ".join(f"{k} {v:.9g}" for k, v in ph["parameters"].items())
    link = ph["link_multipliers"]
    print(f"  phase {ph['name']}: stages {ph['first_stage']}-{last}"
          + (f"; parameters {values}" if values else "")
          + ("" if link is None else "; link multipliers "
             + " ".join(f"{v:.9g}" for v in link)))


def _solve_costate(case, args) -> int:
    """``daddy solve CASE --parametrisation costate``: PDDP (``pddp.solve_pddp``) reported, then
    its polish to the exact optimum (unless --no-polish); --json holds the polished solution
    with the costate solve under ``pddp``. A DaddyError for bad input (exit status 2)."""
    from .pddp import polish, solve_pddp, throttle_switches
    refused = [name for name, given in (
        ("--method", args.method), ("--energy", args.energy), ("--warm-start", args.warm_start),
        ("--r-min-km", args.r_min_km), ("--search-revolutions", args.search_revolutions),
        ("--free-tof", args.free_tof), ("--free-revolutions", args.free_revolutions),
        ("--policy", args.policy)) if given]
    if args.no_polish and (args.oem or args.plot or args.csv):
        raise DaddyError("--csv, --oem, --plot: the polished thrust solution's; not with "
                         "--no-polish (the PDDP solution's controls are costates: --json)")
    if refused:
        raise DaddyError(f"{', '.join(refused)}: not with --parametrisation costate (PDDP "
                         "solves the fuel-optimal transfer over costates, hessdyn)")
    if args.time_budget or _solver_changes(args):
        raise DaddyError("--time-budget, --globalization, --map-order, --multiplier-update: not "
                         "with --parametrisation costate")
    progress = None if args.quiet else (lambda line: print(line, flush=True))
    opts = PDDPOptions(stages=args.costate_stages, sharpness=tuple(args.sharpness))
    r = solve_pddp(case, options=opts, progress=progress)
    steps = ", ".join(f"rho {rho:g}: {'converged' if ok else 'not converged'} {m:.3f} kg"
                      for rho, ok, m in r.steps)
    print(f"PDDP {case.name}: {len(r.sigma)} costate stages, {steps}")
    print(f"  final mass {r.final_mass_kg:.3f} kg at rho {r.rho:g}, {r.switches} switches, "
          f"max violation {r.solution.max_violation:.2e}, {r.cpu_s:.1f} s CPU")
    if not r.solution.converged:
        print(f"daddy: not converged: PDDP: {r.solution.reason}", file=sys.stderr)
        return 1
    if args.no_polish:
        sol = r.solution
    else:
        sol = polish(case, r, stages=args.stages, progress=progress)
        _report(sol)
        u_max = float(case.units.thrust(case.spacecraft.max_thrust_n))
        print(f"  polished from PDDP: {throttle_switches(sol, u_max)} switches")
    if args.json:
        d = sol.to_dict()
        d["pddp"] = r.to_dict()
        Path(args.json).write_text(json.dumps(d, indent=1, allow_nan=False))
    if args.npz:
        sol.to_npz(args.npz)
    _write_outputs(sol, args, case, u_max_n=case.spacecraft.max_thrust_n)
    if not sol.converged:
        print(f"daddy: not converged: {sol.reason}", file=sys.stderr)
        return 1
    return 0


def _solve_sail(case: SailCase, args) -> int:
    """``daddy solve`` of a solar-sail case: maximise the semi-major axis (``solve_sail``),
    reported beside the steering law held per stage. A DaddyError for bad input (the caller
    reports it, exit status 2)."""
    refused = [name for name, given in (
        ("--energy", args.energy), ("--fuel", args.fuel), ("--no-polish", args.no_polish),
        ("--warm-start", args.warm_start), ("--stages", args.stages),
        ("--r-min-km", args.r_min_km), ("--search-revolutions", args.search_revolutions),
        ("--npz", args.npz), ("--free-tof", args.free_tof),
        ("--free-revolutions", args.free_revolutions), ("--policy", args.policy)) if given]
    if refused:
        raise DaddyError(f"{', '.join(refused)}: not for a solar-sail case ({case.name!r} "
                         "maximises its semi-major axis from --guess; its revolutions are in the "
                         "case file)")
    opts = sail_options(run=dict(time_budget_s=args.time_budget), **_solver_changes(args))
    progress = None if args.quiet else (lambda line: print(line, flush=True))
    result = solve_sail(case, SailGuess(args.guess or SailGuess.STEERING_LAW.value), opts,
                        progress, args.method or SAIL_METHOD)
    sol = result.solution
    _report(sol)
    r = result.report()
    print(f"  semi-major axis gain {r['delta_a_km']['osculating']:.4f} km (osculating"
          + (f"; {r['delta_a_km']['j2_energy']:.4f} km from the energy with J2"
             if "j2_energy" in r["delta_a_km"] else "")
          + f"), steering law held per stage {r['steering_law_delta_a_km']['osculating']:.4f} km;"
          f" eclipse width {case.eclipse_width_km} km")
    if args.json:
        d = sol.to_dict()
        d["sail"] = r
        with open(args.json, "w") as f:
            json.dump(d, f, indent=1, allow_nan=False)
    if args.csv:
        write_sail_csv(result, args.csv)
    if args.oem:
        trajectory_output.write_oem(sol, args.oem, args.epoch or _case_epoch(case),
                                    frame=trajectory_output.OemFrame(args.oem_frame))
    if args.plot:
        from .plotting import plot_sail
        plot_sail(result, args.plot)
    if not sol.converged:
        print(f"daddy: not converged: {sol.reason}", file=sys.stderr)
        return 1
    return 0


def _solver_changes(args) -> dict:
    """The option groups the command line changes (``SolverOptions.with_``'s dicts): DDP's
    globalisation and map order, the AUL's multiplier update; {} when none is given."""
    ddp = {k: v for k, v in (("globalization", args.globalization),
                             ("map_order", args.map_order)) if v is not None}
    aul = {} if args.multiplier_update is None else {"multiplier_update": args.multiplier_update}
    return {k: v for k, v in (("ddp", ddp), ("aul", aul)) if v}


def _case_epoch(case: SailCase) -> datetime:
    """The case's start as a UTC date-time (the OEM's default start)."""
    return trajectory_output.J2000 + timedelta(seconds=case.epoch_s)


def _search(case, fuel: bool, args) -> RevolutionSearch:
    """``--search-revolutions``: the search, its trials printed as they are solved."""
    if args.stages or args.warm_start or args.time_budget or _solver_changes(args) or \
            args.no_polish or args.r_min_km:
        raise DaddyError("--search-revolutions solves from the case's cold guess with its own "
                         "stages and the default options: drop --stages, --warm-start, "
                         "--time-budget, --globalization, --map-order, --multiplier-update, "
                         "--no-polish and --r-min-km")
    span = args.search_revolutions
    tol = args.search_tol or span / 20.0
    if not (span > 0 and tol > 0):
        raise DaddyError(f"--search-revolutions and --search-tol must be positive, got {span!r} "
                         f"and {tol!r}")
    print(f"searching {case.revolutions - span / 2:.4f}-{case.revolutions + span / 2:.4f} "
          f"revolutions (bracket {tol:g}):", flush=True)
    found = search_revolutions(case, fuel, span, tol, args.method,
                               None if args.quiet else (lambda line: print(line, flush=True)))
    if found.best is not None:
        print(f"best: {found.revolutions:.4f} revolutions, {found.best.final_mass_kg:.3f} kg "
              f"({len(found.trials)} solves, {sum(t.cpu_s for t in found.trials):.1f} s CPU)")
    return found


def _report(sol: Solution) -> None:
    it = sol.iterations
    rt = sol.runtime_s
    print(f"case {sol.case}  method {sol.method}  {'fuel' if sol.fuel_optimal else 'energy'}-optimal"
          f"  converged {sol.converged} ({sol.reason})")
    kkt = "n/a" if sol.kkt_residual is None else f"{sol.kkt_residual:.2e}"
    print(f"  cost {sol.cost:.10g}  max violation {sol.max_violation:.2e}  KKT residual {kkt}  "
          f"re-propagation miss {sol.repropagation_miss if sol.repropagation_miss is None else f'{sol.repropagation_miss:.2e}'}")
    if sol.final_mass_kg is not None:
        print(f"  final mass {sol.final_mass_kg:.3f} kg  propellant {sol.propellant_kg:.3f} kg")
    if sol.min_path_margin is not None:
        print(f"  path constraint: minimum margin {sol.min_path_margin:.3e} along the DOP853 "
              f"re-propagation ({sol.min_path_margin * sol.units.get('lu_km', 1.0):.3f} km for "
              "a keep-out sphere)")
    if sol.cartesian_miss is not None:
        m = sol.cartesian_miss
        print(f"  flown in Cartesian coordinates in time (DOP853), the arrival misses the final "
              f"node by {m['position_km']:.3e} km, {m['velocity_m_s']:.3e} m/s, "
              f"{m['mass_kg']:.1e} kg")
    print(f"  iterations: restoration {it.get('restore', 0)}, homotopy {it['homotopy']}, "
          f"AUL {it['aul']}, DDP {it['ddp']}, "
          f"Newton {it['newton']}, KKT {it.get('kkt', 0)}; "
          f"polynomial share {sol.polynomial_share:.0%}")
    print(f"  runtime {rt['total']:.2f} s (DDP {rt['ddp']:.2f} s, Newton {rt['newton']:.2f} s, "
          f"KKT {rt.get('kkt', 0.0):.2f} s)")


if __name__ == "__main__":
    sys.exit(main())
