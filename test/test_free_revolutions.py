"""A free arrival angle for Earth-centred cases (issue 46, ``free_time.with_free_revolutions``):
the angle the true-longitude stages span is a static parameter, one solve. Checked against
fixed-angle solves of the same stage count -- feasible points of the free problem, so none may
beat its optimum -- on a short MEO transfer not in the catalogue; bad windows named."""
import json
import math

import numpy as np
import pytest

from daddy_core.catalogue import case_from_dict, load_case, problem_from_case
from daddy_core.catalogue.cases import CASES_DIR
from daddy_core.cli import main
from daddy_core.errors import DaddyError
from daddy_core.solver import case_options, solve


@pytest.fixture(scope="module")
def short_meo():
    """MEO, 3 days (4.09 revolutions, 65 stages), a 0.4 deg RAAN change."""
    d = json.loads((CASES_DIR / "meo_meo.json").read_text())
    d.update(name="meo_3_days", tof_days=3.0)
    d["x_target"][3] = 179.6
    return case_from_dict(d)


def _solve(case, problem, fuel):
    return solve(problem, case.cold_guess(problem.N), fuel_optimal=fuel,
                 options=case_options(case, fuel))


@pytest.mark.parametrize("fuel", [False, True])
def test_the_free_angle_beats_every_fixed_angle_of_the_same_stages(short_meo, fuel):
    case = short_meo
    r0 = case.revolutions
    free = _solve(case, problem_from_case(case, revolutions_window=[r0 - 0.3, r0 + 0.3]), fuel)
    assert free.converged and free.max_violation < 1e-8
    r = free.parameters["angle"] / (2 * math.pi)
    assert r0 - 0.3 < r < r0 + 0.3
    # the solution is in the user's view, its stages as flown spanning the free angle
    assert free.X.shape == (case.stages + 1, 7)
    assert np.sum(free.stage_dt) == pytest.approx(2 * math.pi * r, rel=1e-12)
    for revs in (r0, r - 0.01, r + 0.01):
        fixed = _solve(case, problem_from_case(case.with_revolutions(revs), stages=case.stages),
                       fuel)
        assert fixed.max_violation < 1e-8
        assert free.cost <= fixed.cost * (1 + 1e-6)
        if fuel:
            assert free.final_mass_kg >= fixed.final_mass_kg - 1e-4


def test_the_cli_prints_the_free_revolutions(tmp_path, capsys, short_meo):
    path = tmp_path / "meo.json"
    d = json.loads((CASES_DIR / "meo_meo.json").read_text())
    d.update(name="meo_3_days", tof_days=3.0)
    d["x_target"][3] = 179.6
    d["problem"] = {"revolutions_window": [3.9, 4.3]}
    path.write_text(json.dumps(d))
    assert main(["solve", str(path), "--energy", "--quiet"]) == 0
    line = next(s for s in capsys.readouterr().out.splitlines() if "revolutions (free)" in s)
    assert 3.9 < float(line.split()[-1]) < 4.3


@pytest.mark.parametrize("kwargs, field", [
    (dict(revolutions_window=[4.3, 3.9]), "revolutions_window"),
    (dict(revolutions_window=[3.9]), "revolutions_window"),
    (dict(revolutions_window=[3.9, 4.3], stages=40), "stages"),
    (dict(revolutions_window=[3.9, 4.3], tof_window=[2.0, 4.0]), "tof_window"),
])
def test_bad_angle_windows_are_named(short_meo, kwargs, field):
    with pytest.raises(DaddyError, match=field):
        problem_from_case(short_meo, **kwargs)


def test_a_free_angle_is_for_earth_centred_cases():
    with pytest.raises(DaddyError, match="Earth-centred"):
        problem_from_case(load_case("earth_mars"), revolutions_window=[1.0, 2.0])
