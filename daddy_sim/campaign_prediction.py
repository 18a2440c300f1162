"""A campaign's terminal dispersion predicted from the closed loop's first-order maps (issue 47),
beside the campaign's Monte Carlo: the guidance node's loop linearised about the nominal plan
(the DA engine giving every flow's map), sampled as matrix products instead of flights.

The model flies the campaign's own estimate grid (``closed_loop.flight_steps``) with its
errors (``campaigns.CampaignConfig``): the initial-state dispersion, a navigation error nu on
every estimate the loop corrects from, an execution error w on every flown piece (magnitude and
pointing, as ``sim.TruthSim.apply`` draws them). The state deviation e (7: r, v, m) from the
nominal and the thrust correction c (3) in force evolve as

    piece [a, b] of stage k:  e <- Phi_x e + Phi_u (c + w),  w = S(U_k) z, z ~ N(0, I)
    stage boundary k (laws):  c <- K_k (e + nu)              (the node's tracking law, order 1)
    arrival estimate:         c <- the re-plan's corrections of its stages (below)

A re-plan of the arrival phase (``daddy_ros.shift``) starts from the plan in force and targets
the velocity exactly and the position at its aim point: where the plan in force arrives from
the estimate, brought onto the tolerance's sphere (the radial projection) when farther than
``arrival_tolerance_m``. To first order it is the least change to the corrections in force,
on the node's own stages (the plan in force's, split into ``shift.MIN_STAGES_LEFT``) and
weighted like the laws' (``policy.correction_scale``), that moves the terminal state
predicted from the estimate e + nu with those corrections onto that aim. Every stage's thrust
stays within the rating (a convex programme per draw, ``thrust_balls``), climbing the
node's thrust-margin ladder from the rung the plan in force keeps to; a draw whose rows a
rung cannot meet gets the node's best effort there: its rows as near as they come together,
weighted as the node's arrival rows weigh them (``shift.arrival_weight``), and the node's
rules decide which rung's is flown, if any (``_Targeting._ladder``). The
projection and the rating are why the terminal dispersion is not a Gaussian of the errors
and is sampled (``samples`` draws of every error), not propagated as a covariance. Drift
re-plans are not modelled: to first order a re-plan and the next law null the same predicted
error (but in the node they leave the arrival phase starting on a higher rung of the ladder:
docs/policies.md). A stage without a law re-plans like an arrival estimate.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from daddy_core.da.core import variables
from daddy_core.integrators import rk78
from daddy_core.policy import correction_scale, tracking_policy

from daddy_ros.replan_policy import LADDER_MIN_GAIN, lowest_rung
from daddy_ros.shift import MIN_STAGES_LEFT, arrival_weight, split_stages
from .campaigns import CampaignConfig
from .closed_loop import flight_steps, nominal_planner
from .sim import T0_S
from .thrust_balls import NU, ThrustBalls

NX = 7


@dataclass(frozen=True)
class Prediction:
    """The terminal deviation from the target, position [m] and velocity [m/s], as ``samples``
    draws of the linearised closed loop (samples, 6); its mean (6,) and covariance (6, 6); the
    CPU the prediction took [s]."""

    deviations_si: np.ndarray
    cpu_s: float

    @property
    def mean_si(self) -> np.ndarray:
        return self.deviations_si.mean(axis=0)

    @property
    def cov_si(self) -> np.ndarray:
        return np.cov(self.deviations_si, rowvar=False)


class _Flight:
    """The nominal plan's flow on the mission clock (s from T0): states, thrust and first-order
    maps of any interval, in normalised units."""

    def __init__(self, planner):
        plan = planner.plan
        self.case, self.units = planner.case, planner.units
        self.sol = plan.solution
        self.starts = plan.start_times_s - T0_S
        self.end = float(plan.end_s - T0_S)
        self.rhs = self.case.cartesian_rhs()
        # (rungs,) the thrust-margin ladder's ratings, lowest first (normalised)
        self.ratings = np.array([float(p.u_max) for p in planner.rated_problems])
        self.problem = planner.base_problem.with_x0(self.sol.X[0], self.sol.stage_dt,
                                                    self.sol.t_start)

    def stage(self, t: float) -> int:
        return int(np.clip(np.searchsorted(self.starts, t + 1e-6, side="right") - 1, 0,
                           len(self.starts) - 1))

    def maps(self, a: float, b: float) -> tuple[np.ndarray, np.ndarray]:
        """(Phi_x (7, 7), Phi_u (7, 3)) of the nominal flow over [a, b] inside one stage."""
        k = self.stage(a)
        x0 = self.state(a)
        x = variables(x0, order=1, n=NX + NU)
        u = variables(self.sol.U[k], order=1, n=NX + NU, first=NX)
        dt = float(self.units.time(b - a))
        J = rk78(self.rhs, x, u, 0.0, dt, tol=1e-12).linear()
        return J[:, :NX], J[:, NX:]

    def state(self, t: float) -> np.ndarray:
        """The nominal state at t (normalised)."""
        k = self.stage(t)
        dt = float(self.units.time(t - self.starts[k]))
        x = self.sol.X[k]
        return x if dt <= 0 else rk78(self.rhs, x, self.sol.U[k], 0.0, dt, tol=1e-12)

    def pieces(self, a: float, b: float, also=()) -> list[tuple[float, float]]:
        """[a, b] cut at the nominal stage starts (and the times ``also``)."""
        inner = np.union1d(self.starts, np.asarray(also, float))
        cuts = [a, *inner[(inner > a + 1e-6) & (inner < b - 1e-6)], b]
        return list(zip(cuts[:-1], cuts[1:]))


def predict(config: CampaignConfig, samples: int = 20_000, seed: int = 0,
            initial_si: np.ndarray | None = None) -> Prediction:
    """The campaign's terminal deviation, sampled on its linearised closed loop (module
    docstring). ``initial_si``: (samples, 6) initial-state deviations [m, m/s] to fly instead
    of draws from the campaign's ``initial_state`` dispersion."""
    cpu = time.process_time()
    g = config.guidance
    planner, _ = nominal_planner(config.case, g.time_budget_s, g.arrival_tolerance_m)
    flight = _Flight(planner)
    units, sol = flight.units, flight.sol
    N = len(sol.U)
    laws = tracking_policy(flight.problem, sol.X, sol.U, 1) if g.feedback_order else None
    scale = _si_scale(units)
    rng = np.random.default_rng(seed)
    nav = np.r_[[config.navigation.position_m] * 3, [config.navigation.velocity_m_s] * 3,
                0.0] / scale
    ini = np.r_[[config.initial_state.position_m] * 3, [config.initial_state.velocity_m_s] * 3,
                0.0] / scale
    e = rng.normal(size=(samples, NX)) * ini                       # (S, 7) truth - nominal
    if initial_si is not None:
        initial_si = np.asarray(initial_si, float)
        e = np.zeros((len(initial_si), NX))
        e[:, :6] = initial_si / scale[:6]
        samples = len(e)
    # the corrections in force: stage ends on the clock (J + 1,) and each stage's (S, J, 3)
    ends, c = np.array([0.0, flight.end]), np.zeros((samples, 1, NU))
    radius = float(units.length(g.arrival_tolerance_m)) if g.arrival_tolerance_m else 0.0
    dt_stage = flight.end / N
    last_law = N - max(g.arrival_stages, 0) - 1
    for t0, t1 in flight_steps(0.0, N, dt_stage, config.simulation.substeps, g.arrival_stages,
                               config.simulation.final_substeps or config.simulation.substeps,
                               g.arrival_min_step):
        action = _correction(flight, laws, g, t0, dt_stage, last_law)
        if action is not None:
            seen = e + rng.normal(size=(samples, NX)) * nav         # the estimate's deviation
            ends, c = action(seen, radius, ends, c)
        for a, b in flight.pieces(t0, t1, ends):
            Fx, Fu = flight.maps(a, b)
            now = _in_force(ends, c, [a + 1e-6])[:, 0]
            w = rng.normal(size=(samples, NU)) @ _execution(sol.U[flight.stage(a)], config).T
            e = e @ Fx.T + (now + w) @ Fu.T
    return Prediction(e[:, :6] * scale[:6], time.process_time() - cpu)


