"""How far the DA engine is from its numpy floor: the CR3BP stage expansion of ``bench_da``
(order 2, 10 variables, B = 110 stages, RK78 with the engine's own step count) written against
raw coefficient arrays with the engine's product kernels and no wrapper objects, dispatch,
checks or step control ("minimal engine"), timed interleaved with the engine in one process.

    .venv/bin/python bench/bench_da_floor.py [--rounds 15] [--batch 110]

The ratio engine / minimal is the cost of the layer around the kernels; the minimal engine's
own time is what numpy passes over (66, B) arrays cost on this machine, the floor of any
numpy-based order-2 engine with these kernels.
"""
from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from bench_da import machine
from daddy_core import da
from daddy_core.catalogue import load_case
from daddy_core.da.monomials import tables
from daddy_core.dynamics.models import with_thrust_magnitude
from daddy_core.integrators import RK78_A, RK78_B, rk78

T = tables(10, 2)
N_VAR = 10
SYM = T.sym_factor[:, None]


def mul(a, b):
    """The engine's order-2 block product on raw arrays."""
    out = a * b[0]
    out += a[0] * b
    out[0] *= 0.5
    a1, b1 = a[1:N_VAR + 1], b[1:N_VAR + 1]
    F = np.empty((N_VAR * N_VAR + 1,) + a1.shape[1:])
    np.multiply(a1[:, None], b1[None, :], out=F[:-1].reshape((N_VAR, N_VAR) + a1.shape[1:]))
    F[-1] = 0.0
    out[N_VAR + 1:] += F[T.outer_a] + F[T.outer_b]
    return out


def square(a):
    out = a * (2.0 * a[0])
    out[0] *= 0.5
    a1 = a[1:N_VAR + 1]
    out[N_VAR + 1:] += a1[T.triu_i] * a1[T.triu_j] * SYM
    return out


def series(c, f0, f1, f2):
    out = c * f1
    out[0] = f0
    a1 = c[1:N_VAR + 1]
    out[N_VAR + 1:] += a1[T.triu_i] * a1[T.triu_j] * (SYM * f2)
    return out


def power(c, p):
    inv = 1.0 / c[0]
    f0 = c[0] ** p
    f1 = f0 * inv * p
    return series(c, f0, f1, f1 * inv * ((p - 1.0) / 2.0))


def reciprocal(c):
    inv = 1.0 / c[0]
    return series(c, inv, -inv * inv, inv * inv * inv)


def plus(c, s):
    out = c.copy()
    out[0] += s
    return out


def minimal_expansion(case, x0, u4, dt, steps):
    """RK78 with ``steps`` equal steps on component-major (7, M, B) raw arrays."""
    mu, c_ex = case.units.gm, case.spacecraft.exhaust_speed(case.units)

    def rhs(x, u, out):
        px, py, pz = x[0], x[1], x[2]
        d1, d2 = plus(px, mu), plus(px, mu - 1.0)
        yz2 = square(py) + square(pz)
        k1 = power(square(d1) + yz2, -1.5) * (1.0 - mu)
        k2 = power(square(d2) + yz2, -1.5) * mu
        ks, im = k1 + k2, reciprocal(x[6])
        out[:3] = x[3:6]
        out[3] = x[4] * 2.0 + px - mul(d1, k1) - mul(d2, k2) + mul(u[0], im)
        out[4] = x[3] * -2.0 + py - mul(py, ks) + mul(u[1], im)
        out[5] = mul(u[2], im) - mul(pz, ks)
        out[6] = u[3] * (-1.0 / c_ex)

    def run():
        x, h = x0, dt / steps
        for _ in range(steps):
            K = np.empty((13,) + x.shape)
            for i in range(13):
                xi = x if i == 0 else x + (np.asarray(RK78_A[i]) @ K[:i].reshape(i, -1)
                                           ).reshape(x.shape) * h
                rhs(xi, u4, K[i])
            x = x + (RK78_B @ K.reshape(13, -1)).reshape(x.shape) * h
        return x
    return run


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=15)
    ap.add_argument("--batch", type=int, default=110)
    args = ap.parse_args()
    case = load_case("halo_l2_l1")
    rhs = case.rhs()
    dt = 20 * 86400 / case.units.tu_s / 110
    z0 = np.concatenate([case.x0, [0.05, -0.1, 0.12]])
    B = args.batch
    z = da.variables(np.tile(z0[:, None], (1, B)), order=2)
    stats = {}
    engine = rk78(rhs, z[:7], z[7:], 0.0, dt, tol=1e-13, stats=stats)
    x0 = np.ascontiguousarray(z.c[:, :7].swapaxes(0, 1))
    u4 = np.ascontiguousarray(with_thrust_magnitude(z[7:]).c.swapaxes(0, 1))
    run = minimal_expansion(case, x0, u4, dt, stats["steps"])
    scale = np.abs(engine.c).max()
    diff = np.abs(run().swapaxes(0, 1) - engine.c).max() / scale
    t_min, t_eng = [], []
    for _ in range(args.rounds):
        t0 = time.process_time()
        run()
        t_min.append(time.process_time() - t0)
        t0 = time.process_time()
        rk78(rhs, z[:7], z[7:], 0.0, dt, tol=1e-13)
        t_eng.append(time.process_time() - t0)
    a, b = (1e6 * statistics.median(t) / B for t in (t_min, t_eng))
    print(f"machine: {machine()}")
    print(f"CR3BP stage expansion, B = {B}, {stats['steps']} RK78 steps, {args.rounds} interleaved "
          f"rounds (median CPU): minimal engine {a:.0f} us/stage, daddy's engine {b:.0f} "
          f"us/stage, ratio {b / a:.2f} (results agree to {diff:.1e} relative: equal steps vs "
          "the engine's step control)")


if __name__ == "__main__":
    main()
