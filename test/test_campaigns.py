"""Dispersion campaigns (``daddy_sim.campaigns`` and its results file, executors, CLI, plot):
config validation naming the field, draws, failures recorded, resume after a kill, merge, the
summary from a hand-made file, and a campaign on a loopback Dask LocalCluster."""
import concurrent.futures
from concurrent.futures.process import BrokenProcessPool
import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from daddy_sim import closed_loop
from daddy_sim.campaign_cli import main as campaign_main
from daddy_sim.campaign_executors import Executor, open_executor
from daddy_sim.campaign_results import (Header, ResultsWriter, merge_results, read_results,
                                        summarise, wilson_interval)
from daddy_sim.campaigns import (CampaignConfig, CampaignError, Dispersion, RunRecord,
                                 RunStatus, load_config, run_campaign, run_one)
from daddy_ros.config import TriggerConfig
from daddy_sim.sim import T0_S, Errors, TruthSim

# Open loop (no re-plans): a run is a fraction of a second, and flies every dispersion.
OPEN_LOOP = {"case": "halo_l2_l1", "seeds": {"first": 1, "count": 4},
             "guidance": {"self_replan": False},
             "initial_state": {"position_m": 1000.0, "velocity_m_s": 0.01},
             "missed_thrust": {"probability": 0.5, "start_fraction": [0.2, 0.8],
                               "duration_hours": [12, 48]}}
# --------------------------------------------------------------------------------- config


def test_defaults_are_the_nodes_and_the_demos():
    c = CampaignConfig()
    assert c.guidance.policy == TriggerConfig()
    assert c.errors == Errors()
    assert c.seeds == tuple(range(1, 101))
    assert CampaignConfig.from_dict(c.to_dict()) == c
    assert CampaignConfig.from_dict({}) == c


@pytest.mark.parametrize("data, field", [
    ({"navigaton": {}}, "campaign.navigaton: unknown field"),
    ({"navigation": {"position": 1}}, "campaign.navigation.position: unknown field"),
    ({"navigation": {"position_m": -1}}, "campaign.navigation.position_m: must be in"),
    ({"navigation": {"position_m": "100"}}, "campaign.navigation.position_m: must be a finite"),
    ({"execution": {"pointing_deg": float("nan")}}, "campaign.execution.pointing_deg: must be"),
    ({"guidance": {"replan_every_stages": 1.5}}, "campaign.guidance.replan_every_stages: must "
                                                 "be an integer"),
    ({"guidance": {"self_replan": 1}}, "campaign.guidance.self_replan: must be true or false"),
    ({"missed_thrust": {"probability": 2}}, "campaign.missed_thrust.probability: must be in"),
    ({"missed_thrust": {"start_fraction": [0.9, 0.1]}}, "campaign.missed_thrust.start_fraction:"
                                                        " range low"),
    ({"missed_thrust": {"duration_hours": [1, 2, 3]}}, "campaign.missed_thrust.duration_hours"),
    ({"seeds": {"first": 1, "count": 0}}, "campaign.seeds.count: must be in"),
    ({"seeds": [1, 2, 1]}, "campaign.seeds: a seed is listed twice"),
    ({"seeds": "1-10"}, "campaign.seeds: must be"),
    ({"case": "no_such_case"}, "campaign.case:"),
    ({"case": "leo_leo"}, "campaign.case: 'leo_leo' cannot be flown"),
    ({"simulation": 3}, "campaign.simulation: expected a mapping"),
])
def test_bad_config_names_the_field(data, field):
    with pytest.raises(CampaignError, match=field.replace(".", r"\.").replace("(", r"\(")
                       .replace("[", r"\[")):
        CampaignConfig.from_dict(data)