def _correction(flight: _Flight, laws, g, t: float, dt_stage: float, last_law: int):
    """The correction made from the estimate at t, as a function (seen deviations (S, 7),
    tolerance radius) -> c (S, 3), or None: a law at a stage boundary before the arrival phase,
    the re-plan's targeting in it."""
    if not g.self_replan:
        return None                             # the nominal flown open loop
    remaining = (flight.end - t) / dt_stage                        # in nominal stages
    eps = 1e-6
    if g.arrival_stages and remaining <= g.arrival_stages + eps and \
            remaining > g.arrival_min_step + eps:
        return _replan(flight, t)
    k = int(round(t / dt_stage))
    if laws is None or abs(t - k * dt_stage) > 1e-6 * dt_stage or not 0 < k <= last_law \
            or (g.replan_every_stages and k % g.replan_every_stages):
        return None
    if not laws.has_law[k]:
        return _replan(flight, t)               # no law: a re-plan
    K = laws.coefficients[k, 1:, :]             # (7, 3): c = seen @ K, for stage k
    span = np.array([t, t + dt_stage])
    return lambda seen, radius, ends, c: (span, (seen @ K)[:, None, :])


def _replan(flight: _Flight, t: float):
    """A re-plan from t, as the action (seen deviations (S, 7), tolerance radius, the
    corrections in force (ends, c)) -> (edges, c): the plan in force's stages from t (a
    re-plan's own, else the nominal's), split like the node's (``shift.split_stages``), each
    new stage starting from the correction its part of the plan flies."""
    def action(seen: np.ndarray, radius: float, ends: np.ndarray, c: np.ndarray):
        edges = _replan_stages(flight, t, ends)
        held = _in_force(ends, c, 0.5 * (edges[:-1] + edges[1:]))   # at the stages' midpoints
        return edges, _Targeting(flight, edges)(seen, radius, held)
    return action


