"""Mission-design outputs of a solution (issue 51): CCSDS OEMs for every system with a frame in
space, read back by an independent reader (the ``oem`` package); the CR3BP rotating-to-inertial
conversion against closed forms; the mission plot for each kind of system; ``daddy export``
of a saved solution."""
import re
from datetime import datetime, timezone

import numpy as np
import pytest

from daddy_core import trajectory_output as out
from daddy_core.catalogue import load_case, problem_from_case
from daddy_core.cli import main as cli_main
from daddy_core.errors import DaddyError
from daddy_core.mission_plot import kepler_orbit, switches, thrust_in_frame
from daddy_core.solver import case_options, solve

EPOCH = datetime(2027, 3, 1, 6, 30, tzinfo=timezone.utc)


def _energy_solution(name: str, **case_changes):
    case = load_case(name)
    problem = problem_from_case(case, **case_changes)
    sol = solve(problem, case.cold_guess(problem.N), fuel_optimal=False,
                options=case_options(case, False), case_name=case.name)
    assert sol.converged, sol.reason
    return case, sol


@pytest.fixture(scope="module")
def halo():
    return _energy_solution("halo_l2_l1")


@pytest.fixture(scope="module")
def earth_mars():
    return _energy_solution("earth_mars")


def _read_oem(path):
    """(metadata, (K,) seconds since START_TIME, (K, 6) states [km, km/s]) by the oem package."""
    oem = pytest.importorskip("oem", reason="the analysis extra (make test installs it)")
    from astropy.time import Time
    msg = oem.OrbitEphemerisMessage.open(str(path))
    assert msg.version == "2.0" and len(msg.segments) == 1
    meta = msg.segments[0].metadata
    states = list(msg.states)
    t0 = Time(str(meta["START_TIME"]).replace(" ", "T"), scale="utc")
    t = np.array([(s.epoch - t0).sec for s in states])
    rv = np.array([np.concatenate([s.position, s.velocity]) for s in states])
    return meta, t, rv


def test_a_cr3bp_oem_reads_back_in_the_rotating_and_the_inertial_frame(halo, tmp_path):
    case, sol = halo
    X = sol.X_si[:, :6] / 1000.0
    t = sol.times_s
    out.write_oem(sol, tmp_path / "rot.oem", EPOCH, frame=out.OemFrame.ROTATING)
    meta, t_read, rv = _read_oem(tmp_path / "rot.oem")
    assert meta["CENTER_NAME"] == "EARTH-MOON BARYCENTER" and meta["REF_FRAME"] == "EMB_ROTATING"
    np.testing.assert_allclose(t_read, t, atol=1e-5)
    np.testing.assert_allclose(rv, X, rtol=1e-11, atol=1e-12)

    out.write_oem(sol, tmp_path / "in.oem", EPOCH)
    meta, t_read, rv = _read_oem(tmp_path / "in.oem")
    assert meta["REF_FRAME"] == "EMB_INERTIAL"
    np.testing.assert_allclose(t_read, t, atol=1e-5)
    # a rotation about z through the barycentre: distances from it and z are the rotating
    # frame's; at the epoch the axes agree and the velocity gains n z x r
    np.testing.assert_allclose(np.linalg.norm(rv[:, :3], axis=1),
                               np.linalg.norm(X[:, :3], axis=1), rtol=1e-12)
    np.testing.assert_allclose(rv[:, 2], X[:, 2], rtol=1e-12, atol=1e-9)
    n = 1.0 / case.units.tu_s
    np.testing.assert_allclose(rv[0, :3], X[0, :3], rtol=1e-12)
    np.testing.assert_allclose(rv[0, 3:], X[0, 3:] + n * np.array([-X[0, 1], X[0, 0], 0.0]),
                               rtol=1e-11, atol=1e-12)


def test_rotating_to_inertial_is_the_closed_form_rotation():
    """The Moon, at rest in the rotating frame, moves on a circle in the inertial one: half a
    period later at -r, always at speed n r; along a moving rotating-frame path the inertial
    velocity is the derivative of the inertial position (central differences)."""
    tu = 375_190.0
    n, r = 1.0 / tu, 384_399e3
    t = np.array([0.0, 0.5 * np.pi * tu, np.pi * tu])
    moon = np.tile([r, 0, 0, 0, 0, 0], (3, 1))
    y = out.rotating_to_inertial_si(moon, t, tu)
    np.testing.assert_allclose(y[:, :3], [[r, 0, 0], [0, r, 0], [-r, 0, 0]], atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(y[:, 3:], axis=1), n * r, rtol=1e-14)

    def path(s):   # a rotating-frame trajectory and its velocity
        return np.column_stack([1e8 + 3e7 * np.sin(s / 1e5), 2e7 * np.cos(s / 2e5), 1e6 * s / 1e5,
                                3e2 * np.cos(s / 1e5), -1e2 * np.sin(s / 2e5),
                                10.0 + 0 * s])
    s = np.linspace(0.0, 2e6, 7)
    h = 1.0
    y = out.rotating_to_inertial_si(path(s), s, tu)
    fd = (out.rotating_to_inertial_si(path(s + h), s + h, tu)[:, :3]
          - out.rotating_to_inertial_si(path(s - h), s - h, tu)[:, :3]) / (2 * h)
    np.testing.assert_allclose(y[:, 3:], fd, rtol=1e-6, atol=1e-4)


