"""The solar-sail cases (issue 45): each in its window against the independent references
computed for the issue (CasADi + IPOPT, re-propagated with DOP853), from the steering law and
from the Sun-facing guess; the model against a Cartesian energy rate; bad case files refused by
field; `daddy solve` writing what a user opens."""
import csv
import json
import math

import numpy as np
import pytest

from daddy_core.catalogue import load_case, load_thrust_case
from daddy_core.catalogue.cases import CASES_DIR
from daddy_core.catalogue.sail_cases import (SailGuess, continuous_law, law_controls,
                                             sail_case_from_dict, solve_sail)
from daddy_core.cli import main
from daddy_core.dynamics import models, sail
from daddy_core.errors import DaddyError

GEO_2D_OPTIMUM_KM = 205.7018     # issue 45: the discrete optimum of the 2-D case
GEO_2D_LAW_KM = 205.7359         # the continuous steering law
GEO_3D_OPTIMUM_KM = {0.0: 207.5038, 90.0: 208.1062, 180.0: 208.8721}
ACS3_PAPER_KM = 0.464314         # the paper, no perturbations (window: 1 %)
ACS3_J2_OSCULATING_KM = 0.46618  # issue 45's reference with J2, osculating


def _gain(case, x):
    a = lambda s: s[0] / (1 - s[1] ** 2 - s[2] ** 2)   # noqa: E731
    return (a(x) - a(case.x0)) * case.units.lu_km


def _geo_3d(phase_deg: float):
    d = json.loads((CASES_DIR / "geo_sail_3rev.json").read_text())
    d["x0"][5] = phase_deg
    return sail_case_from_dict(d)


@pytest.mark.parametrize("guess", list(SailGuess))
def test_the_planar_geo_raise_reaches_the_discrete_optimum_from_either_guess(guess):
    case = load_case("geo_sail_2d_3rev")
    r = solve_sail(case, guess)
    assert r.solution.converged
    assert r.delta_a_km["osculating"] == pytest.approx(GEO_2D_OPTIMUM_KM, abs=0.01)
    # the law held per stage is a feasible point: DDP's optimum is at least as good
    assert r.delta_a_km["osculating"] >= r.law_delta_a_km["osculating"]


def test_the_continuous_steering_law_is_the_references():
    """The model and the law, flown continuously (DOP853), against the issue's independent
    propagation of the same law: 205.7359 km (2-D) and 208.9069 km (3-D, phase 180 deg)."""
    case = load_case("geo_sail_2d_3rev")
    assert _gain(case, continuous_law(case)) == pytest.approx(GEO_2D_LAW_KM, abs=1e-3)
    case = load_case("geo_sail_3rev")
    assert _gain(case, continuous_law(case)) == pytest.approx(208.9069, abs=1e-3)


@pytest.mark.parametrize("phase", [180.0, 0.0, 90.0])
def test_the_3d_geo_raise_at_each_phase(phase):
    """208.87 +- 0.02 km at the case's phase (180 deg); at any phase the continuous law minus
    35 +- 5 m (the paper's gap between DDP and the law), and the issue's optimum there."""
    case = load_case("geo_sail_3rev") if phase == 180.0 else _geo_3d(phase)
    r = solve_sail(case, SailGuess.SUN_FACING if phase == 180.0 else SailGuess.STEERING_LAW)
    da = r.delta_a_km["osculating"]
    assert r.solution.converged
    assert da == pytest.approx(GEO_3D_OPTIMUM_KM[phase], abs=0.02)
    law = _gain(case, continuous_law(case))
    assert law - da == pytest.approx(0.035, abs=0.005)


def test_acs3_within_a_percent_of_the_paper_with_eclipses():
    case = load_case("acs3_3rev")
    assert case.eclipse_width_km == 10.0
    r = solve_sail(case)
    assert r.solution.converged
    assert r.delta_a_km["osculating"] == pytest.approx(ACS3_PAPER_KM, rel=0.01)
    assert r.delta_a_km["osculating"] >= r.law_delta_a_km["osculating"]
    # the law passes the shadow: the sunlight fraction is ~0 over part of each revolution
    assert "j2_energy" not in r.delta_a_km


def test_acs3_with_j2_reports_both_gains_and_matches_the_independent_osculating_value():
    """With J2 the osculating a swings, but the case starts and ends at the ascending node
    after whole revolutions: the osculating and the J2-energy gains agree within a metre, and
    both are the issue's independent 0.46618 km within 0.1 %, not the paper's 0.389 km."""
    r = solve_sail(load_case("acs3_3rev_j2"))
    assert r.solution.converged
    d = r.delta_a_km
    assert d["osculating"] == pytest.approx(ACS3_J2_OSCULATING_KM, rel=1e-3)
    assert abs(d["osculating"] - d["j2_energy"]) < 1e-3


def test_the_sail_rates_are_the_cartesian_energy_rate():
    """The Sundman-staged elements' rates, turned into da/dt, equal 2 a^2 / mu (a_sail . v)
    from the Cartesian acceleration -- Gauss' equations in MEE checked against the energy."""
    case = load_case("geo_sail_3rev")
    rhs = case.rhs()
    rng = np.random.default_rng(3)
    gm = case.units.gm
    for _ in range(5):
        x = np.array([1.0 + 0.1 * rng.random(), 0.05 * rng.normal(), 0.05 * rng.normal(),
                      0.1 * rng.normal(), 0.1 * rng.normal(), rng.random()])
        L = rng.uniform(0, 2 * math.pi)
        u = rng.normal(size=2)
        rates = np.asarray(rhs(L, x, u), float)
        p, f, g = x[:3]
        q = 1 - f * f - g * g
        da_dL = rates[0] / q + p * (2 * f * rates[1] + 2 * g * rates[2]) / q ** 2
        da_dt = da_dL / rates[5]
        rv = models.mee_to_cartesian(x[:5], L, gm)
        r_sun = np.asarray(case.sun_position(x[5]), float)
        s_hat = (rv[:3] - r_sun) / np.linalg.norm(rv[:3] - r_sun)
        n = np.asarray(sail.sail_normal(u[0], u[1], s_hat), float)
        model = case.sail_model()
        acc = np.asarray(sail.sail_acceleration(rv[:3], r_sun, n, 1.0, model.sail_gm), float)
        a = p / q
        assert da_dt == pytest.approx(2 * a * a / gm * (acc @ rv[3:]), rel=1e-9)