def test_a_case_s_closed_loop_section_sets_its_mission_defaults_and_a_file_overrides_them(
        tmp_path):
    """Earth-Mars's navigation errors and success criteria come from its case file (an
    interplanetary mission's, not the cislunar defaults); a campaign file's fields override
    them one by one; a case file with a bad closed_loop section is named."""
    em = CampaignConfig.from_dict({"case": "earth_mars"})
    assert (em.navigation.position_m, em.success.miss_km, em.success.miss_cm_s) == (
        1000.0, 1000.0, 100.0)
    assert em.execution == CampaignConfig().execution          # not in its section: defaults
    own = CampaignConfig.from_dict({"case": "earth_mars", "success": {"miss_km": 5.0}})
    assert (own.success.miss_km, own.success.miss_cm_s) == (5.0, 100.0)
    assert CampaignConfig.from_dict(em.to_dict()) == em          # results headers round-trip
    assert CampaignConfig.from_dict({"case": "halo_l2_l1"}).success == CampaignConfig().success
    # the command line's --case (daddy_campaign run --case earth_mars) too, with or without a
    # campaign file, whose own fields still win
    import argparse

    from daddy_sim.campaign_cli import _config_from_args
    args = argparse.Namespace(config=None, case="earth_mars", runs=3, first_seed=None)
    assert _config_from_args(args).success == em.success
    (tmp_path / "c.json").write_text(json.dumps({"success": {"miss_cm_s": 50.0}}))
    args.config = str(tmp_path / "c.json")
    assert _config_from_args(args).success.miss_cm_s == 50.0
    assert _config_from_args(args).navigation == em.navigation
    case = json.loads((Path(__file__).parents[1] / "daddy_core/catalogue/cases/"
                       "earth_mars.json").read_text())
    for section, field in (({"success": {"miss_km": -1.0}}, "closed_loop.success.miss_km"),
                           ({"guidanse": {}}, "closed_loop.guidanse: unknown section")):
        path = tmp_path / "mission.json"
        path.write_text(json.dumps({**case, "closed_loop": section}))
        with pytest.raises(CampaignError, match=field.replace(".", r"\.")):
            CampaignConfig.from_dict({"case": str(path)})


def test_config_files_json_and_yaml(tmp_path):
    (tmp_path / "c.json").write_text(json.dumps(OPEN_LOOP))
    (tmp_path / "c.yaml").write_text("case: halo_l2_l1\nseeds: {first: 1, count: 4}\n"
                                     "guidance: {self_replan: false}\n"
                                     "initial_state: {position_m: 1000.0, velocity_m_s: 0.01}\n"
                                     "missed_thrust: {probability: 0.5, start_fraction: [0.2, "
                                     "0.8], duration_hours: [12, 48]}\n")
    assert load_config(tmp_path / "c.json") == load_config(tmp_path / "c.yaml")
    (tmp_path / "bad.yaml").write_text("guidance: {time_budget_s: 0}\n")
    with pytest.raises(CampaignError, match=r"bad\.yaml\.guidance\.time_budget_s"):
        load_config(tmp_path / "bad.yaml")
    with pytest.raises(CampaignError, match="missing.json"):
        load_config(tmp_path / "missing.json")


# --------------------------------------------------------------------------------- draws


def test_dispersions_leave_the_error_streams_alone_and_outages_stop_the_engine():
    c = CampaignConfig.from_dict(OPEN_LOOP)
    d = Dispersion.draw(c, 3, 86400.0)
    assert d == Dispersion.draw(c, 3, 86400.0) != Dispersion.draw(c, 4, 86400.0)
    assert np.any(np.array(d.initial_offset_si) != 0)
    plain = TruthSim("halo_l2_l1", seed=3, t0_s=T0_S)
    moved = TruthSim("halo_l2_l1", seed=3, t0_s=T0_S,
                     initial_offset_si=np.array(d.initial_offset_si))
    p0, v0, _ = plain.truth_si()
    p1, v1, _ = moved.truth_si()
    np.testing.assert_allclose(p1 - p0, d.initial_offset_si[:3], atol=1e-6)
    np.testing.assert_allclose(v1 - v0, d.initial_offset_si[3:], atol=1e-9)
    # the navigation errors drawn are the same numbers: the initial dispersion has its own stream
    e0, e1 = plain.estimate_si(), moved.estimate_si()
    np.testing.assert_allclose(e0[0] - p0, e1[0] - p1, atol=1e-6)
    # an outage covering the middle half of a step: the engine fires for half of it
    thrust = np.array([0.3, 0.0, 0.0])
    runs = {}
    for name, outage in (("on", None), ("half", (T0_S + 250.0, T0_S + 750.0)),
                         ("off", (T0_S - 1.0, T0_S + 2000.0))):
        sim = TruthSim("halo_l2_l1", Errors(0, 0, 0, 0), seed=0, t0_s=T0_S, outage_s=outage)
        applied = sim.apply(thrust, 1000.0)
        runs[name] = (sim.truth_si()[2], applied)
    m0 = TruthSim("halo_l2_l1").truth_si()[2]
    used = {k: m0 - m for k, (m, _) in runs.items()}
    assert used["off"] == 0.0 and not np.any(runs["off"][1])
    assert used["half"] == pytest.approx(used["on"] / 2, rel=1e-6)


