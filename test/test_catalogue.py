"""The catalogue loads every paper case with the paper's constants; bad case files are named."""
import json

import numpy as np
import pytest

from daddy_core.dynamics import Spacecraft
from daddy_core.errors import DaddyError
from daddy_core.catalogue import case_from_dict, list_cases, load_case

EXPECTED = {  # name: (tof days, N); Earth-centred cases: N from their revolutions (below)
    "earth_mars": (348.79, 40), "halo_l2_l1": (20, 110), "nrho_dro": (21.2, 150),
    "lyapunov_l1_l2": (12, 300), "dro_dro": (17.5, 100), "dro_dro_2rev": (33, 300),
    "dro_dro_3rev": (52.75, 200), "leo_leo": (35, 5221), "leo_leo_j2": (35, 5221),
    "meo_meo": (55, 1199), "gto_geo": (95, 4969),
}
SAIL_CASES = ("geo_sail_2d_3rev", "geo_sail_3rev", "acs3_3rev", "acs3_3rev_j2", "acs3_3rev_j2j4",
              "acs3_3rev_all", "geo_sail_500rev")   # test_sail_cases.py


def test_all_cases_present_and_consistent():
    assert (set(EXPECTED) | {"double_integrator", "two_phase_lq", "dro_dro_pddp",
                             "dro_dro_2rev_pddp"} | set(SAIL_CASES) == set(list_cases()))
    # two_phase_lq: test_phased_cases.py; dro_dro_pddp, dro_dro_2rev_pddp (issue 48's
    # spacecraft): test_costate.py
    for name, (tof_days, n) in EXPECTED.items():
        c = load_case(name)
        assert c.stages == n
        assert c.units.time_s(c.tof) / 86400 == pytest.approx(tof_days)
        assert c.x0.shape == (7,) and c.x0[6] == 1.0
        assert c.spacecraft == Spacecraft()


def test_paper_units():
    em = load_case("halo_l2_l1").units
    assert em.tu_s == pytest.approx(375189, abs=1)
    assert em.vu_km_s == pytest.approx(1.02455, abs=1e-5)
    assert em.gm == pytest.approx(1.21506e-2, rel=1e-5)
    sun = load_case("earth_mars").units
    assert sun.tu_s == pytest.approx(5022642.891, abs=1e-3)
    assert sun.vu_km_s == pytest.approx(29.78469183, abs=1e-7)
    # thrust: 0.5 N on 1000 kg is 5e-4 m/s^2
    acc_si = 0.5 / 1000.0
    acc_norm = float(sun.thrust(0.5)) / 1.0  # per unit mass
    assert acc_norm * sun.lu_km * 1000 / sun.tu_s ** 2 == pytest.approx(acc_si)
    leo = load_case("leo_leo")
    assert leo.x0[0] * leo.units.lu_km == pytest.approx(6778.0)    # p = a on a circular orbit
    assert np.degrees(2 * np.arctan(np.hypot(leo.x0[3], leo.x0[4]))) == pytest.approx(51.0)


def test_earth_cases_are_staged_in_true_longitude():
    """An Earth-centred case's stages are equal arcs of true longitude over its revolutions:
    by default the revolutions made in the time of flight at the mean of the initial and
    target mean motions (LEO: 5553 s and 6052 s periods over 35 days -> 522.1; the
    independent transcription's optimum has 521.2), or the case file's; the state carries the
    time, whose target is the time of flight."""
    from daddy_core.catalogue import problem_from_case
    leo = load_case("leo_leo")
    periods_s = 2 * np.pi * np.sqrt(np.array([6778.0, 7178.0]) ** 3 / 398_600.0)
    revs = 35 * 86400 / 2 / periods_s[0] + 35 * 86400 / 2 / periods_s[1]
    assert leo.revolutions == pytest.approx(revs, rel=1e-9) and leo.stages == round(revs * 10)
    assert leo.t_start == pytest.approx(np.radians(145.0))       # RAAN + argp + nu
    assert leo.x_target[5] == pytest.approx(35.0) and leo.x0[5] == 0.0   # days (TU = 1 day)
    prob = problem_from_case(leo, stages=100)
    assert prob.stage_dt.sum() == pytest.approx(2 * np.pi * revs)
    assert prob.stage_t0[0] == leo.t_start and prob.time_index == 5
    d = json.loads((load_case.__globals__["CASES_DIR"] / "leo_leo.json").read_text())
    d["revolutions"] = 519.2
    c = case_from_dict(d)
    assert c.revolutions == 519.2 and c.stages == 5192
    for field, value, msg in (("revolutions", -1, "revolutions"),
                              ("stages_per_revolution", 2, "stages_per_revolution")):
        with pytest.raises(DaddyError, match=msg):
            case_from_dict({**d, field: value})
    with pytest.raises(DaddyError, match="'stages': Earth-centred cases are staged in true"):
        case_from_dict({**d, "stages": 5000})


