"""A campaign's results as a table (``daddy_sim.campaign_table``): pandas reads the Parquet
file in one line with the documented columns; the terminal state and its RTN deviation follow
from the records by an independent computation; JSONL -> Parquet -> JSONL keeps every record;
merge and a finished campaign write the table beside their file; the plot reads a table; the
progress bar; pyarrow missing is said."""
import json
import math
import re
import sys
from pathlib import Path

import numpy as np
import pytest

from daddy_core.catalogue import load_case
from daddy_sim.campaign_cli import execute, main as campaign_main
from daddy_sim.campaign_results import Header, ResultsWriter, read_results
from daddy_sim.campaign_table import NAMES, columns, read_table, write_table
from daddy_sim.campaigns import CampaignConfig, CampaignError, Dispersion, RunRecord, RunStatus

pd = pytest.importorskip("pandas", reason="the analysis extra (make test installs it)")
pytest.importorskip("pyarrow", reason="the analysis extra (make test installs it)")

DOCS = Path(__file__).resolve().parents[1] / "docs" / "campaigns.md"


def _header(case="halo_l2_l1", count=6):
    return Header(CampaignConfig.from_dict({"case": case,
                                            "seeds": {"first": 1, "count": count}}),
                  open_loop_final_mass_kg=973.0, wet_mass_kg=1000.0, version="9.9")


def _runs(n, rng):
    """n completed runs with deviations, dispersions and latencies, and one failed run."""
    out = []
    for s in range(1, n + 1):
        dev = tuple(float(x) for x in np.r_[rng.normal(0, 100, 3), rng.normal(0, 1e-3, 3)])
        outage = (float(rng.uniform(1e4, 1e5)), 3600.0) if s % 2 else None
        out.append(RunRecord(
            seed=s, status=RunStatus.COMPLETED, success=bool(s % 3), miss_km=0.1 * s,
            miss_cm_s=0.01 * s, final_mass_kg=973.0 - 0.001 * s, propellant_kg=27.0 + 0.001 * s,
            replans=3, drift_replans=1, latency_ms=tuple(rng.lognormal(3, 1, 3)),
            deviation_si=dev, laws_served=2, law_eval_ms=(0.03, 0.05), wall_s=1.5, cpu_s=1.4,
            dispersion=Dispersion(tuple(rng.normal(0, 10, 6)), outage), worker="h:1"))
    out.append(RunRecord.failed(n + 1, "ValueError: x", cpu_s=0.5, worker="h:2"))
    return out


def _results_file(path, n=5, seed=0):
    with ResultsWriter.create(path, _header(count=n + 1)) as w:
        for r in _runs(n, np.random.default_rng(seed)):
            w.append(r)
    return read_results(path)


def _json(records) -> list:
    """Records as their JSON (NaN as null: NaN fields compare equal)."""
    return [r.to_json() for r in records]


def test_pandas_reads_the_table_in_one_line_with_the_documented_columns(tmp_path):
    _results_file(tmp_path / "r.jsonl")
    assert campaign_main(["export", str(tmp_path / "r.jsonl")]) == 0
    df = pd.read_parquet(tmp_path / "r.parquet")
    assert df.shape == (6, len(NAMES)) and tuple(df.columns) == NAMES
    assert list(df.seed) == [1, 2, 3, 4, 5, 6]
    assert list(df.status) == ["completed"] * 5 + ["failed"]
    assert df.success.dtype == bool and df.replans.dtype == np.int64
    assert math.isnan(df.miss_km[5]) and df.error[5] == "ValueError: x"
    assert df.propellant_excess_kg[0] == pytest.approx(27.001 - 27.0)
    # every column is documented, in order, with its unit (docs/campaigns.md's table)
    documented = re.findall(r"^\| `([a-z0-9_]+)` \|", DOCS.read_text(), flags=re.M)
    assert tuple(documented) == NAMES


def test_terminal_state_and_rtn_deviation_follow_from_the_records(tmp_path):
    """The terminal state is the target's plus the deviation; the RTN deviation's components
    are its projections on r, r x v and their cross product, computed here from the case."""
    res = _results_file(tmp_path / "r.jsonl")
    df = pd.DataFrame(columns(res))
    case = load_case("halo_l2_l1")
    target = case.units.cartesian_si(case.x_target)[:6]
    r, v = target[:3], target[3:]
    R = r / np.linalg.norm(r)
    N = np.cross(r, v) / np.linalg.norm(np.cross(r, v))
    T = np.cross(N, R)
    for i, rec in enumerate(res.records[:5]):
        d = np.array(rec.deviation_si)
        row = df.iloc[i]
        assert np.allclose(row[["x_m", "y_m", "z_m", "vx_m_s", "vy_m_s", "vz_m_s"]]
                           .to_numpy(float), target + d, rtol=0, atol=1e-6)
        for axis, e in zip("rtn", (R, T, N)):
            assert row[f"d{axis}_rtn_m"] == pytest.approx(d[:3] @ e, abs=1e-9)
            assert row[f"dv{axis}_rtn_m_s"] == pytest.approx(d[3:] @ e, abs=1e-15)
        assert rec.miss_km >= 0   # (the record's own miss is its flight's, not checked here)
    assert np.isnan(df.iloc[5][["x_m", "dr_rtn_m", "initial_dx_m"]].to_numpy(float)).all()