def _in_force(ends: np.ndarray, c: np.ndarray, times) -> np.ndarray:
    """(S, len(times), 3) the corrections in force (stage ends (J + 1,), c (S, J, 3)) at the
    times on the clock; zero outside their stages."""
    j = np.searchsorted(ends, np.asarray(times, float), side="right") - 1
    inside = (j >= 0) & (j < c.shape[1])
    return np.where(inside[None, :, None], c[:, np.clip(j, 0, c.shape[1] - 1)], 0.0)


def _replan_stages(flight: _Flight, t: float, ends: np.ndarray) -> np.ndarray:
    """(stages + 1,) the edges of a re-plan's stages from t: the remaining stages of the plan
    in force -- a re-plan's, whose corrections span its stages to the end (more than one),
    or the nominal's (a law's correction spans one nominal stage) --, the longest halved until
    there are ``shift.MIN_STAGES_LEFT``, as the node's arrival phase flies them."""
    replanned = len(ends) > 2 and abs(ends[-1] - flight.end) <= 1e-6
    bounds = np.asarray(ends[1:] if replanned else [*flight.starts[1:], flight.end], float)
    bounds = bounds[bounds > t + 1e-6]
    dts, _ = split_stages(np.diff(np.r_[t, bounds]), MIN_STAGES_LEFT)
    return t + np.r_[0.0, np.cumsum(dts)]


