"""DA engine benchmark: order-2 CR3BP stage expansion in 10 variables (7 states + 3 controls),
dt = 20 d / 110 (the halo L2->L1 stage), batched over B stages; map evaluation; and, when the
optional ``daceypy`` is installed, the same unbatched workload in daceypy in the same run.

    .venv/bin/python bench/bench_da.py [--seconds 1.0]

Targets (issue #2, 2-core machine): B = 110 batched expansion <= 250 us/stage with RK4/20 and
<= 120 us/stage with RK78; single-map evaluation <= 5 us, batched <= 0.3 us/stage; unbatched
expansion no slower than daceypy.
"""
from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np

from daddy_core import da
from daddy_core.integrators import rk4, rk78
from daddy_core.catalogue import load_case


def timeit(fn, seconds: float) -> float:
    fn()
    n, t0 = 0, time.perf_counter()
    while True:
        fn()
        n += 1
        el = time.perf_counter() - t0
        if el > seconds and n >= 3:
            return el / n


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} cores, numpy {np.__version__}, Python {platform.python_version()}"


def daceypy_expansion(case, z0, dt, integrator):
    """The same stage expansion written for daceypy (scalar DA objects), RK4/20 or RK78."""
    import daceypy
    from daceypy import DA, array
    DA.init(2, 10)
    mu = case.units.gm
    c = case.spacecraft.exhaust_speed(case.units)

    def rhs(t, x, u):
        d1, d2 = x[0] + mu, x[0] - (1.0 - mu)
        yz2 = x[1] * x[1] + x[2] * x[2]
        k1 = (d1 * d1 + yz2) ** -1.5 * (1.0 - mu)
        k2 = (d2 * d2 + yz2) ** -1.5 * mu
        im = 1.0 / x[6]
        un = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2] + 1e-24).sqrt()
        return array([x[3], x[4], x[5],
                      2.0 * x[4] + x[0] - d1 * k1 - d2 * k2 + u[0] * im,
                      -2.0 * x[3] + x[1] - x[1] * (k1 + k2) + u[1] * im,
                      -x[2] * (k1 + k2) + u[2] * im, -un / c])

    def run():
        z = array([DA(i + 1) + z0[i] for i in range(10)])
        x, u = z[:7], z[7:]
        if integrator == "rk4":
            h = dt / 20
            for _ in range(20):
                k1 = rhs(0, x, u)
                k2 = rhs(0, x + k1 * (h / 2), u)
                k3 = rhs(0, x + k2 * (h / 2), u)
                k4 = rhs(0, x + k3 * h, u)
                x = x + (k1 + k2 * 2.0 + k3 * 2.0 + k4) * (h / 6)
            return x
        # RK78 on the same step sequence as ours (the step count is what matters for cost)
        from daddy_core.integrators import RK78_A, RK78_B
        stats = {}
        rk78(case.rhs(), z0[:7], z0[7:], 0.0, dt, tol=1e-13, stats=stats)
        h = dt / stats["steps"]
        for _ in range(stats["steps"]):
            ks = []
            for i in range(13):
                xi = x
                for a, k in zip(RK78_A[i], ks):
                    if a:
                        xi = xi + k * (a * h)
                ks.append(rhs(0, xi, u))
            for b, k in zip(RK78_B, ks):
                if b:
                    x = x + k * (b * h)
        return x
    del daceypy
    return run


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=1.0, help="time per measurement")
    args = ap.parse_args()
    case = load_case("halo_l2_l1")
    rhs = case.rhs()
    dt = 20 * 86400 / case.units.tu_s / 110
    z0 = np.concatenate([case.x0, [0.05, -0.1, 0.12]])
    print(f"machine: {machine()}")
    print("CR3BP stage expansion, order 2, 10 variables, dt = 20 d / 110")
    print(f"{'B':>5} {'RK4/20 us/stage':>16} {'RK78 us/stage':>14}")
    results = {}
    for B in (1, 40, 110, 300):
        Z = z0 if B == 1 else np.tile(z0[:, None], (1, B))
        x = da.variables(Z, order=2)
        t4 = timeit(lambda: rk4(rhs, x[:7], x[7:], 0.0, dt, steps=20), args.seconds) / B
        t78 = timeit(lambda: rk78(rhs, x[:7], x[7:], 0.0, dt, tol=1e-13), args.seconds) / B
        results[B] = (t4, t78)
        print(f"{B:>5} {t4 * 1e6:>16.1f} {t78 * 1e6:>14.1f}")
    print(f"targets at B=110: RK4/20 <= 250 us (ratio {results[110][0] * 1e6 / 250:.2f}), "
          f"RK78 <= 120 us (ratio {results[110][1] * 1e6 / 120:.2f})")

    m1 = rk78(rhs, da.variables(z0, 2)[:7], da.variables(z0, 2)[7:], 0.0, dt)
    dv = np.full(10, 1e-4)
    t_single = timeit(lambda: da.evaluate(m1, dv), args.seconds)
    Zb = np.tile(z0[:, None], (1, 110))
    mb = rk78(rhs, da.variables(Zb, 2)[:7], da.variables(Zb, 2)[7:], 0.0, dt)
    dvb = np.full((10, 110), 1e-4)
    t_batch = timeit(lambda: da.evaluate(mb, dvb), args.seconds) / 110
    print(f"map evaluation: single {t_single * 1e6:.2f} us (target <= 5), "
          f"batched {t_batch * 1e6:.3f} us/stage at B=110 (target <= 0.3)")

    try:
        import daceypy  # noqa: F401
    except ImportError:
        print("daceypy not installed: no side-by-side comparison "
              "(pip install daceypy into the venv to get one)")
        return
    for integ, ours in (("rk4", results[1][0]), ("rk78", results[1][1])):
        t_dace = timeit(daceypy_expansion(case, z0, dt, integ), args.seconds)
        print(f"daceypy unbatched {integ}: {t_dace * 1e6:.0f} us/stage; ours {ours * 1e6:.0f} us; "
              f"ratio ours/daceypy {ours / t_dace:.2f}; ours batched B=110 / daceypy "
              f"{results[110][0 if integ == 'rk4' else 1] / t_dace:.3f}")


if __name__ == "__main__":
    main()