def test_perturbations_and_reach_of_earth_cases_are_checked():
    """``perturbations`` lists known forces and only on Earth-centred cases; a target out of
    reach in the time of flight is refused with Edelbaum's estimate before anything is built:
    the LEO transfer (1.058 km/s; 0.5 N at 2000 s make 0.884 km/s in 20 days) -- and one whose
    time of flight allows it (25 days) loads."""
    from daddy_core.catalogue.cases import Perturbation
    cases_dir = load_case.__globals__["CASES_DIR"]
    assert load_case("leo_leo_j2").perturbations == {Perturbation.J2}
    assert load_case("leo_leo").perturbations == frozenset()
    d = json.loads((cases_dir / "leo_leo.json").read_text())
    with pytest.raises(DaddyError, match="'perturbations' must be a list of"):
        case_from_dict({**d, "perturbations": ["j3"]})
    with pytest.raises(DaddyError, match="'perturbations' is for Earth-centred cases"):
        case_from_dict({**json.loads((cases_dir / "earth_mars.json").read_text()),
                        "perturbations": ["j2"]})
    with pytest.raises(DaddyError, match=r"cannot be reached in 20 days: Edelbaum's estimate of "
                                         r"the transfer is 1.058 km/s.* make 0.884 km/s"):
        case_from_dict({**d, "tof_days": 20})
    assert case_from_dict({**d, "tof_days": 25}).tof == pytest.approx(25.0)


def test_user_case_file(tmp_path):
    d = json.loads((load_case.__globals__["CASES_DIR"] / "dro_dro.json").read_text())
    d["name"] = "my_dro"
    d["stages"] = 20
    p = tmp_path / "my_dro.json"
    p.write_text(json.dumps(d))
    c = load_case(p)
    assert c.name == "my_dro" and c.stages == 20


@pytest.mark.parametrize("field,value,msg", [
    ("stages", 0, "stages"), ("tof_days", -1.0, "tof_days"), ("x0", [1, 2], "x0"),
    ("x_target", [float("nan")] * 6, "x_target"), ("system", "mars", "system"),
    ("spacecraft", {"dry_mass_kg": 2000.0}, "dry_mass_kg"),
])
def test_bad_case_fields_are_named(field, value, msg):
    d = json.loads((load_case.__globals__["CASES_DIR"] / "halo_l2_l1.json").read_text())
    d[field] = value
    with pytest.raises(DaddyError, match=msg):
        case_from_dict(d)


@pytest.mark.parametrize("element, value, msg", [
    (0, -7000.0, r"'x0\[0\]' \(a, km\) must be > 0"),
    (1, 1.0, r"'x0\[1\]' \(e\) must be in \[0, 1\)"),
    (2, 180.0, r"'x0\[2\]' \(i, deg\) must be in \[0, 180\): .* retrograde equatorial"),
    (2, -5.0, r"'x0\[2\]' \(i, deg\)"),
    (1, 0.2, "perigee radius .* inside the Earth"),
])
def test_bad_orbital_elements_are_named(element, value, msg):
    """Keplerian inputs of the Earth cases: each element checked before anything is built."""
    d = json.loads((load_case.__globals__["CASES_DIR"] / "leo_leo.json").read_text())
    d["x0"][element] = value
    with pytest.raises(DaddyError, match=msg):
        case_from_dict(d)


def test_unknown_case_lists_known():
    with pytest.raises(DaddyError, match="halo_l2_l1"):
        load_case("no_such_case")