class _Targeting:
    """A re-plan's first-order correction over the stages ``edges`` (module docstring): the
    thrust change of each stage for a seen deviation."""

    def __init__(self, flight: _Flight, edges: np.ndarray):
        self.edges = edges = np.asarray(edges, float)
        blocks = [flight.pieces(a, b) for a, b in zip(edges[:-1], edges[1:])]
        to_end = np.eye(NX)                            # Phi from the end of a piece to t_f
        sens = []                                      # each stage's d x_f / d c
        for stage in reversed(blocks):
            M = np.zeros((NX, NU))
            for a, b in reversed(stage):
                Fx, Fu = flight.maps(a, b)
                M += to_end @ Fu
                to_end = to_end @ Fx
            sens.append(M)
        U = flight.sol.U[[flight.stage(a) for a in edges[:-1]]]        # (stages, 3)
        self.scale = np.repeat(correction_scale(flight.problem, U), NU)  # of each column
        M = np.hstack(sens[::-1]) * self.scale         # (7, 3 * stages), scaled controls
        self.phi, self.M = to_end[:6], M[:6]
        self.thrust = U.ravel()
        self.balls = ThrustBalls(self.thrust, self.scale)
        self.ratings = flight.ratings
        self.rating = float(self.ratings[-1])
        self.units = flight.units

    def __call__(self, seen: np.ndarray, radius: float, held: np.ndarray) -> np.ndarray:
        """(S, stages, 3) the corrections from the seen deviations (S, 7) and the corrections
        the plan in force flies on each stage (S, stages, 3)."""
        kept = held.reshape(len(seen), -1) / self.scale    # (S, 3 * stages) scaled
        # (S, 6) the terminal deviation flying the plan in force
        predicted = seen @ self.phi.T + kept @ self.M.T
        goal = np.zeros_like(predicted)               # the velocity nulled, the position kept
        r = np.linalg.norm(predicted[:, :3], axis=1, keepdims=True)   # ... brought onto the
        goal[:, :3] = predicted[:, :3] * np.minimum(1.0, radius / np.maximum(r, 1e-300))  # ball
        rows = goal - predicted
        return self._clipped(kept + self._ladder(rows, kept, self._weights(radius)))

    def _ladder(self, rows: np.ndarray, kept: np.ndarray, w: np.ndarray) -> np.ndarray:
        """(S, 3 * stages) the change to the corrections kept (S, 3 * stages) of a re-plan
        whose terminal rows (S, 6) are weighted by w (6,), as the node's re-plan makes it
        (``GuidancePlanner._climb`` and ``_adopt``): the least change within the rating of the
        first rung of the margin ladder, from the one the plan in force keeps to, that meets
        the rows; out of reach, each rung's best effort, a higher rung's kept where it misses
        less and the climb stopped where it missed more than ``LADDER_MIN_GAIN`` of the one
        below; that best effort replaces the corrections in force only where it misses less
        than they do (the largest weighted row), else they are kept.

        A draw's best effort on the rung it starts from cannot stop its climb (there is none
        below to compare), so it is made only once the next rung is out of reach too: a draw
        still short past its first rung with no best effort yet gets the rung below's first.
        Most draws a rung cannot serve, the next one can."""
        S = len(kept)
        change, fits, stopped = np.zeros_like(kept), np.zeros(S, bool), np.zeros(S, bool)
        best, miss = np.zeros_like(kept), np.full(S, np.inf)   # the best effort so far
        rung, top = self._rung(kept), len(self.ratings) - 1
        for k, rating in enumerate(self.ratings):
            todo = np.flatnonzero(~fits & ~stopped & (rung <= k))
            step, met = self.balls.least_change(self.M, rows[todo], kept[todo], rating)
            change[todo[met]] = step[met]
            fits[todo[met]] = True
            short = todo[~met]
            late = short[(rung[short] < k) & np.isinf(miss[short])]
            best[late], miss[late] = self._best_effort(rows[late], kept[late],
                                                       float(self.ratings[k - 1]), w)
            short = short[~(np.isinf(miss[short]) & (k < top))]   # (their first rung: later)
            d, m = self._best_effort(rows[short], kept[short], rating, w)
            better = m < miss[short]
            stopped[short] = better & (m > LADDER_MIN_GAIN * miss[short])
            best[short[better]], miss[short[better]] = d[better], m[better]
        out = np.flatnonzero(~fits)
        adopt = out[miss[out] < np.max(np.abs(rows[out] * w), axis=1)]
        change[adopt] = best[adopt]
        return change

    def _rung(self, kept: np.ndarray) -> np.ndarray:
        """(S,) the lowest rung of the margin ladder whose rating the plan in force (the
        corrections kept, (S, 3 * stages)) keeps to, as ``GuidancePlanner._rung_for``."""
        peak = np.linalg.norm(self.balls.thrust_of(kept), axis=2).max(axis=1, initial=0.0)
        return lowest_rung(peak, self.ratings)

    def _weights(self, radius: float) -> np.ndarray:
        """(6,) the weights of the terminal rows as the node's re-plan states them: position
        rows x ``shift.arrival_weight`` in the arrival phase (radius > 0), velocity rows 1."""
        w = np.ones(6)
        if radius > 0:
            w[:3] = arrival_weight(self.units, radius)
        return w

    def _best_effort(self, rows: np.ndarray, kept: np.ndarray, rating: float,
                     w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The change (S, 3 * stages) of a re-plan whose rows (S, 6) ``rating`` cannot meet,
        and its miss (S,): the rows as near as they come together -- least squares of the
        rows weighted by w (6,) as the node's terminal constraints weigh them, every stage
        within the rating -- and the largest weighted row left. The node's best-effort plan
        is its augmented Lagrangian's stalled point, near min 1/2 |psi|^2 of the same rows
        (docs/policies.md, the campaign prediction)."""
        balls = self.balls
        inside = balls.within(kept, rating) - kept
        d = balls.nearest(self.M * w[:, None], rows * w, inside, kept, rating)
        d = balls.within(kept + d, rating) - kept   # (the barrier's ball is 1e-6 wider)
        return d, np.max(np.abs((rows - d @ self.M.T) * w), axis=1)

    def _clipped(self, c: np.ndarray) -> np.ndarray:
        """(S, stages, 3) the thrust changes, a thrust past the rating scaled back onto it."""
        return (self.balls.within(c, self.rating) * self.scale).reshape(len(c), -1, NU)


def _execution(U: np.ndarray, config: CampaignConfig) -> np.ndarray:
    """The square root S (3, 3) of the execution error's covariance on a commanded thrust U
    (normalised; w = S z, z ~ N(0, I)): the magnitude's along U, the pointing's across it (a
    rotation by N(0, sigma) about a random axis normal to U: sigma^2 / 2 per transverse axis).
    Along and across are orthogonal projections, so S = a P + b (I - P) squares to the
    covariance a^2 P + b^2 (I - P)."""
    mag = float(np.linalg.norm(U))
    if mag == 0.0:
        return np.zeros((NU, NU))
    u = U / mag
    along = np.outer(u, u)
    sp = np.radians(config.execution.pointing_deg)
    return config.execution.magnitude * mag * along + \
        np.sqrt(0.5) * sp * mag * (np.eye(NU) - along)


def _si_scale(units) -> np.ndarray:
    """(7,) SI per normalised unit of [r, v, m]."""
    one = units.cartesian_si(np.ones(NX)) - units.cartesian_si(np.zeros(NX))
    return np.asarray(one, float)


AXES = ("x [m]", "y [m]", "z [m]", "vx [m/s]", "vy [m/s]", "vz [m/s]")


# resamples of the runs behind each 95 % interval (``compare``)
BOOTSTRAP_RESAMPLES = 4999


@dataclass(frozen=True)
class Comparison:
    """A prediction beside a Monte Carlo's terminal deviations (runs, 6): per axis the
    predicted mean and standard deviation, the sample's, and the sample's 95 % intervals
    (bootstrap, ``compare``); the CPU of each [s]."""

    predicted_mean: np.ndarray
    predicted_std: np.ndarray
    mean: np.ndarray
    mean_95: np.ndarray          # (6, 2)
    std: np.ndarray
    std_95: np.ndarray           # (6, 2)
    runs: int
    predicted_cpu_s: float
    monte_carlo_cpu_s: float

    @property
    def mean_inside(self) -> np.ndarray:
        return (self.mean_95[:, 0] <= self.predicted_mean) & \
            (self.predicted_mean <= self.mean_95[:, 1])

    @property
    def std_inside(self) -> np.ndarray:
        return (self.std_95[:, 0] <= self.predicted_std) & \
            (self.predicted_std <= self.std_95[:, 1])


def compare(prediction: Prediction, deviations_si: np.ndarray,
            monte_carlo_cpu_s: float) -> Comparison:
    """``prediction`` against the Monte Carlo's terminal deviations (runs, 6), with the runs'
    95 % intervals of the mean and of the standard deviation by the bootstrap (BCa,
    ``BOOTSTRAP_RESAMPLES`` resamples, a fixed seed: the same runs give the same intervals).
    Why not Student's t and the chi-square: the chi-square interval of a standard deviation
    holds for Gaussian samples only, and a closed loop's terminal deviations are not (the
    halo's: kurtosis 4-7, where a Gaussian's is 3); on heavier tails it is too narrow
    (``test_campaign_prediction.py``: 74 % coverage where it promises 95 %)."""
    d = np.asarray(deviations_si, float)
    mean, std = d.mean(axis=0), d.std(axis=0, ddof=1)
    return Comparison(prediction.mean_si, np.sqrt(np.diag(prediction.cov_si)), mean,
                      _bootstrap_95(d, lambda x, axis: x.mean(axis=axis), mean), std,
                      _bootstrap_95(d, lambda x, axis: x.std(axis=axis, ddof=1), std),
                      len(d), prediction.cpu_s, monte_carlo_cpu_s)


def _bootstrap_95(d: np.ndarray, statistic, value: np.ndarray) -> np.ndarray:
    """(k, 2) the BCa 95 % interval of ``statistic`` of the runs d (runs, k), per axis; an
    axis whose runs are all equal has its value as the interval (no spread to resample)."""
    import warnings

    from scipy import stats
    with warnings.catch_warnings(), np.errstate(all="ignore"):   # (a constant axis, or two
        warnings.simplefilter("ignore", stats.DegenerateDataWarning)   # runs: NaN, warned)
        warnings.simplefilter("ignore", RuntimeWarning)
        ci = stats.bootstrap((d,), statistic, axis=0, n_resamples=BOOTSTRAP_RESAMPLES,
                             method="BCa", rng=np.random.default_rng(0),
                             batch=500).confidence_interval
    out = np.column_stack([ci.low, ci.high])
    return np.where(np.isfinite(out), out, value[:, None])


def format_comparison(c: Comparison) -> str:
    rows = [f"terminal deviation from the target: predicted (linearised closed loop) vs "
            f"{c.runs} closed-loop runs (95 % intervals)",
            f"{'':10s}{'mean pred':>12s}{'mean MC':>12s}{'95 % interval':>26s}"
            f"{'std pred':>12s}{'std MC':>12s}{'95 % interval':>26s}"]
    for i, axis in enumerate(AXES):
        f = ".3f" if i < 3 else ".6f"
        rows.append(
            f"{axis:10s}{c.predicted_mean[i]:>12{f}}{c.mean[i]:>12{f}}"
            f"{f'[{c.mean_95[i, 0]:{f}}, {c.mean_95[i, 1]:{f}}]':>26s}"
            f"{c.predicted_std[i]:>12{f}}{c.std[i]:>12{f}}"
            f"{f'[{c.std_95[i, 0]:{f}}, {c.std_95[i, 1]:{f}}]':>26s}"
            f"  {'in' if c.mean_inside[i] else 'OUT'}/{'in' if c.std_inside[i] else 'OUT'}")
    rows.append(f"CPU: prediction {c.predicted_cpu_s:.1f} s, Monte Carlo {c.monte_carlo_cpu_s:.0f} s"
                f" ({c.predicted_cpu_s / c.monte_carlo_cpu_s:.2%})")
    return "\n".join(rows)


def plot_comparison(prediction: Prediction, deviations_si: np.ndarray, path) -> None:
    """The terminal position (x-y, x-z) and velocity deviations of the runs with the 1- and
    3-sigma ellipses of their covariance and of the prediction's. Needs matplotlib."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .campaign_plot import ellipse
    d = np.asarray(deviations_si, float)
    fig, axes = plt.subplots(1, 4, figsize=(18, 4.6))
    for ax, (i, j) in zip(axes, ((0, 1), (0, 2), (3, 4), (3, 5))):
        ax.plot(d[:, i], d[:, j], ".", ms=3, color="0.5", label=f"runs ({len(d)})")
        for cov, colour, name in ((np.cov(d, rowvar=False), "tab:blue", "runs' covariance"),
                                  (prediction.cov_si, "tab:orange", "predicted")):
            for k, style in ((1, "-"), (3, "--")):
                x, y = ellipse(cov[np.ix_([i, j], [i, j])], k)
                ax.plot(x, y, style, color=colour,
                        label=f"{name}, {k} sigma")
        ax.set_xlabel(AXES[i])
        ax.set_ylabel(AXES[j])
        ax.set_aspect("equal", adjustable="datalim")
    axes[0].legend(fontsize=7, loc="upper left")
    fig.suptitle("terminal deviation: closed-loop runs and the linearised loop's prediction")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