# --------------------------------------------------------------------------------- runs


class _InThread(concurrent.futures.ThreadPoolExecutor):
    """One worker thread: monkeypatches in this process reach the runs."""

    def __init__(self):
        super().__init__(1)


def test_a_run_that_raises_is_recorded_and_the_campaign_goes_on(monkeypatch):
    real_fly = closed_loop.fly

    def fly(link, sim, *a, **kw):
        if sim.rng.bit_generator.seed_seq.entropy == 2:
            raise RuntimeError("boom in the loop")
        return real_fly(link, sim, *a, **kw)

    monkeypatch.setattr(closed_loop, "fly", fly)
    c = CampaignConfig.from_dict({**OPEN_LOOP, "seeds": [1, 2, 3]})
    with _InThread() as pool:
        recs = {r.seed: r for r in run_campaign(c, c.seeds, pool)}
    assert sorted(recs) == [1, 2, 3]
    assert recs[2].status is RunStatus.FAILED and recs[2].error == "RuntimeError: boom in the loop"
    assert not recs[2].success and math.isnan(recs[2].miss_km)
    assert recs[2].dispersion == Dispersion.draw(c, 2, TruthSim("halo_l2_l1").tof_s)
    assert recs[1].status is recs[3].status is RunStatus.COMPLETED
    assert recs[1].replans == 0 and recs[1].miss_km > 0


def test_a_run_the_executor_lost_is_recorded():
    class Lost(concurrent.futures.Executor):
        def submit(self, fn, *args, **kw):
            f = concurrent.futures.Future()
            f.set_exception(BrokenProcessPool("worker died"))
            return f

    recs = list(run_campaign(CampaignConfig(), [7], Lost()))
    assert len(recs) == 1 and recs[0].seed == 7 and recs[0].status is RunStatus.FAILED
    assert recs[0].error == "executor: concurrent.futures.process.BrokenProcessPool: worker died"


# --------------------------------------------------------------------------------- results files


def _record(seed, success, km, cm_s, prop, lat=(), status=RunStatus.COMPLETED, error=""):
    if status is RunStatus.FAILED:
        return RunRecord.failed(seed, error, cpu_s=1.0)
    return RunRecord(seed=seed, status=status, success=success, miss_km=km, miss_cm_s=cm_s,
                     final_mass_kg=1000.0 - prop, propellant_kg=prop, replans=len(lat),
                     latency_ms=tuple(lat), cpu_s=2.0)


def _header(**config):
    return Header(CampaignConfig.from_dict({"seeds": {"first": 1, "count": 5}, **config}),
                  open_loop_final_mass_kg=975.0, wet_mass_kg=1000.0, version="9.9")


def test_summary_from_a_hand_made_results_file(tmp_path):
    """The numbers are worked by hand from the lines below (Wilson 3/5: 0.2307 - 0.8824)."""
    lines = [_header().to_json(),
             _record(1, True, 0.1, 0.2, 25.0, (10.0, 30.0)).to_json(),
             _record(2, True, 0.3, 0.4, 25.1, (20.0,)).to_json(),
             _record(3, True, 0.2, 0.1, 24.9, (40.0, 50.0)).to_json(),
             _record(4, False, 5.0, 3.0, 26.0, (1000.0,)).to_json(),
             _record(5, False, 0, 0, 0, status=RunStatus.FAILED, error="ValueError: x").to_json()]
    p = tmp_path / "r.jsonl"
    p.write_text("".join(json.dumps(x) + "\n" for x in lines))
    s = summarise(read_results(p))
    assert (s.runs, s.completed, s.failed, s.success) == (5, 4, 1, 3)
    assert s.success_rate == 0.6
    assert s.success_wilson_95 == pytest.approx((0.2307, 0.8824), abs=1e-4)
    assert (s.miss_km.median, s.miss_km.max) == (pytest.approx(0.25), 5.0)
    assert s.propellant_kg.median == pytest.approx(25.05)
    assert s.propellant_open_loop_kg == 25.0
    assert (s.latency_ms.median, s.latency_ms.p95, s.latency_ms.max) == (35.0, 1000.0, 1000.0)
    assert s.replans_per_run == 1.5 and s.cpu_s_per_run == pytest.approx(1.8)
    assert s.errors == (("ValueError: x", 1),)
    assert wilson_interval(0, 10) == (0.0, pytest.approx(0.2775, abs=1e-4))
    assert wilson_interval(10, 10) == (pytest.approx(0.7225, abs=1e-4), 1.0)
    out = subprocess.run([sys.executable, "-m", "daddy_sim.campaign_cli", "summary", str(p)],
                         capture_output=True, text=True, check=True).stdout
    assert "3/5 = 60.0 %" in out.replace("60.0%", "60.0 %") and "23.1%" in out
    assert "failed x1: ValueError: x" in out
    js = json.loads(subprocess.run([sys.executable, "-m", "daddy_sim.campaign_cli", "summary",
                                    str(p), "--json"], capture_output=True, text=True,
                                   check=True).stdout)
    assert js["success"] == 3 and js["miss_km"]["max"] == 5.0


