"""Optional plots (matplotlib is an optional extra: pip install matplotlib)."""
from __future__ import annotations

import numpy as np

from .errors import DaddyError


def plot_solution(sol, path: str, flown=None) -> None:
    """PNG with the trajectory (x-y, normalised) and the thrust magnitude against u_max.

    Args:
        sol: a Solution.
        path: output PNG file.
        flown: optional (K, >=2) array of flown positions to overlay (closed-loop demo).
    """
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as exc:
        raise DaddyError("--plot needs matplotlib (pip install matplotlib)") from exc
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.5))
    X = sol.X
    ax1.plot(X[:, 0], X[:, 1], ".-", label="planned")
    if flown is not None:
        ax1.plot(flown[:, 0], flown[:, 1], "-", label="flown")
    ax1.plot(X[0, 0], X[0, 1], "go", label="start")
    ax1.plot(X[-1, 0], X[-1, 1], "r*", label="end")
    ax1.set_xlabel("x [LU]")
    ax1.set_ylabel("y [LU]")
    ax1.axis("equal")
    ax1.legend()
    t = np.concatenate([[0.0], np.cumsum(sol.stage_dt)]) * sol.units.get("tu_s", 1.0) / 86400
    thrust = np.linalg.norm(sol.thrust_n, axis=1)
    ax2.step(t[:-1], thrust, where="post", label="|u|")
    ax2.set_xlabel("time [day]")
    ax2.set_ylabel("thrust [N]")
    ax2.set_title(f"{sol.case} ({sol.method})")
    ax2.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
