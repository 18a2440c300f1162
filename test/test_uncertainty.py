"""Uncertainty propagation on DA (issue 47, ``daddy_core/uncertainty.py``): closed-form
Gaussian moments of polynomials against their exact values, and on the planar orbit raise the
terminal polynomial (open loop, and closed by the feedback laws) against a Monte Carlo of the
same nonlinear flight: the polynomial at each sample, the mean and the covariance; the laws
shrink the terminal rows' dispersion."""
import numpy as np
import pytest

from daddy_core.da.core import DA, variables
from daddy_core.da.maps import evaluate
from daddy_core.errors import DaddyError
from daddy_core.policy import feedback_policy
from daddy_core.solver import solve
from daddy_core.uncertainty import gaussian_moments, terminal_polynomial
from test_policy import TIGHT, _on_circle, _orbit_raise

SIGMA = 1e-4       # initial position and velocity error, each component (normalised units)
SAMPLES = 4000


def test_gaussian_moments_of_polynomials_are_exact():
    """1-D: p = a + b x + c x^2 + d x^3 with x ~ N(0, s^2): mean a + c s^2, variance
    b^2 s^2 + 6 b d s^4 + 2 c^2 s^4 + 15 d^2 s^6. 2-D: the covariance of (x + y, x y)."""
    a, b, c, d, s = 0.3, -1.2, 0.7, 2.0, 0.4
    x = variables([0.0], order=3)[0]
    mean, cov = gaussian_moments(DA((a + b * x + c * x * x + d * x * x * x).c[:, None],
                                    x.T), np.array([[s * s]]))
    assert mean[0] == pytest.approx(a + c * s ** 2, rel=1e-14)
    assert cov[0, 0] == pytest.approx(b * b * s ** 2 + 6 * b * d * s ** 4 + 2 * c * c * s ** 4
                                      + 15 * d * d * s ** 6, rel=1e-13)
    v = variables([0.0, 0.0], order=2)
    P = np.array([[0.5, 0.2], [0.2, 0.3]])
    mean, cov = gaussian_moments(DA(np.stack([(v[0] + v[1]).c, (v[0] * v[1]).c], axis=1), v.T),
                                 P)
    # E[xy] = P01; var(x+y) = P00 + P11 + 2 P01; var(xy) = P00 P11 + P01^2; cov(x+y, xy) = 0
    np.testing.assert_allclose(mean, [0.0, 0.2], atol=1e-15)
    np.testing.assert_allclose(cov, [[0.5 + 0.3 + 0.4, 0.0], [0.0, 0.15 + 0.04]], atol=1e-15)
    with pytest.raises(DaddyError, match="covariance"):
        gaussian_moments(DA(np.stack([(v[0] + v[1]).c], axis=1), v.T), np.ones((3, 3)))


@pytest.fixture(scope="module")
def flight():
    problem = _orbit_raise([1.0, 0.0, 0.0, 1.0])
    sol = solve(problem, np.full((40, 2), 1e-3), options=TIGHT)
    rng = np.random.default_rng(47)
    dx0 = rng.normal(scale=SIGMA, size=(4, SAMPLES))
    return problem, sol, feedback_policy(problem, sol, order=2), dx0


def _monte_carlo(problem, sol, policy, dx0):
    """The nonlinear flight of every sample (nx, S): the controls of the plan, or the laws'."""
    S = dx0.shape[1]
    x = sol.X[0][:, None] + dx0
    for k in range(problem.N):
        u = (policy.control(k, x) if policy is not None and policy.has_law[k]
             else np.repeat(sol.U[k][:, None], S, axis=1))
        x = problem.step(x, u, np.repeat(problem.stage_dt[k], S),
                         np.repeat(problem.stage_t0[k], S))
    return x


@pytest.mark.parametrize("closed", [False, True])
def test_the_terminal_polynomial_matches_a_monte_carlo_of_the_flight(flight, closed):
    problem, sol, policy, dx0 = flight
    law = policy if closed else None
    poly = terminal_polynomial(problem, sol.X, sol.U, law, order=3)
    x = _monte_carlo(problem, sol, law, dx0)
    miss = x - sol.X[-1][:, None]
    at_samples = evaluate(DA(poly.c[:, :, None], poly.T), dx0)
    # the polynomial is the flight to its truncation: 1e-5 of the dispersion, or better
    assert np.abs(at_samples - miss).max() < 1e-5 * np.abs(miss).max()
    mean, cov = gaussian_moments(poly, np.eye(4) * SIGMA ** 2)
    se = miss.std(axis=1) / np.sqrt(SAMPLES)
    assert np.all(np.abs(mean - miss.mean(axis=1)) < 4 * se)
    # the sample standard deviations' relative standard error is sqrt(1 / (2 S)) = 1.1 %
    np.testing.assert_allclose(np.sqrt(np.diag(cov)), miss.std(axis=1), rtol=0.05)


def test_the_feedback_laws_shrink_the_terminal_rows_dispersion(flight):
    problem, sol, policy, dx0 = flight
    open_rows = np.asarray(_on_circle(_monte_carlo(problem, sol, None, dx0), None))
    closed_rows = np.asarray(_on_circle(_monte_carlo(problem, sol, policy, dx0), None))
    assert np.all(closed_rows.std(axis=1) * 10 < open_rows.std(axis=1))


def test_the_policies_page_examples_run_together(capsys):
    """docs/policies.md: the feedback-law example, then the uncertainty one continuing it (the
    page's later, self-contained examples run in test_readme)."""
    import pathlib
    import re
    text = (pathlib.Path(__file__).parents[1] / "docs" / "policies.md").read_text()
    blocks = re.findall(r"```(?:python|py)\n(.*?)```", text, re.S)
    assert len(blocks) >= 2 and "terminal_polynomial" in blocks[1]
    exec(compile("\n".join(blocks[:2]), "docs/policies.md", "exec"), {"__name__": "docs"})
    assert len(capsys.readouterr().out.strip().splitlines()) >= 2


def test_daddy_predict_puts_the_prediction_beside_its_monte_carlo():
    """The halo transfer, 10 km / 1 cm/s initial errors: the prediction's standard deviations
    within 5 % of 2,000 sampled flights' (the sampled standard error is 1.6 %); flying the
    laws shrinks the terminal position spread at least 50x (measured 200x); a case whose
    state is not Cartesian is refused by name."""
    from daddy_core.catalogue import load_case
    from daddy_core.cli import main
    from daddy_core.prediction import predict_case
    case = load_case("halo_l2_l1")
    laws = predict_case(case, True, 1, 10.0, 0.01, 2000)
    np.testing.assert_allclose(laws["predicted_std"], laws["sampled_std"], rtol=0.05)
    open_loop = predict_case(case, True, 0, 10.0, 0.01, 200)
    assert max(laws["predicted_std"][:3]) * 50 < min(open_loop["predicted_std"][:2])
    assert main(["predict", "leo_leo"]) == 2
    assert main(["predict", "halo_l2_l1", "--sigma-km", "-1"]) == 2
