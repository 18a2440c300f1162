"""Multi-phase cases as data (issue 46, ``catalogue/phased_cases.py``): the bundled
``two_phase_lq`` case file against the issue's values, through ``daddy solve`` with its JSON and
CSV read back, a velocity jump written in a user's case file, and bad phases named by field."""
import copy
import json

import numpy as np
import pytest

from daddy_core.catalogue import case_from_dict, load_case, load_thrust_case, problem_from_case
from daddy_core.catalogue.cases import CASES_DIR
from daddy_core.cli import main
from daddy_core.errors import DaddyError
from daddy_core.solver import Solution, case_options, solve

OMEGA_2 = [39 / 11, 85 / 33, 163 / 33, -1 / 11, -5 / 33, 4 / 33]        # the issue's omega_2*
# Table 1's junction costate (printed to 6 digits), lambda_1 its negative under psi_1 as written
LAMBDA_1 = -np.array([0.0545455, 0.224242, -0.139394, 0.327273, 0.0121212, 0.630303])


def _case_dict():
    return json.loads((CASES_DIR / "two_phase_lq.json").read_text())


def test_the_two_phase_case_file_solves_to_the_issues_values(tmp_path, capsys):
    out, csv = tmp_path / "lq.json", tmp_path / "lq.csv"
    assert main(["solve", "two_phase_lq", "--quiet", "--json", str(out), "--csv", str(csv)]) == 0
    assert "phase two: stages 5-9; parameters two.x0 3.545454" in capsys.readouterr().out
    sol = Solution.from_json(out)
    assert sol.cost == pytest.approx(2.9742424242, abs=1e-8)
    one, two = sol.phases
    np.testing.assert_allclose(list(two["parameters"].values()), OMEGA_2, atol=1e-7)
    np.testing.assert_allclose(one["link_multipliers"], LAMBDA_1, atol=5e-6)
    assert two["link_multipliers"] is None
    # each phase from its own start: phase one from x0, phase two from omega_2; the link holds
    np.testing.assert_allclose(one["X"][0], np.ones(6))
    np.testing.assert_allclose(two["X"][0], OMEGA_2, atol=1e-7)
    np.testing.assert_allclose(two["X"][0], one["X"][-1], atol=1e-7)
    np.testing.assert_allclose(two["X"][-1], [2.0, 4.0, 1.0, -0.5, 1.5, -2.5], atol=1e-7)
    k = np.arange(10)
    u = np.vstack([one["U"], two["U"]])
    np.testing.assert_allclose(u, np.column_stack(
        [-3 / 11 + 3 / 110 * k, -5 / 11 + 37 / 330 * k, -2 / 55 - 23 / 330 * k]), atol=1e-7)
    rows = np.genfromtxt(csv, delimiter=",", names=True)
    assert rows.dtype.names[:2] == ("phase", "k") and rows.shape == (12,)
    second = rows[rows["phase"] == 1]
    np.testing.assert_allclose([second[0][f"x{i}"] for i in range(6)], OMEGA_2, atol=1e-7)


def test_a_velocity_jump_in_a_users_case_file_lands_on_the_target():
    """The link's jump adds an impulse between the phases: the next phase starts at the
    previous end plus the jump, and the target is still met."""
    d = _case_dict()
    d["phases"][0]["link"] = {"jump": [0, 0, 0, 0.3, -0.2, 0.1]}
    d["phases"][1]["stages"] = 3
    case = case_from_dict(d)
    problem = problem_from_case(case)
    sol = solve(problem, case.cold_guess(problem.N), fuel_optimal=False,
                options=case_options(case, False))
    assert sol.converged and sol.max_violation < 1e-8
    one, two = sol.phases
    np.testing.assert_allclose(np.subtract(two["X"][0], one["X"][-1]),
                               [0, 0, 0, 0.3, -0.2, 0.1], atol=1e-7)
    np.testing.assert_allclose(two["X"][-1], case.x_target, atol=1e-7)
    assert len(two["U"]) == 3


@pytest.mark.parametrize("change, field", [
    (lambda d: d.update(system="sun_two_body"), "'phases' is built for the double_integrator"),
    (lambda d: d["phases"][1].pop("start"), "phases[0].link"),
    (lambda d: d["phases"][1]["start"].pop("lower"), "phases[1].start.lower"),
    (lambda d: d["phases"][1].update(thrust=1), "phases[1].thrust"),
    (lambda d: d["phases"][0].update(start={"lower": 0, "upper": 1}), "phases[0].start"),
    (lambda d: d["phases"][1].update(link={"jump": 0}), "phases[1].link"),
    (lambda d: d["phases"][1].update(stages=0), "phases[1].stages"),
    (lambda d: d["phases"][0]["link"].update(jump=[1, 2]), "phases[0].link.jump"),
    (lambda d: d["phases"][1]["start"].update(guess=99), "phases[1].start.guess"),
    (lambda d: d.update(stages=10), "'stages'"),
    (lambda d: d["problem"].update(terminal="velocity"), "problem.terminal"),
])
def test_bad_phases_are_refused_by_field(change, field):
    d = copy.deepcopy(_case_dict())
    change(d)
    with pytest.raises(DaddyError, match=field.replace("[", r"\[").replace("]", r"\]")):
        case_from_dict(d)


def test_phased_cases_go_to_the_solver_not_the_guidance_node():
    with pytest.raises(DaddyError, match="has phases"):
        load_thrust_case("two_phase_lq")
    with pytest.raises(DaddyError, match="tof_window"):
        problem_from_case(load_case("two_phase_lq"), tof_window=[5.0, 20.0])
