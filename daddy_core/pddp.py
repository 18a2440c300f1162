"""Pontryagin-Bellman DDP (issue 48; Sidhoum & Oguri, arXiv 2502.20291): a transfer solved over
the costates of a few long stages (``costate``), with the project's DDP / AUL / trust region,
a continuation over the throttle's sharpness rho, and its answer polished to the exact
bang-bang optimum of the thrust-controlled problem.

    solve_pddp(case, guess, options)  -> PDDPResult     (the costate solve, rho continued)
    polish(case, result)              -> Solution       (thrust schedule -> exact fuel optimum)

What the pipeline chooses and why (docs/costate-stages.md, docs/design-notes.md):
- the decision variables are the scaled costates sigma (``costate.costate_scale``): a unit
  change of any moves the switching function by O(1), so one spherical trust region fits all;
- DDP with second-order dynamics (``Method.HESSDYN``) and the trust region
  (``Globalization.TRUST_REGION``): with no stage cost, Q_uu comes from the dynamics' second
  derivatives alone and is indefinite away from the optimum; the sweep takes the trust-region
  step on the region's boundary there (``sweeps.backward_sweep``, indefinite stages);
- no feasibility restoration of the guess (``StartOptions.restore``): Newton's minimum-norm
  restoration of a costate guess drives every stage's throttle into saturation, where the
  propellant's gradient vanishes (a full-thrust transfer is a stationary point of the costate
  parametrisation); the AUL loop meets the terminal rows while the cost is active.
"""
from __future__ import annotations

import enum
import time
from dataclasses import dataclass, field

import numpy as np

from .catalogue import problem_from_case
from .costate import costate_problem, switching, thrust_schedule
from .errors import DaddyError
from .integrators import rk78
from .solver import Globalization, Method, Solution, SolverOptions, case_options, solve


class Parametrisation(enum.Enum):
    """What a stage's decision variables are: the thrust (DADDy) or the costates (PDDP)."""

    THRUST = "thrust"
    COSTATE = "costate"


@dataclass(frozen=True)
class PDDPOptions:
    """The PDDP pipeline's settings (the DDP's own are ``solver``)."""

    stages: int = 5                         # costate stages (the paper's robustness runs: 5)
    sharpness: tuple = (1.0,)               # rho of each continuation step, each warm-started
    solver: SolverOptions = field(default_factory=lambda: SolverOptions().with_(
        ddp=dict(globalization=Globalization.TRUST_REGION), start=dict(restore=False),
        homotopy=((0.0, 1.0),)))

    def __post_init__(self):
        if self.stages < 1:
            raise DaddyError(f"PDDPOptions.stages must be >= 1, got {self.stages}")
        if not self.sharpness or any(not (r > 0.0) for r in self.sharpness):
            raise DaddyError(f"PDDPOptions.sharpness must be positive rho values, got "
                             f"{self.sharpness!r}")


@dataclass
class PDDPResult:
    """A costate solve: sigma (N, 7) the scaled costates at the stages' starts, costates (N, 7)
    lambda = scale * sigma (normalised units), the sharpness rho of the last continuation step
    reached, the DDP ``Solution`` of that step, its switch count (sign changes of the
    switching function along the flown trajectory) and CPU seconds."""

    sigma: np.ndarray
    costates: np.ndarray
    rho: float
    solution: Solution
    switches: int
    cpu_s: float
    steps: list        # (rho, converged, final mass kg) of each continuation step

    @property
    def final_mass_kg(self) -> float:
        return float(self.solution.final_mass_kg)

    def to_dict(self) -> dict:
        """The costates and the continuation as JSON-ready values (the CLI's ``pddp`` entry)."""
        return {"rho": self.rho, "stages": len(self.sigma), "final_mass_kg": self.final_mass_kg,
                "switches": self.switches, "converged": self.solution.converged,
                "costates": self.costates.tolist(), "sigma": self.sigma.tolist(),
                "steps": [{"rho": r, "converged": c, "final_mass_kg": m}
                          for r, c, m in self.steps], "cpu_s": self.cpu_s}


def default_guess(case, stages: int) -> np.ndarray:
    """(stages, 7) sigma: thrust along the departure velocity at half throttle (|sigma_v| = 1
    puts the switching function at 0), lambda_r = lambda_m = 0 -- a guess that asks nothing of
    the case but its departure state."""
    v = np.asarray(case.cartesian_x0(), float)[3:6]
    sigma = np.zeros((stages, 7))
    sigma[:, 3:6] = -v / np.linalg.norm(v)
    return sigma


