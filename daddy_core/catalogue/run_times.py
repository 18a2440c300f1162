"""The catalogue's measured run times (``run_times.json``, written by
``bench/bench_catalogue.py --write``): what `daddy list` shows as a case's expected run time,
with the machine and date they were measured on -- measurements, not a model, so they age with
the code and the machine; the bench script renews them."""
from __future__ import annotations

import json
from pathlib import Path

RUN_TIMES_FILE = Path(__file__).with_name("run_times.json")


def read_run_times() -> dict:
    """The measurements ({"cases": {name: {"energy": ..., "fuel": ...}}, "machine", "date"}),
    or {} without a readable file."""
    try:
        return json.loads(RUN_TIMES_FILE.read_text())
    except (OSError, ValueError):
        return {}


def expected_run_time(run_times: dict, case_name: str) -> str:
    """'energy 45 s, fuel 7.1 s' for a case measured in ``run_times`` ('fuel: not converged in
    600 s' where a solve did not converge within the cap); '' when it was not measured."""
    measured = run_times.get("cases", {}).get(case_name, {})
    return ", ".join(f"{kind}{' ' if r.get('converged') else ': '}{solve_time(r)}"
                     for kind in ("energy", "fuel") if (r := measured.get(kind)) is not None)


def solve_time(measured: dict) -> str:
    """One measured solve ({"cpu_s", "converged", ...}): '45 s', or 'not converged in 600 s'."""
    if measured.get("converged"):
        return f"{measured['cpu_s']:.3g} s"
    return f"not converged in {measured['cpu_s']:.0f} s"


def measured_on(run_times: dict) -> str:
    """'measured on <machine>, <date>, ...' of ``run_times`` ('' without them)."""
    if "machine" not in run_times or "date" not in run_times:
        return ""
    return f"measured on {run_times['machine']}, {run_times['date']}, CPU per solve"