def test_the_steering_law_maximises_the_energy_rate_over_a_brute_force_search():
    case = load_case("geo_sail_3rev")
    x, L = case.x0, case.t_start + 0.7
    rhs = case.rhs()
    best = law_controls(case, x, L)
    rate = lambda u: float(np.asarray(rhs(L, x, u), float)[0])   # noqa: E731  (dp/dL at e = 0)
    grid = np.linspace(-6, 6, 121)
    brute = max(rate(np.array([w1, w2])) for w1 in grid for w2 in grid)
    assert rate(best) >= brute - 1e-12 * abs(brute)


BASE = {"name": "bad", "system": "earth_sail", "x0": [42241.0, 0, 0, 0, 0, 0], "beta": 0.011,
        "epoch": "2000-01-01T12:00:00", "revolutions": 1, "stages_per_revolution": 100}


@pytest.mark.parametrize("change, field", [
    ({"beta": 0.0}, "'beta'"), ({"beta": -0.01}, "'beta'"),
    ({"x0": [6000.0, 0, 0, 0, 0, 0]}, "'x0'"), ({"x0": [8000.0, 0.3, 0, 0, 0, 0]}, "'x0'"),
    ({"epoch": "2071-01-01T00:00:00"}, "'epoch'"), ({"epoch": "yesterday"}, "'epoch'"),
    ({"steering": "sideways"}, "'steering'"), ({"perturbations": ["j5"]}, "'perturbations'"),
    ({"eclipse": {"width_km": 0}}, "'eclipse.width_km'"),
    ({"eclipse": {"shadow": "cone", "width_km": 5}}, "'eclipse.shadow'"),
    ({"sun": {"fixed_direction": [0, 0, 0]}}, "'sun.fixed_direction'"),
    ({"wet_mass_kg": 100}, "'wet_mass_kg'"), ({"stages_per_revolution": 2}, "'stages_per_revolution'"),
])
def test_bad_sail_case_files_are_refused_by_field(change, field):
    with pytest.raises(DaddyError, match=field):
        sail_case_from_dict({**BASE, **change})


def test_the_guidance_node_refuses_a_sail_case_by_name():
    with pytest.raises(DaddyError, match="solar-sail case"):
        load_thrust_case("geo_sail_3rev")


def test_daddy_solve_writes_a_sail_solution_a_user_can_open(tmp_path, capsys):
    out = tmp_path / "s"
    assert main(["solve", "geo_sail_2d_3rev", "--quiet", "--guess", "sun_facing",
                 "--json", f"{out}.json", "--csv", f"{out}.csv", "--oem", f"{out}.oem"]) == 0
    text = capsys.readouterr().out
    assert "semi-major axis gain 205.70" in text and "steering law held per stage" in text
    d = json.loads(open(f"{out}.json").read())
    assert d["sail"]["delta_a_km"]["osculating"] == pytest.approx(GEO_2D_OPTIMUM_KM, abs=0.01)
    assert d["sail"]["eclipse_width_km"] is None and d["method"] == "hessdyn"
    rows = list(csv.DictReader(open(f"{out}.csv")))
    assert len(rows) == 301
    a = [float(r["a_km"]) for r in rows]
    assert a[-1] - a[0] == pytest.approx(d["sail"]["delta_a_km"]["osculating"], abs=1e-9)
    cone = np.array([float(r["cone_deg"]) for r in rows[:-1]])
    assert np.all(np.abs(cone) < 90) and rows[-1]["cone_deg"] == ""
    oem = open(f"{out}.oem").read()
    assert "REF_FRAME = EME2000" in oem and "START_TIME = 2000-01-01T12:00:00" in oem
    # thrust-case options are refused for a sail case, by name
    assert main(["solve", "geo_sail_2d_3rev", "--fuel"]) == 2
    assert "--fuel" in capsys.readouterr().err


@pytest.mark.slow
def test_the_500_revolution_geo_raise_beats_the_steering_law_within_a_percent_of_the_paper():
    """GEO, 500 revolutions (50 000 stages), beta 0.0011, eclipses, J2-J4, the Moon and the
    Sun: at least the law held per stage, within 1 % of the paper's 3793.1 km."""
    r = solve_sail(load_case("geo_sail_500rev"))
    assert np.all(np.isfinite(r.solution.X))
    assert r.delta_a_km["osculating"] >= r.law_delta_a_km["osculating"]
    assert r.delta_a_km["osculating"] == pytest.approx(3793.1, rel=0.01)


def test_daddy_solve_plots_a_sail_case(tmp_path):
    """The plot of a, e, i over revolutions and the sail angles with the shadow arcs (the
    plots extra, installed by make test)."""
    pytest.importorskip("matplotlib")
    png = tmp_path / "acs3.png"
    assert main(["solve", "acs3_3rev", "--quiet", "--plot", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20_000
