"""The campaign's terminal dispersion predicted on the linearised closed loop (issue 47,
``daddy_sim/campaign_prediction.py``): its maps against flown dispersions, and the CLI that
prints it beside a results file's runs."""
import json

import numpy as np
import pytest

from daddy_sim.campaign_prediction import compare, predict
from daddy_sim.campaigns import CampaignConfig, Dispersion
from daddy_sim.closed_loop import DirectLink, fly, nominal_planner
from daddy_sim.sim import T0_S, TruthSim

QUIET = {"navigation": {"position_m": 0.0, "velocity_m_s": 0.0},
         "execution": {"magnitude": 0.0, "pointing_deg": 0.0},
         "initial_state": {"position_m": 100.0, "velocity_m_s": 1e-3}}


def _flown(config: CampaignConfig, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(the seed's initial offset (6,), its flight's terminal deviation (6,))."""
    planner, _ = nominal_planner(config.case, 60.0, config.guidance.arrival_tolerance_m)
    case = planner.case
    draw = Dispersion.draw(config, seed, case.tof * case.units.tu_s)
    offset = np.array(draw.initial_offset_si)
    sim = TruthSim(config.case, config.errors, seed=seed, t0_s=T0_S, initial_offset_si=offset)
    policy = config.guidance.policy
    r = fly(DirectLink(planner, policy), sim, planner, policy, config.simulation.substeps,
            config.simulation.final_substeps)
    return offset, r["deviation_si"]


def test_the_linearised_open_loop_is_the_flown_one_to_its_nonlinearity():
    """Flown open loop from five initial offsets (100 m, 1 mm/s per axis; no other error), the
    terminal deviations (~15 km) are the prediction's for the same offsets to 3 %."""
    config = CampaignConfig.from_dict({**QUIET, "guidance": {"self_replan": False}})
    offsets, flown = zip(*(_flown(config, seed) for seed in range(1, 6)))
    predicted = predict(config, initial_si=np.array(offsets)).deviations_si
    for p, f in zip(predicted, flown):
        assert np.linalg.norm(p[:3] - f[:3]) < 0.03 * np.linalg.norm(f[:3])
        assert np.linalg.norm(p[3:] - f[3:]) < 0.03 * np.linalg.norm(f[3:])


def test_a_comparison_puts_the_prediction_inside_or_outside_the_runs_intervals():
    """Runs whose sample mean is 0 and standard deviation sigma: a prediction of the same
    Gaussian is inside both 95 % intervals on every axis, one 1.5x as wide outside the
    standard deviation's and inside the mean's."""
    from daddy_sim.campaign_prediction import Prediction
    sigma = np.array([100, 100, 100, 1e-3, 1e-3, 1e-3])
    rng = np.random.default_rng(1)
    z = rng.normal(size=(400, 6))
    runs = (z - z.mean(axis=0)) / z.std(axis=0, ddof=1) * sigma
    same = Prediction(rng.normal(size=(20000, 6)) * sigma, 1.0)
    wide = Prediction(same.deviations_si * 1.5, 1.0)
    assert compare(same, runs, 100.0).std_inside.all()
    assert not compare(wide, runs, 100.0).std_inside.any()
    assert compare(wide, runs, 100.0).mean_inside.all()


def test_daddy_campaign_predict_prints_the_prediction_beside_the_runs(tmp_path, capsys):
    from daddy_sim.campaign_cli import main
    out = tmp_path / "c.jsonl"
    config = tmp_path / "c.json"
    config.write_text(json.dumps({"case": "halo_l2_l1", "seeds": {"first": 1, "count": 2},
                                  **QUIET, "guidance": {"self_replan": False}}))
    assert main(["run", str(config), "--out", str(out), "--jobs", "1"]) == 0
    capsys.readouterr()
    assert main(["predict", str(out), "--samples", "500", "--plot",
                 str(tmp_path / "p.png")]) == 0
    text = capsys.readouterr().out
    assert "2 closed-loop runs" in text and "vz [m/s]" in text
    assert (tmp_path / "p.png").stat().st_size > 10_000
    assert main(["predict", str(config), "--samples", "500"]) == 0   # a campaign file: no runs
    assert "x [m]" in capsys.readouterr().out