def test_bad_results_files_name_file_and_line(tmp_path):
    p = tmp_path / "r.jsonl"
    p.write_text(json.dumps(_header().to_json()) + "\n{not json\n"
                 + json.dumps(_record(1, True, 0.1, 0.1, 25).to_json()) + "\n")
    with pytest.raises(CampaignError, match=r"r\.jsonl:2: not JSON"):
        read_results(p)
    p.write_text(json.dumps(_record(1, True, 0.1, 0.1, 25).to_json()) + "\n")
    with pytest.raises(CampaignError, match="first line is not a campaign header"):
        read_results(p)


def test_partial_last_line_is_ignored_and_trimmed_on_resume(tmp_path):
    p = tmp_path / "r.jsonl"
    full = json.dumps(_record(1, True, 0.1, 0.1, 25).to_json()) + "\n"
    p.write_text(json.dumps(_header().to_json()) + "\n" + full + full[:40])
    res = read_results(p)
    assert len(res.records) == 1 and res.partial_lines == 1
    with ResultsWriter.resume(p) as w:
        assert w.recorded == {1}
        w.append(_record(2, True, 0.1, 0.1, 25))
    res = read_results(p)
    assert [r.seed for r in res.records] == [1, 2] and res.partial_lines == 0


def test_merge_one_experiment_only(tmp_path):
    a, b, c = tmp_path / "a.jsonl", tmp_path / "b.jsonl", tmp_path / "c.jsonl"
    with ResultsWriter.create(a, _header()) as w:
        for s in (1, 2):
            w.append(_record(s, True, 0.1, 0.1, 25))
    with ResultsWriter.create(b, _header()) as w:
        for s in (2, 3):
            w.append(_record(s, False, 9.0, 0.1, 25))
    merged, dropped = merge_results([a, b], tmp_path / "m.jsonl")
    assert dropped == 1 and [r.seed for r in merged.records] == [1, 2, 3]
    back = read_results(tmp_path / "m.jsonl")
    assert back.records[1].success and back.header.config.seeds == (1, 2, 3)
    with ResultsWriter.create(c, _header(navigation={"position_m": 5.0})):
        pass
    with pytest.raises(CampaignError, match=r"navigation\.position_m: 100\.0 vs 5\.0"):
        merge_results([a, c], tmp_path / "x.jsonl")
    with pytest.raises(CampaignError, match="exists"):
        merge_results([a, b], tmp_path / "m.jsonl")