def solve_pddp(case, guess=None, options: PDDPOptions | None = None,
               progress=None) -> PDDPResult:
    """PDDP on the catalogue CR3BP ``case``: the costate problem (``costate.costate_problem``)
    solved at each rho of ``options.sharpness`` in turn, each step warm-started from the last;
    guess: (stages, 7) sigma (None: ``default_guess``). The result is the last step that
    converged (or the first step's answer, ``converged=False``, when none did).
    ``options.solver.run.time_budget_s`` bounds the whole continuation: each step gets what
    the earlier ones left, and none starts once it is spent."""
    o = options or PDDPOptions()
    sigma = default_guess(case, o.stages) if guess is None else np.asarray(guess, float)
    if sigma.shape != (o.stages, 7):
        raise DaddyError(f"guess: expected ({o.stages}, 7) scaled costates, got {sigma.shape}")
    t0, wall0 = time.process_time(), time.perf_counter()
    budget = o.solver.run.time_budget_s
    steps, best = [], None
    for rho in o.sharpness:
        problem = costate_problem(case, o.stages, rho)
        opts = o.solver   # the time budget is the whole continuation's
        if budget is not None and best is not None:
            left = budget - (time.perf_counter() - wall0)
            if left <= 0.0:
                break
            opts = opts.with_(run=dict(time_budget_s=left))
        sol = solve(problem, sigma, method=Method.HESSDYN, fuel_optimal=False,
                    options=opts, case_name=case.name, progress=progress)
        steps.append((rho, sol.converged, float(sol.final_mass_kg)))
        if not sol.converged:
            break
        best, sigma = (rho, problem, sol), sol.U
    rho, problem, sol = best or (o.sharpness[0], problem, sol)
    return PDDPResult(sigma=sol.U, costates=problem.step.costates(sol.U.T).T, rho=rho,
                      solution=sol, switches=switch_count(problem, sol.U), steps=steps,
                      cpu_s=time.process_time() - t0)


def switching_function(problem, sigma, samples: int = 200):
    """(t, S): the switching function S = |lambda_v| c / m + lambda_m - 1 sampled ``samples``
    times per stage along the costate solution ``sigma`` of ``problem`` (normalised time)."""
    step = problem.step
    c = step.law[0]
    lam = step.costates(np.asarray(sigma, float).T).T
    x, t, ts, S = np.asarray(problem.x0, float), 0.0, [], []
    for k, dt in enumerate(problem.stage_dt):
        z = np.r_[x, lam[k]]
        h = dt / samples
        for i in range(samples + 1):
            if i:
                z = rk78(step.flow14.rhs, z, None, t + (i - 1) * h, h, tol=1e-12)
            ts.append(t + i * h)
            S.append(switching(np.linalg.norm(z[10:13]), z[13], z[6], c))
        x, t = z[:7], t + dt
    return np.array(ts), np.array(S)


def switch_count(problem, sigma) -> int:
    """Sign changes of the switching function along the costate solution: the bang-bang
    switches of its thrust (a change at a stage boundary, where the costates jump, counts)."""
    _, S = switching_function(problem, sigma)
    on = S > 0.0
    return int(np.count_nonzero(on[1:] != on[:-1]))


def throttle_switches(solution: Solution, u_max: float) -> int:
    """A thrust-controlled solution's switches: changes of its stages' throttle across one
    half of the rating (``u_max``, normalised)."""
    on = np.linalg.norm(np.asarray(solution.U)[:, :3], axis=1) > 0.5 * u_max
    return int(np.count_nonzero(on[1:] != on[:-1]))


def polish(case, result: PDDPResult, stages: int | None = None,
           options: SolverOptions | None = None, progress=None) -> Solution:
    """The exact bang-bang optimum from a PDDP answer: its thrust averaged on the case's thrust
    stages (``costate.thrust_schedule``) warm-starts the case's fuel-optimal solve, whose
    pseudo-Huber continuation and exact throttle end game return the true optimum."""
    problem = problem_from_case(case, stages=stages)
    cp = costate_problem(case, len(result.sigma), result.rho)
    U = thrust_schedule(cp, result.sigma, problem.N)
    return solve(problem, U, fuel_optimal=True, options=options or case_options(case, True),
                 case_name=case.name, progress=progress)


__all__ = ["PDDPOptions", "Parametrisation", "PDDPResult", "default_guess", "polish", "solve_pddp",
           "switch_count", "switching_function", "throttle_switches"]