def test_a_sun_centred_oem_reads_back(earth_mars, tmp_path):
    case, sol = earth_mars
    out.write_oem(sol, tmp_path / "em.oem", EPOCH)
    meta, t, rv = _read_oem(tmp_path / "em.oem")
    assert (meta["CENTER_NAME"], meta["REF_FRAME"]) == ("SUN", "ECLIPJ2000")
    np.testing.assert_allclose(t, sol.times_s, atol=1e-5)
    np.testing.assert_allclose(rv, sol.X_si[:, :6] / 1000.0, rtol=1e-11)
    # the arrival is the case's target state
    np.testing.assert_allclose(rv[-1], case.units.cartesian_si(case.x_target)[:6] / 1000.0,
                               rtol=1e-6, atol=1e-6)


def test_an_earth_centred_oem_reads_back(tmp_path):
    """A short LEO raise (1 day; energy-optimal), its OEM in EME2000 against the solution's
    Cartesian states from its elements."""
    import json

    from daddy_core.catalogue.cases import CASES_DIR, case_from_dict
    d = json.loads((CASES_DIR / "leo_leo.json").read_text())
    d.update(name="leo_raise", tof_days=1.0, x_target=[6788.0, 0, 51.0, 145.0, 0, 0])
    case = case_from_dict(d)
    problem = problem_from_case(case)
    sol = solve(problem, np.full((problem.N, 3), float(case.units.thrust(1e-6))),
                fuel_optimal=False, options=case_options(case, False), case_name="leo_raise")
    assert sol.converged, sol.reason
    out.write_oem(sol, tmp_path / "leo.oem", EPOCH)
    meta, t, rv = _read_oem(tmp_path / "leo.oem")
    assert (meta["CENTER_NAME"], meta["REF_FRAME"]) == ("EARTH", "EME2000")
    np.testing.assert_allclose(t, sol.times_s, atol=1e-5)
    np.testing.assert_allclose(rv, sol.X_si[:, :6] / 1000.0, rtol=1e-11, atol=1e-9)
    # Earth-centred thrust (RTN) turned to EME2000 keeps its magnitude and its radial part
    u = thrust_in_frame(sol)
    np.testing.assert_allclose(np.linalg.norm(u, axis=1), np.linalg.norm(sol.thrust_n, axis=1),
                               rtol=1e-12, atol=1e-15)
    r = sol.X_si[:-1, :3]
    np.testing.assert_allclose(np.sum(u * r, axis=1) / np.linalg.norm(r, axis=1),
                               sol.thrust_n[:, 0], rtol=1e-9, atol=1e-12)


def test_systems_without_a_frame_have_no_oem(tmp_path):
    with pytest.raises(DaddyError, match="needs a frame in space"):
        out.check_oem("double_integrator", out.OemFrame.INERTIAL, "di")
    with pytest.raises(DaddyError, match="rotating frame"):
        out.check_oem("earth_equinoctial", out.OemFrame.ROTATING, "leo")


def test_kepler_orbit_passes_through_its_state_and_switches_count_changes():
    state = np.array([1.4e8, -5e7, 1e3, 9.7, 28.0, 0.0004])
    gm = 1.32712440041e11
    o = kepler_orbit(state, gm, n=20001)
    assert np.min(np.linalg.norm(o - state[:3], axis=1)) < 1e-4 * np.linalg.norm(state[:3])
    h = np.cross(state[:3], state[3:])
    assert np.max(np.abs(o @ h)) / (np.linalg.norm(h) * np.linalg.norm(state[:3])) < 1e-12
    assert switches(np.array([1, 1, 0, 0, 1, 0], bool)) == 3
    assert switches(np.zeros(5, bool)) == 0


def _is_png(path, min_bytes):
    data = path.read_bytes()
    return data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > min_bytes


def test_daddy_export_writes_the_files_of_a_saved_solution(halo, earth_mars, tmp_path, capsys):
    """The mission plot of a CR3BP and a Sun-centred solution, and the CSV and OEM, from the
    JSON ``daddy solve --json`` writes; the CSV's states are the solution's."""
    pytest.importorskip("matplotlib")
    for name, (case, sol) in (("halo", halo), ("em", earth_mars)):
        sol.to_json(tmp_path / f"{name}.json")
        assert cli_main(["export", str(tmp_path / f"{name}.json"), "--plot",
                         str(tmp_path / f"{name}.png"), "--csv", str(tmp_path / f"{name}.csv"),
                         "--oem", str(tmp_path / f"{name}.oem"), "--epoch",
                         "2027-03-01T06:30:00"]) == 0, capsys.readouterr().err
        assert _is_png(tmp_path / f"{name}.png", 60_000)
        rows = np.genfromtxt(tmp_path / f"{name}.csv", delimiter=",", skip_header=1)
        np.testing.assert_allclose(rows[:, 2:9], sol.X_si, rtol=1e-15)
        text = (tmp_path / f"{name}.oem").read_text()
        assert len(re.findall(r"^\d{4}-\d\d-\d\dT", text, re.M)) == sol.N + 1
        assert "START_TIME = 2027-03-01T06:30:00.000000" in text
    assert cli_main(["export", str(tmp_path / "halo.json")]) == 2
    assert "give --csv, --oem or --plot" in capsys.readouterr().err
    assert cli_main(["export", str(tmp_path / "nothing.json"), "--csv", "x.csv"]) == 2
