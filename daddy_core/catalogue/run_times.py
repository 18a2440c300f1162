"""The catalogue's measured run times (``run_times.json``, written by
``bench/bench_catalogue.py --write``): what `daddy list` shows as a case's expected run time,
with the machine and date they were measured on -- measurements, not a model, so they age with
the code and the machine; the bench script renews them."""
from __future__ import annotations

import json
from pathlib import Path

RUN_TIMES_FILE = Path(__file__).with_name("run_times.json")


def expected_run_time(case_name: str) -> str:
    """'energy 45 s, fuel 7.1 s' for a measured case ('fuel: not converged in 600 s' where a
    solve did not converge within the cap); '' when the case was not measured."""
    try:
        measured = json.loads(RUN_TIMES_FILE.read_text())["cases"].get(case_name, {})
    except (OSError, ValueError, KeyError):
        return ""
    parts = []
    for kind in ("energy", "fuel"):
        r = measured.get(kind)
        if r is None:
            continue
        if r.get("converged"):
            parts.append(f"{kind} {r['cpu_s']:.3g} s")
        else:
            parts.append(f"{kind}: not converged in {r['cpu_s']:.0f} s")
    return ", ".join(parts)


def measured_on() -> str:
    """'on <machine>, <date>' of the measurements ('' without them)."""
    try:
        d = json.loads(RUN_TIMES_FILE.read_text())
        return f"measured on {d['machine']}, {d['date']}, CPU per solve"
    except (OSError, ValueError, KeyError):
        return ""
