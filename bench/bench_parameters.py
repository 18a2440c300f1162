"""Free time of flight against the fixed-time solve at the optimal time (issue 46): the rest-to-
rest double integrator of the issue (D = 10, N = 20, J = sum u^2 dt + T), CPU medians of
interleaved runs and their ratio.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python bench/bench_parameters.py [--rounds 5]
"""
from __future__ import annotations

import argparse
import platform
import time

import numpy as np

from daddy_core.da import functions as dm
from daddy_core.problem import Problem
from daddy_core.solver import SolverOptions, solve
from daddy_core.static_parameters import with_free_time

T_STAR = 7.7508155   # the optimum
OPTIONS = SolverOptions(kkt=dict(tol=1e-9))


def rest_to_rest(T: float) -> Problem:
    def step(x, u, dt):
        return dm.stack([x[0] + x[1] * dt + 0.5 * u[0] * dt * dt, x[1] + u[0] * dt])
    return Problem(name="rest_to_rest", x0=np.zeros(2), x_target=np.array([10.0, 0.0]),
                   stage_dt=np.full(20, T / 20), step=step,
                   stage_cost=lambda x, u, dt, hom=(0.0, 1.0): u[0] * u[0] * dt,
                   terminal_cost=lambda x, xt: 0.0 * x[0],
                   g_teq=lambda x, xt: dm.stack([x[0] - xt[0], x[1] - xt[1]]), nu=1)


def cpu(fn) -> tuple[float, object]:
    t = time.process_time()
    out = fn()
    return time.process_time() - t, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=5)
    args = ap.parse_args()
    free, fixed = [], []
    for _ in range(args.rounds):   # interleaved
        t, s = cpu(lambda: solve(with_free_time(rest_to_rest(10.0), 1.0, 50.0, time_cost=1.0),
                                 np.zeros((20, 1)), fuel_optimal=False, options=OPTIONS))
        free.append(t)
        t, s2 = cpu(lambda: solve(rest_to_rest(T_STAR), np.zeros((20, 1)),
                                  fuel_optimal=False, options=OPTIONS))
        fixed.append(t)
    print(f"machine: {platform.processor() or platform.machine()}")
    print(f"free ToF: T = {s.parameters['tof']:.7f}, J = {s.cost:.7f}, median "
          f"{np.median(free):.3f} s CPU; fixed T*: J = {s2.cost + T_STAR:.7f}, median "
          f"{np.median(fixed):.3f} s; ratio {np.median(free) / np.median(fixed):.2f}")


if __name__ == "__main__":
    main()
