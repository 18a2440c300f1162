"""``daddy predict``: a catalogue case's terminal dispersion from an initial-state error,
predicted on DA (``uncertainty``) and sampled by a Monte Carlo of the same flight, side by side.

The flight: the case's optimum flown from a perturbed start, each stage's control from the
solution's feedback laws where they exist (``policy``; order 0: the plan's controls, open
loop). No navigation or execution errors and no re-plans: this is the laws' own closed loop,
not the guidance node's (``daddy_campaign`` flies that one).
"""
from __future__ import annotations

import time

import numpy as np

from .catalogue import Case, problem_from_case
from .errors import DaddyError
from .solver import case_options, solve
from .uncertainty import gaussian_moments, monte_carlo, terminal_polynomial


def predict_case(case: Case, fuel: bool, law_order: int, sigma_km: float, sigma_m_s: float,
                 samples: int, seed: int = 1, order: int = 2) -> dict:
    """The prediction and the Monte Carlo of ``case`` (module docstring): per axis of the
    terminal position [km] and velocity [m/s], the predicted mean and standard deviation and
    the sampled ones, with the laws' coverage and the CPU of each."""
    if case.staged_in_angle:
        raise DaddyError(f"predict: {case.name!r} is staged in true longitude (its state is "
                         "equinoctial elements); prediction is built for the Cartesian cases")
    if not (sigma_km >= 0 and sigma_m_s >= 0 and (sigma_km > 0 or sigma_m_s > 0)):
        raise DaddyError("predict: --sigma-km and --sigma-m-s must be >= 0, one of them > 0")
    if not (isinstance(samples, int) and samples >= 10):
        raise DaddyError(f"predict: --samples must be an integer >= 10, got {samples!r}")
    problem = problem_from_case(case)
    opts = case_options(case, fuel, policy=dict(order=law_order))
    sol = solve(problem, case.cold_guess(problem.N), fuel_optimal=fuel, options=opts)
    if not sol.converged:
        raise DaddyError(f"predict: the case's solve did not converge ({sol.reason})")
    policy = sol.policy if law_order else None
    if law_order and policy is None:
        raise DaddyError(f"predict: no feedback laws: {sol.policy_error}")
    units = case.units
    si_sigma = np.array([sigma_km * 1e3] * 3 + [sigma_m_s] * 3 + [0.0])
    scale = units.cartesian_normalised(np.ones(7))               # SI -> normalised, per entry
    cov = np.diag((si_sigma * scale) ** 2)
    t = time.process_time()
    poly = terminal_polynomial(problem, sol.X, sol.U, policy, order=order)
    mean, covariance = gaussian_moments(poly, cov)
    t_poly = time.process_time() - t
    t = time.process_time()
    _, miss = monte_carlo(problem, sol.X, sol.U, policy, cov, samples,
                          np.random.default_rng(seed))
    t_mc = time.process_time() - t
    to_si = 1.0 / scale[:6]
    return {"case": case.name, "fuel_optimal": fuel, "law_order": law_order,
            "laws": None if policy is None else int(policy.has_law.sum()), "stages": problem.N,
            "samples": samples, "order": order,
            "predicted_mean": (mean[:6] * to_si).tolist(),
            "predicted_std": (np.sqrt(np.diag(covariance))[:6] * to_si).tolist(),
            "sampled_mean": (miss[:6].mean(axis=1) * to_si).tolist(),
            "sampled_std": (miss[:6].std(axis=1, ddof=1) * to_si).tolist(),
            "predicted_cpu_s": t_poly, "sampled_cpu_s": t_mc}


def report(r: dict) -> str:
    """The side-by-side table of ``predict_case``'s result."""
    laws = ("open loop (the plan's controls)" if r["laws"] is None
            else f"feedback laws of order {r['law_order']} on {r['laws']} of {r['stages']} stages")
    lines = [f"case {r['case']}  {'fuel' if r['fuel_optimal'] else 'energy'}-optimal, {laws}",
             f"terminal deviation: order-{r['order']} polynomial (closed-form moments) | "
             f"Monte Carlo of {r['samples']} flights",
             f"{'':8s}{'mean':>12s} {'std':>12s} | {'mean':>12s} {'std':>12s} "
             f"{'mean 95 % CI':>14s}"]
    for i, (axis, unit, f) in enumerate([("x", "km", 1e-3), ("y", "km", 1e-3), ("z", "km", 1e-3),
                                         ("vx", "m/s", 1.0), ("vy", "m/s", 1.0),
                                         ("vz", "m/s", 1.0)]):
        half = 1.96 * r["sampled_std"][i] / np.sqrt(r["samples"]) * f
        lines.append(f"{axis + ' ' + unit:8s}{r['predicted_mean'][i] * f:12.4g} "
                     f"{r['predicted_std'][i] * f:12.4g} | {r['sampled_mean'][i] * f:12.4g} "
                     f"{r['sampled_std'][i] * f:12.4g}   ±{half:.3g}")
    lines.append(f"CPU: prediction {r['predicted_cpu_s']:.3g} s, Monte Carlo "
                 f"{r['sampled_cpu_s']:.3g} s")
    return "\n".join(lines)
