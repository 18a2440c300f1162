"""A campaign's results as one PNG: where the runs arrived (position vs velocity miss, the
success box drawn), what they spent (propellant against the open-loop optimum and its band),
how long guidance took (every re-plan's latency), and the terminal deviations in the target's
RTN frame with the 1- and 3-sigma ellipses of their covariance (drawn from the results table's
columns, ``campaign_table``). Needs matplotlib (the plots extra)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .campaign_results import Results, summarise
from .campaign_table import RTN, columns
from .campaigns import RunStatus

# the deviation panels: (x column, y column, axis scale, unit)
DEVIATION_PANELS = (("dr_rtn_m", "dt_rtn_m", 1.0, "m"), ("dr_rtn_m", "dn_rtn_m", 1.0, "m"),
                    ("dvr_rtn_m_s", "dvt_rtn_m_s", 1e3, "mm/s"),
                    ("dvr_rtn_m_s", "dvn_rtn_m_s", 1e3, "mm/s"))


def ellipse(cov: np.ndarray, k: float, centre=(0.0, 0.0),
            n: int = 200) -> tuple[np.ndarray, np.ndarray]:
    """The k-sigma ellipse of a (2, 2) covariance about ``centre``: (n,) x and y."""
    w, v = np.linalg.eigh(cov)
    a = np.linspace(0, 2 * np.pi, n)
    pts = v @ (k * np.sqrt(np.maximum(w, 0.0))[:, None] * np.vstack([np.cos(a), np.sin(a)]))
    return pts[0] + centre[0], pts[1] + centre[1]


def plot_campaign(results: Results, path) -> None:
    """Write the PNG to ``path``. Raises ImportError without matplotlib."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    s = summarise(results)
    crit = results.header.config.success
    done = [r for r in results.records if r.status is RunStatus.COMPLETED]
    table = columns(results)
    dev = {k: np.array(v, float) for k, v in table.items()
           if k in {c for p in DEVIATION_PANELS for c in p[:2]}}
    has_dev = int(np.isfinite(dev["dr_rtn_m"]).sum()) >= 3
    fig = plt.figure(figsize=(16, 9.4 if has_dev else 4.8))
    grid = fig.add_gridspec(2 if has_dev else 1, 12)
    a1, a2, a3 = (fig.add_subplot(grid[0, 4 * i:4 * i + 4]) for i in range(3))
    lo, hi = s.success_wilson_95
    fig.suptitle(f"{results.header.config.case}: {s.success}/{s.runs} runs succeeded "
                 f"({s.success_rate:.1%}, 95 % interval {lo:.1%} - {hi:.1%})"
                 + (f"; {s.failed} runs failed to complete" if s.failed else ""))

    # 1. terminal miss, log-log: the runs span orders of magnitude when some fail
    ok = [r for r in done if r.success]
    bad = [r for r in done if not r.success]
    km = [r.miss_km for r in done] + [crit.miss_km]
    cms = [r.miss_cm_s for r in done] + [crit.miss_cm_s]
    x0, y0 = min(km) / 3, min(cms) / 3
    a1.add_patch(Rectangle((x0, y0), crit.miss_km - x0, crit.miss_cm_s - y0, fill=True,
                           alpha=0.12, color="tab:green", label="success box"))
    a1.plot([r.miss_km for r in ok], [r.miss_cm_s for r in ok], "o", ms=4, color="tab:green",
            label=f"success ({len(ok)})")
    if bad:
        a1.plot([r.miss_km for r in bad], [r.miss_cm_s for r in bad], "x", ms=6,
                color="tab:red", label=f"miss or propellant out of bounds ({len(bad)})")
    hit = [r for r in done if r.dispersion and r.dispersion.outage_s]
    if hit:
        a1.plot([r.miss_km for r in hit], [r.miss_cm_s for r in hit], "o", ms=11, mfc="none",
                color="0.3", label=f"with a missed-thrust event ({len(hit)})")
    a1.set_xscale("log")
    a1.set_yscale("log")
    a1.set_xlim(x0, max(km) * 3)
    a1.set_ylim(y0, max(cms) * 3)
    a1.set_xlabel("terminal position miss [km]")
    a1.set_ylabel("terminal velocity miss [cm/s]")
    a1.set_title("arrival")
    a1.legend(loc="upper left", fontsize=8)

    # 2. propellant against the open-loop optimum and the success band
    prop = np.array([r.propellant_kg for r in done])
    ref = s.propellant_open_loop_kg
    band = crit.propellant_fraction * ref
    a2.axvspan(ref - band, ref + band, alpha=0.12, color="tab:green",
               label=f"within {crit.propellant_fraction:.0%}")
    if len(prop):
        a2.hist(prop, bins=min(40, max(8, len(prop) // 4)), color="tab:blue", alpha=0.8,
                label="closed-loop runs")
    a2.axvline(ref, color="k", ls="--", label=f"open-loop optimum {ref:.3f} kg")
    a2.set_xlabel("propellant [kg]")
    a2.set_ylabel("runs")
    a2.set_title("propellant")
    a2.legend(fontsize=8)

    # 3. re-plan latency, log bins
    lat = np.array([x for r in done for x in r.latency_ms])
    if len(lat):
        edges = np.logspace(np.log10(max(lat.min(), 1e-2)) - 0.05, np.log10(lat.max()) + 0.05,
                            40)
        a3.hist(lat, bins=edges, color="tab:purple", alpha=0.8)
        a3.set_xscale("log")
        a3.axvline(s.latency_ms.median, color="k", ls="--",
                   label=f"median {s.latency_ms.median:.0f} ms")
        a3.axvline(s.latency_ms.p95, color="k", ls=":", label=f"p95 {s.latency_ms.p95:.0f} ms")
        a3.legend(fontsize=8)
    a3.set_xlabel("re-plan latency [ms]")
    a3.set_ylabel("re-plans")
    a3.set_title(f"guidance latency ({len(lat)} re-plans)")

    if has_dev:
        _deviation_panels(fig, grid, dev)
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _deviation_panels(fig, grid, dev: dict) -> None:
    """The terminal deviations of the completed runs in the target's RTN frame, with the
    1- and 3-sigma ellipses of their covariance about their mean."""
    names = dict(zip(RTN, "RTN"))
    for i, (cx, cy, scale, unit) in enumerate(DEVIATION_PANELS):
        ax = fig.add_subplot(grid[1, 3 * i:3 * i + 3])
        ok = np.isfinite(dev[cx]) & np.isfinite(dev[cy])
        x, y = dev[cx][ok] * scale, dev[cy][ok] * scale
        ax.plot(x, y, ".", ms=4, color="0.35", label=f"runs ({ok.sum()})")
        centre = (x.mean(), y.mean())
        cov = np.cov(np.vstack([x, y]))
        for k, style in ((1, "-"), (3, "--")):
            ax.plot(*ellipse(cov, k, centre), style, color="tab:blue", label=f"{k} sigma")
        ax.plot(*centre, "+", color="tab:blue", ms=10, label="mean")
        ax.axhline(0, color="0.8", lw=0.8)
        ax.axvline(0, color="0.8", lw=0.8)
        kind = "position" if unit == "m" else "velocity"
        ax.set_xlabel(f"{kind} deviation {names[cx.split('_')[0][-1]]} [{unit}]")
        ax.set_ylabel(f"{kind} deviation {names[cy.split('_')[0][-1]]} [{unit}]")
        ax.set_title(f"terminal {kind}, target's RTN frame", fontsize=10)
        ax.set_aspect("equal", adjustable="datalim")
        if i == 0:
            ax.legend(fontsize=7, loc="upper left")
