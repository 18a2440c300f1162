"""A campaign's results as one PNG: where the runs arrived (position vs velocity miss, the
success box drawn), what they spent (propellant against the open-loop optimum and its band),
and how long guidance took (every re-plan's latency). Needs matplotlib (the plots extra)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .campaign_results import Results, summarise
from .campaigns import RunStatus


def plot_campaign(results: Results, path) -> None:
    """Write the PNG to ``path``. Raises ImportError without matplotlib."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    s = summarise(results)
    crit = results.header.config.success
    done = [r for r in results.records if r.status is RunStatus.COMPLETED]
    fig, (a1, a2, a3) = plt.subplots(1, 3, figsize=(15, 4.6))
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

    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