def test_problem_settings_are_apart_from_solver_settings():
    # case files hold the problem's gains under "problem"; one left among the solver's settings
    # (the old layout) is named with where it belongs, not silently ignored
    d = json.loads((load_case.__globals__["CASES_DIR"] / "halo_l2_l1.json").read_text())
    c = case_from_dict(d)
    assert c.problem["terminal_cost_gain"] == 1e6 and "terminal_cost_gain" not in c.solver
    assert "tol_aul" in c.solver and "tol_aul" not in c.problem
    d["solver"]["stage_cost_gain"] = d["problem"].pop("stage_cost_gain")
    with pytest.raises(DaddyError, match="solver.stage_cost_gain' belongs in 'problem'"):
        case_from_dict(d)
    # a solver section holds the paper's per-case settings only: a solver option tuned for one
    # case (the old short_step / carry_rho) is named, not silently applied or ignored
    d = json.loads((load_case.__globals__["CASES_DIR"] / "halo_l2_l1.json").read_text())
    d["solver"]["short_step"] = 0.5
    with pytest.raises(DaddyError, match="solver.short_step' is not a case setting"):
        case_from_dict(d)


@pytest.mark.parametrize("where, key, msg", [
    ((), "r_min_km", r"'r_min_km' is unknown: .*problem_from_case\(case, r_min_km"),
    ((), "stagez", r"'stagez' is unknown \(known: name, .*stages,"),
    (("problem",), "tol_ddp", r"'problem.tol_ddp' is unknown: it belongs in the 'solver'"),
    (("problem",), "gain", r"'problem.gain' is unknown \(known: stage_cost_gain"),
    (("spacecraft",), "mass_kg", r"'spacecraft.mass_kg' is unknown \(known: wet_mass_kg"),
    (("solver", "homotopy"), "H", r"'solver.homotopy.H' is unknown \(known: h, delta\)"),
])
def test_an_unknown_key_anywhere_in_a_case_file_is_named_with_the_known_ones(where, key, msg):
    """A key the loader does not read is an error, never silently ignored (a top-level
    ``r_min_km`` once solved the problem without its keep-out and said nothing)."""
    d = json.loads((load_case.__globals__["CASES_DIR"] / "halo_l2_l1.json").read_text())
    section = d
    for name in where:
        section = section[name]
    section[key] = 1.0
    with pytest.raises(DaddyError, match=msg):
        case_from_dict(d)


@pytest.mark.parametrize("name", ["earth_mars", "halo_l2_l1", "leo_leo", "double_integrator"])
def test_states_convert_to_si_and_back_for_every_system(name):
    # one place for the state <-> SI conversion (Units), including the equinoctial elements,
    # checked against the unit definitions themselves
    c = load_case(name)
    u = c.units
    si = u.states_si(c.x0)
    np.testing.assert_allclose(u.states_normalised(si), c.x0, rtol=1e-15)
    if c.system == "earth_equinoctial":
        assert si[0] == pytest.approx(6778e3)                     # p [m] (paper Table 10 LEO)
        np.testing.assert_array_equal(si[1:5], c.x0[1:5])          # f, g, h, k unchanged
        t = u.states_si(c.x_target)[5]
        assert t == pytest.approx(35 * 86400.0)                    # time [s]
    else:
        assert si[0] == pytest.approx(c.x0[0] * u.lu_km * 1e3)
        assert si[3] == pytest.approx(c.x0[3] * u.lu_km * 1e3 / u.tu_s)
    if c.x0.size == 7:
        assert si[6] == pytest.approx(c.spacecraft.wet_mass_kg)
    batch = u.states_si(np.stack([c.x0, c.x0]))                    # (..., nx) arrays alike
    np.testing.assert_array_equal(batch[1], si)


def test_daddy_list_shows_each_case_with_its_measured_run_time(capsys):
    """`daddy list` names every case with its stage count and the run times measured by
    bench/bench_catalogue.py (catalogue/run_times.json: every case's energy-optimal solve, the
    fuel-optimal one where the case has a spacecraft), a fuel solve that did not converge
    within the bench's cap said as such, and the machine and date of the measurement."""
    from daddy_core.catalogue.run_times import expected_run_time, read_run_times
    from daddy_core.cli import main
    measured = read_run_times()
    assert set(measured["cases"]) == set(list_cases())
    for name, runs in measured["cases"].items():
        assert "energy" in runs and ("fuel" in runs) == (getattr(load_case(name), "spacecraft", None) is not None)
        for r in runs.values():
            text = expected_run_time(measured, name)
            assert (f"{r['cpu_s']:.3g} s" if r["converged"] else "not converged in") in text
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert all(line.split()[0] in measured["cases"] and "[expected: energy" in line
               for line in out.splitlines()[:-1])
    assert out.splitlines()[-1].startswith(f"(expected run times measured on {measured['machine']}")