def test_jsonl_parquet_jsonl_keeps_every_record_and_the_header(tmp_path):
    res = _results_file(tmp_path / "r.jsonl")
    write_table(res, tmp_path / "r.parquet")
    back = read_table(tmp_path / "r.parquet")
    assert _json(back.records) == _json(res.records)
    assert back.header == res.header
    assert campaign_main(["export", str(tmp_path / "r.parquet"), "-o",
                          str(tmp_path / "again.jsonl")]) == 0
    assert _json(read_results(tmp_path / "again.jsonl").records) == _json(res.records)
    # summaries of either file agree
    for name in ("r.jsonl", "r.parquet"):
        assert campaign_main(["summary", str(tmp_path / name), "--json"]) == 0


def test_merge_writes_the_merged_table_beside_its_file(tmp_path, capsys):
    a, b = tmp_path / "a.jsonl", tmp_path / "b.jsonl"
    runs = _runs(4, np.random.default_rng(1))
    for path, part in ((a, runs[:3]), (b, runs[2:])):
        with ResultsWriter.create(path, _header(count=5)) as w:
            for r in part:
                w.append(r)
    assert campaign_main(["merge", str(a), str(b), "-o", str(tmp_path / "m.jsonl")]) == 0
    assert f"table: {tmp_path / 'm.parquet'}" in capsys.readouterr().out
    df = pd.read_parquet(tmp_path / "m.parquet")
    assert list(df.seed) == [1, 2, 3, 4, 5]
    assert _json(read_table(tmp_path / "m.parquet").records) == _json(read_results(
        tmp_path / "m.jsonl").records)


def test_the_plot_reads_a_table(tmp_path):
    pytest.importorskip("matplotlib")
    _results_file(tmp_path / "r.jsonl", n=30)
    assert campaign_main(["export", str(tmp_path / "r.jsonl")]) == 0
    assert campaign_main(["plot", str(tmp_path / "r.parquet"), "-o",
                          str(tmp_path / "r.png")]) == 0
    png = (tmp_path / "r.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 40_000


def test_export_refusals_name_the_option(tmp_path, capsys):
    _results_file(tmp_path / "r.jsonl")
    assert campaign_main(["export", str(tmp_path / "r.jsonl"), "-o",
                          str(tmp_path / "r.csv")]) == 2
    assert "export -o" in capsys.readouterr().err
    assert campaign_main(["export", str(tmp_path / "r.jsonl")]) == 0
    assert campaign_main(["export", str(tmp_path / "r.jsonl")]) == 2
    assert "exists (--overwrite" in capsys.readouterr().err
    assert campaign_main(["export", str(tmp_path / "r.parquet")]) == 2
    assert "-o F.jsonl" in capsys.readouterr().err
    (tmp_path / "x.parquet").write_bytes(b"not parquet")
    assert campaign_main(["summary", str(tmp_path / "x.parquet")]) == 2
    assert "results table" in capsys.readouterr().err


def test_without_pyarrow_the_table_is_skipped_and_says_how(tmp_path, monkeypatch):
    res = _results_file(tmp_path / "r.jsonl")
    monkeypatch.setitem(sys.modules, "pyarrow", None)
    with pytest.raises(CampaignError, match=r"pip install 'daddy_ros\[analysis\]'"):
        write_table(res, tmp_path / "r.parquet")


def test_a_progress_bar_with_the_success_so_far(tmp_path, capsys):
    """An open-loop campaign of 3 runs with the bar: one bar on stderr ending at 3/3 with
    the success count; no per-run lines for the runs that succeeded."""
    pytest.importorskip("tqdm", reason="the campaigns extra (make test installs it)")
    from daddy_sim.campaign_executors import Executor
    config = CampaignConfig.from_dict({"case": "halo_l2_l1", "seeds": {"first": 1, "count": 3},
                                       "guidance": {"self_replan": False},
                                       "success": {"miss_km": 1e9, "miss_cm_s": 1e9,
                                                   "propellant_fraction": 1.0}})
    header = Header(config, 973.0, 1000.0)
    lines = []
    with ResultsWriter.create(tmp_path / "r.jsonl", header) as w:
        assert execute(w, config, Executor.LOCAL, 1, out=lines.append, bar=True) == 3
    err = capsys.readouterr().err
    assert "3/3" in err and "success 3/3" in err
    assert not any(line.startswith("[") for line in lines), lines
    assert len(read_results(tmp_path / "r.jsonl").records) == 3
    assert json.loads((tmp_path / "r.jsonl").read_text().splitlines()[0])["type"] == "header"