def test_campaign_plot_is_a_readable_png(tmp_path):
    pytest.importorskip("matplotlib")
    p = tmp_path / "r.jsonl"
    rng = np.random.default_rng(0)
    with ResultsWriter.create(p, _header()) as w:
        for s in range(1, 41):
            km, cms = rng.lognormal(-2, 1), rng.lognormal(-2, 1)
            w.append(_record(s, km < 1 and cms < 1, km, cms, 25 + rng.normal(0, 0.1),
                             tuple(rng.lognormal(4, 0.5, 20))))
        w.append(_record(41, False, 0, 0, 0, status=RunStatus.FAILED, error="X: y"))
    assert campaign_main(["plot", str(p), "-o", str(tmp_path / "r.png")]) == 0
    png = (tmp_path / "r.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 20_000


# --------------------------------------------------------------------------------- CLI


def _records_in(path: Path) -> int:
    try:
        return sum(1 for line in path.read_text().splitlines() if '"type": "run"' in line)
    except FileNotFoundError:
        return 0


def test_resume_after_the_campaign_is_killed(tmp_path):
    """SIGKILL to the whole campaign (CLI and its pool) after 2 records; --resume runs the
    rest: every seed once, the first records untouched."""
    cfg = tmp_path / "c.json"
    cfg.write_text(json.dumps({**OPEN_LOOP, "seeds": {"first": 1, "count": 8}}))
    out = tmp_path / "r.jsonl"
    cmd = [sys.executable, "-m", "daddy_sim.campaign_cli", "run", str(cfg), "--out", str(out),
           "--jobs", "1"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while _records_in(out) < 2 and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    before = read_results(out).records
    assert 2 <= len(before) < 8, proc.stderr.read()
    rc = campaign_main(["run", "--resume", str(out), "--jobs", "2"])
    assert rc == 0
    after = read_results(out).records
    assert sorted(r.seed for r in after) == list(range(1, 9))
    assert after[:len(before)] == before
    try:   # the resumed campaign's table: the whole file, both parts
        from daddy_sim.campaign_table import read_table
        table = read_table(out.with_suffix(".parquet"))
    except CampaignError as exc:
        assert "tables extra" in str(exc)
    else:
        assert [r.seed for r in table.records] == [r.seed for r in after]


def test_gnc_demo_runs_is_a_campaign(tmp_path, capsys):
    from daddy_sim.demo import main as demo_main
    out = tmp_path / "runs.jsonl"
    rc = demo_main(["--runs", "2", "--jobs", "1", "--seed", "5", "--replan-every", "1000",
                    "--final-stages", "0", "--trigger-km", "0", "--trigger-cm-s", "0",
                    "--results", str(out)])
    assert rc == 0
    res = read_results(out)
    assert sorted(r.seed for r in res.records) == [5, 6]
    assert all(r.status is RunStatus.COMPLETED and r.replans == 0 for r in res.records)
    assert res.header.config.guidance.replan_every_stages == 1000
    assert "success (<= 1 km, <= 1 cm/s" in capsys.readouterr().out


def test_cli_errors_name_the_option(tmp_path, capsys):
    assert campaign_main(["run", "--case", "leo_leo", "--out", str(tmp_path / "x")]) == 2
    assert "--case: 'leo_leo' cannot be flown" in capsys.readouterr().err
    assert campaign_main(["run", "--runs", "0", "--out", str(tmp_path / "x")]) == 2
    assert "--runs: must be at least 1" in capsys.readouterr().err
    assert campaign_main(["run", "--scheduler", "tcp://127.0.0.1:1", "--runs", "1",
                          "--out", str(tmp_path / "y")]) == 2
    assert "--scheduler: an existing cluster is a Dask one" in capsys.readouterr().err
    assert not (tmp_path / "y").exists()


# --------------------------------------------------------------------------------- Dask


def _listening(proc) -> list:
    """(ip, port) of every listening TCP socket of a psutil process and its children."""
    import psutil
    out = []
    for p in [proc, *proc.children(recursive=True)]:
        try:
            out += [c.laddr for c in p.net_connections(kind="inet")
                    if c.status == psutil.CONN_LISTEN]
        except psutil.NoSuchProcess:
            pass
    return out


def test_dask_local_cluster_gives_the_local_records_and_stays_on_loopback():
    pytest.importorskip("distributed", reason="the campaigns extra (make test installs it)")
    import psutil
    c = CampaignConfig.from_dict(OPEN_LOOP)
    with open_executor(Executor.DASK, 2) as (pool, what):
        assert "LocalCluster tcp://127.0.0.1:" in what
        dask = {r.seed: r for r in run_campaign(c, c.seeds, pool)}
        listening = _listening(psutil.Process())
        # the same cluster as an existing one (--scheduler): a client of its own
        address = what.split()[2].rstrip(",")
        with open_executor(Executor.DASK, 1, scheduler=address) as (remote, what2):
            assert what2 == f"Dask cluster {address}, 2 workers"
            again = list(run_campaign(c, c.seeds[:2], remote))
    # scheduler, dashboard, 2 nannies, 2 workers: all bound to loopback
    assert len(listening) >= 6, listening
    assert {addr.ip for addr in listening} == {"127.0.0.1"}, listening
    local = {s: run_one(c, s) for s in c.seeds}
    assert sorted(dask) == list(c.seeds)
    assert len({r.worker for r in dask.values()} - {local[1].worker}) >= 1
    for s in c.seeds:
        assert dask[s].outcome() == local[s].outcome()
    assert any(r.dispersion.outage_s for r in dask.values())
    assert sorted(r.outcome() for r in again) == [dask[s].outcome() for s in c.seeds[:2]]


def test_dask_missing_says_how_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)
    with pytest.raises(CampaignError, match=r"pip install 'daddy_ros\[campaigns\]'"):
        with open_executor(Executor.DASK, 1):
            pass
