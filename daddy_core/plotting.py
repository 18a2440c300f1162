"""Optional plots (matplotlib is an optional extra: pip install matplotlib)."""
from __future__ import annotations

import numpy as np

from .errors import DaddyError


def _pyplot():
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as exc:
        raise DaddyError("--plot needs matplotlib (pip install matplotlib)") from exc
    return plt


def plot_sail(result, path: str) -> None:
    """PNG of a sail solve (``catalogue.sail_cases.SailResult``) over revolutions: the
    semi-major axis gain of DDP and of the steering law held per stage, e and i, and the sail's
    cone and clock angles with the shadow arcs (sunlight < 1/2) shaded."""
    from .catalogue.sail_cases import sail_angles, sunlight_at_nodes
    plt = _pyplot()
    sol, case = result.solution, result.case
    el = sol.elements
    revs = np.concatenate([[0.0], np.cumsum(sol.stage_dt)]) / (2 * np.pi)
    X_law = result.law_X
    a_law = X_law[:, 0] / (1 - X_law[:, 1] ** 2 - X_law[:, 2] ** 2) * case.units.lu_km
    fig, ((ax_a, ax_e), (ax_i, ax_u)) = plt.subplots(2, 2, figsize=(12, 7.5))
    ax_a.plot(revs, el[:, 0] - el[0, 0], label="DDP")
    ax_a.plot(revs, a_law - a_law[0], "--", label="steering law held per stage")
    ax_a.set_ylabel("a - a0 [km] (osculating)")
    ax_a.legend()
    ax_e.plot(revs, el[:, 1])
    ax_e.set_ylabel("e")
    ax_i.plot(revs, el[:, 2])
    ax_i.set_ylabel("i [deg]")
    cone, clock = sail_angles(case, sol.U)
    ax_u.plot(revs[:-1], cone, ".", ms=2, label="cone")
    ax_u.plot(revs[:-1], clock, ".", ms=2, label="clock")
    light = sunlight_at_nodes(case, sol.X, sol.t_start + revs * 2 * np.pi)
    dark = light < 0.5
    if dark.any():
        ax_u.fill_between(revs, -180, 180, where=dark, color="0.8", label="shadow")
    ax_u.set_ylabel("sail angles [deg]")
    ax_u.legend(loc="upper right", fontsize=8)
    for ax in (ax_a, ax_e, ax_i, ax_u):
        ax.set_xlabel("revolutions")
        ax.ticklabel_format(axis="y", useOffset=False)
    d = result.delta_a_km["osculating"]
    fig.suptitle(f"{case.name}: da = {d:.4f} km (steering law "
                 f"{result.law_delta_a_km['osculating']:.4f} km), beta {case.beta}, eclipse width "
                 f"{case.eclipse_width_km} km")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_solution(sol, path: str, flown=None, u_max_n: float | None = None) -> None:
    """PNG with the trajectory and the thrust magnitude against time (u_max drawn when given).

    Cartesian solutions: the x-y path (normalised). Earth-centred ones (many revolutions, whose
    path is a disc of ink): the evolution of a, e, i and RAAN over time, as the paper's Fig. 9a.

    Args:
        sol: a Solution.
        path: output PNG file.
        flown: optional (K, >=2) array of flown positions to overlay (closed-loop demo).
        u_max_n: the thrust bound [N], drawn on the thrust panel.
    """
    plt = _pyplot()
    days = sol.times_s / 86400.0
    if sol.elements is not None:
        fig, axes = plt.subplots(2, 2, figsize=(11, 7))
        (ax_a, ax_e), (ax_i, ax2) = axes
        el = sol.elements
        for ax, col, label in ((ax_a, 0, "a [km]"), (ax_e, 1, "e"), (ax_i, 2, "i [deg]")):
            ax.plot(days, el[:, col])
            ax.set_xlabel("time [day]")
            ax.set_ylabel(label)
        ax_o = ax_i.twinx()
        ax_o.plot(days, np.unwrap(np.radians(el[:, 3])) * 180 / np.pi, "C1")
        ax_o.set_ylabel("RAAN [deg]", color="C1")
        for ax in (ax_a, ax_e, ax_i, ax_o):
            ax.ticklabel_format(axis="y", useOffset=False)
    else:
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
    thrust = np.linalg.norm(sol.thrust_n, axis=1)
    ax2.step(days[:-1], thrust, where="post", label="|u|")
    if u_max_n is not None:
        ax2.axhline(u_max_n, color="k", ls="--", lw=0.8, label="u_max")
    ax2.set_ylim(0.0, 1.1 * max(u_max_n or 0.0, float(np.max(thrust, initial=0.0))) or 1.0)
    ax2.set_xlabel("time [day]")
    ax2.set_ylabel("thrust [N]")
    ax2.set_title(f"{sol.case} ({sol.method})")
    ax2.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
