"""RK78 (and RK4) against scipy's DOP853 at rtol = atol = 1e-12 on every model; our DOP853 (the
solver's re-propagation check) against scipy's."""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from daddy_core import da
from daddy_core.dynamics import Dynamics, models
from daddy_core.dynamics.units import Spacecraft, earth_units
from daddy_core.errors import DaddyError
from daddy_core.integrators import dop853, dop853_batch, rk4, rk78
from daddy_core.catalogue import load_case


def reference(rhs, x0, u, T):
    sol = solve_ivp(lambda t, x: rhs(t, x, u), (0.0, T), x0, method="DOP853", rtol=1e-12, atol=1e-12)
    return sol.y[:, -1]


@pytest.mark.parametrize("name", ["earth_mars", "halo_l2_l1", "dro_dro", "leo_leo"])
def test_rk78_matches_dop853(name):
    case = load_case(name)
    rhs = case.rhs()
    t0, T = case.t_start, 5 * case.stage_lengths()[0]  # five stages' worth
    u = np.array([0.3, -0.2, 0.1]) * (0.5 / case.units.thrust_unit_n)  # ~0.2 N
    x = rk78(rhs, case.x0, u, t0, T, tol=1e-13)
    sol = solve_ivp(lambda t, x: rhs(t, x, u), (t0, t0 + T), case.x0, method="DOP853",
                    rtol=1e-12, atol=1e-12)
    ref = sol.y[:, -1]
    # DOP853 at rtol 1e-12 is itself accurate to ~1e-12 relative
    assert np.max(np.abs(x - ref) / np.maximum(1.0, np.abs(ref))) < 1e-10
    # fixed-step RK4 with one step per stage is less accurate on the same span
    x4 = rk4(rhs, case.x0, u, t0, T, steps=5)
    assert np.max(np.abs(x4 - ref)) > np.max(np.abs(x - ref))


def test_rk78_fewer_rhs_calls_than_rk4_for_same_accuracy():
    case = load_case("halo_l2_l1")
    rhs = case.rhs()
    T = case.tof / 110
    ref = reference(rhs, case.x0, np.zeros(3), T)
    stats = {}
    x = rk78(rhs, case.x0, np.zeros(3), 0.0, T, tol=1e-12, stats=stats)
    err78 = np.max(np.abs(x - ref))
    # smallest RK4 step count reaching the same accuracy
    for steps in (5, 10, 20, 40, 80, 160, 320):
        if np.max(np.abs(rk4(rhs, case.x0, np.zeros(3), 0.0, T, steps=steps) - ref)) <= max(err78, 1e-12):
            break
    assert stats["rhs_calls"] < 4 * steps


@pytest.mark.parametrize("B", [3, 12])   # state by state (<= 8) and vectorised
def test_batched_rk78_with_different_stage_lengths(B):
    case = load_case("earth_mars")
    rhs = case.rhs()
    X = np.tile(case.x0[:, None], (1, B))
    U = np.zeros((3, B))
    dts = np.linspace(0.05, 0.3, B)
    xb = rk78(rhs, X, U, 0.0, dts, tol=1e-13)
    for j in range(B):
        np.testing.assert_allclose(xb[:, j], reference(rhs, case.x0, np.zeros(3), dts[j]), atol=1e-11)


def test_batched_da_rk78_drops_arrived_stages_without_changing_any():
    """A batch whose stages need very different step counts (an NRHO stage through perilune
    takes many, the rest one or two): the elements that have arrived leave the batch
    (integrators._Arrived); every element's expansion is the one it gets integrated alone (to
    round-off: small batches take another product kernel), and the step count is the slowest
    element's."""
    case = load_case("nrho_dro")
    rhs = case.rhs()
    dt = case.tof / 150
    # 16 stages of the coast from the NRHO's start: 21-24 pass perilune (3-15 steps at 1e-8)
    starts = [21, 22, 23, 24] + list(range(0, 120, 10))
    X = np.stack([rk78(rhs, case.x0, np.zeros(3), 0.0, k * dt, tol=1e-13) for k in starts],
                 axis=1)
    U = np.full((3, X.shape[1]), 1e-7)
    z = da.variables(np.concatenate([X, U]), order=2)
    dts = np.full(X.shape[1], dt)
    stats = {}
    F = rk78(rhs, z[:7], z[7:], 0.0, dts, tol=1e-8, h0=dts, stats=stats)
    alone = []
    for j in range(X.shape[1]):
        s = {}
        zj = da.variables(np.concatenate([X[:, j], U[:, j]]), order=2)
        Fj = rk78(rhs, zj[:7], zj[7:], 0.0, dts[j], tol=1e-8, h0=dts[j], stats=s)
        alone.append(s["steps"])
        np.testing.assert_allclose(F.c[..., j], Fj.c, rtol=0, atol=1e-12 * np.abs(Fj.c).max())
    assert stats["steps"] == max(alone) and max(alone) >= 3 * min(alone)


@pytest.mark.parametrize("name", ["earth_mars", "halo_l2_l1", "leo_leo"])
def test_single_state_rk78_matches_batched_path(name):
    """One (nx,) state takes the plain-Python path: float lists for a rhs flagged
    ``Dynamics.scalar_components``, numpy arrays for any other (a plain callable); both follow the batched path's steps."""
    case = load_case(name)
    rhs = case.rhs()
    assert rhs.scalar_components
    seen = []

    def unflagged(t, x, u):
        seen.append(type(x))
        return rhs(t, x, u)

    u = np.array([0.3, -0.2, 0.1]) * (0.5 / case.units.thrust_unit_n)
    T = case.tof / 40
    xb = rk78(rhs, case.x0[:, None], u[:, None], 0.0, T, tol=1e-13)[:, 0]
    for f in (rhs, unflagged):
        x = rk78(f, case.x0, u, 0.0, T, tol=1e-13)
        assert isinstance(x, np.ndarray) and x.shape == case.x0.shape
        np.testing.assert_allclose(x, xb, rtol=0, atol=1e-14 * np.max(np.abs(xb)))
    assert seen and set(seen) == {np.ndarray}


def test_equinoctial_matches_cartesian_with_rtn_thrust():
    units = earth_units()
    c = 40.0
    rhs_eq = models.equinoctial(1.0, c)
    x0 = np.append(models.keplerian_to_equinoctial(0.6, 0.1, 0.5, 1.0, 0.3, 0.2), 1.0)
    u_rtn = np.array([0.01, 0.02, -0.015])

    def rhs_cart(t, y, u):
        r, v, m = y[:3], y[3:6], y[6]
        h = np.cross(r, v)
        R = np.column_stack([r / np.linalg.norm(r), np.cross(h, r) / np.linalg.norm(np.cross(h, r)),
                             h / np.linalg.norm(h)])
        a = -r / np.linalg.norm(r) ** 3 + R @ u / m
        return np.concatenate([v, a, [-np.linalg.norm(u) / c]])

    T = 2.0
    xe = rk78(rhs_eq, x0, u_rtn, 0.0, T, tol=1e-13)
    y0 = np.append(models.equinoctial_to_cartesian(x0, 1.0), 1.0)
    yc = reference(rhs_cart, y0, u_rtn, T)
    np.testing.assert_allclose(models.equinoctial_to_cartesian(xe, 1.0), yc[:6], atol=1e-9)
    np.testing.assert_allclose(xe[6], yc[6], atol=1e-12)
    assert units.vu_km_s == pytest.approx(0.48890, abs=1e-5)


def test_earth_orbits_have_their_keplerian_period_and_secular_rate():
    """Earth-centred physics in the catalogue's units: a ballistic LEO of 6778 km closes after
    2 pi sqrt(a^3 / mu) = 5553 s (the units' gm is 4 pi^2, not 1), an eccentric orbit (e = 0.3,
    within the Sundman model's step bound, ``models.SUNDMAN_MAX_STEP``) after its own period --
    in the time-staged Gauss equations L advances by exactly 2 pi in a period, in the
    Sundman-transformed ones (the catalogue's) the time advances by a period over 2 pi of L; the
    other elements come back -- and a small tangential thrust raises a circular orbit at
    the Gauss-equation rate da/dt = 2 a^(3/2) f / sqrt(mu) (f the acceleration)."""
    from daddy_core.dynamics.units import MU_EARTH_KM3_S2
    units = earth_units()
    c = Spacecraft().exhaust_speed(units)
    timed = models.equinoctial(units.gm, c)
    sundman = load_case("leo_leo").rhs()
    period_s = 2 * np.pi * np.sqrt(6778.0 ** 3 / MU_EARTH_KM3_S2)
    assert period_s == pytest.approx(5553.0, abs=1.0)
    for a_km, e in ((6778.0, 0.0), (24_505.9, 0.3)):
        T = float(units.time(2 * np.pi * np.sqrt(a_km ** 3 / MU_EARTH_KM3_S2)))
        kep = (a_km / units.lu_km, e, np.radians(7.0), 0.3, 0.5, 0.1)
        x0 = np.append(models.keplerian_to_equinoctial(*kep), 1.0)
        x = rk78(timed, x0, np.zeros(3), 0.0, T, tol=1e-13)
        np.testing.assert_allclose(x[5] - x0[5], 2 * np.pi, rtol=1e-9)
        np.testing.assert_allclose(x[:5], x0[:5], rtol=0, atol=1e-9)
        mee, L0 = models.keplerian_to_mee(*kep)
        y0 = np.concatenate([mee, [0.0, 1.0]])
        y = rk78(sundman, y0, np.zeros(3), L0, 2 * np.pi, tol=1e-13)
        assert y[5] == pytest.approx(T, rel=1e-10)
        np.testing.assert_allclose(y[:5], mee, rtol=0, atol=1e-10)
    thrust_n = 0.5
    kep = (7000.0 / units.lu_km, 0.0, 0.3, 0.0, 0.0, 0.0)
    T = float(units.time(2 * np.pi * np.sqrt(7000.0 ** 3 / MU_EARTH_KM3_S2)))
    u = np.array([0.0, float(units.thrust(thrust_n)), 0.0])
    x0 = np.append(models.keplerian_to_equinoctial(*kep), 1.0)
    x = rk78(timed, x0, u, 0.0, T, tol=1e-13)
    f_km_s2 = thrust_n / 1000.0 / 1000.0   # N on 1000 kg -> km / s^2
    da_km = 2 * 7000.0 ** 1.5 * f_km_s2 / np.sqrt(MU_EARTH_KM3_S2) * units.time_s(T)
    assert (x[0] - x0[0]) * units.lu_km == pytest.approx(da_km, rel=2e-3)
    mee, L0 = models.keplerian_to_mee(*kep)
    y = rk78(sundman, np.concatenate([mee, [0.0, 1.0]]), u, L0, 2 * np.pi, tol=1e-13)
    a_km = y[0] / (1 - y[1] ** 2 - y[2] ** 2) * units.lu_km
    assert a_km - 7000.0 == pytest.approx(da_km, rel=2e-3)


def test_sundman_elements_match_a_cartesian_propagation_in_time():
    """The Sundman-transformed Gauss equations (independent variable the true longitude, time
    a state) against Newton's equations in Cartesian coordinates with the same RTN thrust
    integrated in time to the time the transformed run reached: 1.1 revolutions of an inclined
    eccentric orbit with thrust in all three directions, position to 1e-9 of the orbit's size;
    and the element conversions round-trip."""
    units = earth_units()
    gm, c = units.gm, 40.0
    mee, L0 = models.keplerian_to_mee(0.6, 0.1, 0.5, 1.0, 0.3, 0.2)
    rv, m = models.mee_to_cartesian(mee, L0, gm), 1.0
    back, L_back = models.cartesian_to_mee(rv, gm)
    np.testing.assert_allclose(back, mee, atol=1e-14)
    assert L_back == pytest.approx(L0 % (2 * np.pi), abs=1e-14)
    u_rtn = np.array([0.01, 0.02, -0.015]) * gm
    x = rk78(models.equinoctial_sundman(gm, c), np.concatenate([mee, [0.0, m]]), u_rtn, L0, 7.0,
             tol=1e-13)

    def rhs_cart(t, y, u):
        r, v = y[:3], y[3:6]
        h = np.cross(r, v)
        R = np.column_stack([r / np.linalg.norm(r), np.cross(h, r) / np.linalg.norm(np.cross(h, r)),
                             h / np.linalg.norm(h)])
        return np.concatenate([v, -gm * r / np.linalg.norm(r) ** 3 + R @ u / y[6],
                               [-np.linalg.norm(u) / c]])
    yc = reference(rhs_cart, np.append(rv, m), u_rtn, x[5])
    np.testing.assert_allclose(models.mee_to_cartesian(x[:5], L0 + 7.0, gm), yc[:6], atol=1e-9)
    assert x[6] == pytest.approx(yc[6], abs=1e-13)


def test_sundman_elements_with_j2_match_a_cartesian_propagation_and_regress_the_node():
    """J2 in the Sundman-transformed Gauss equations against the J2 acceleration written in
    Cartesian coordinates (the gradient of the zonal potential, a = -3/2 J2 mu R^2 / r^5 [x (1 -
    5 z^2/r^2), y (1 - 5 z^2/r^2), z (3 - 5 z^2/r^2)]) with RTN thrust, over three revolutions
    of an inclined eccentric LEO: position to 1 cm (without J2: tens of km off); and
    ballistic, the node regresses at the secular rate -3/2 n J2 (R/p)^2 cos i (Vallado eq.
    9-41) over ten revolutions, to 1 %."""
    from daddy_core.dynamics.units import EARTH_J2, EARTH_J2_RADIUS_KM
    units = earth_units()
    gm, c, R = units.gm, 40.0, EARTH_J2_RADIUS_KM / units.lu_km
    rhs = models.equinoctial_sundman(gm, c, EARTH_J2, R)
    mee, L0 = models.keplerian_to_mee(7000.0 / units.lu_km, 0.05, 0.9, 1.0, 0.3, 0.2)
    u_rtn = np.array([0.01, 0.02, -0.015]) * gm * 1e-2
    x = rk78(rhs, np.concatenate([mee, [0.0, 1.0]]), u_rtn, L0, 20.0, tol=1e-13)

    def rhs_cart(t, y, u):
        r, v = y[:3], y[3:6]
        rn = np.linalg.norm(r)
        h = np.cross(r, v)
        Rm = np.column_stack([r / rn, np.cross(h, r) / np.linalg.norm(np.cross(h, r)),
                              h / np.linalg.norm(h)])
        z2 = (r[2] / rn) ** 2
        a_j2 = -1.5 * EARTH_J2 * gm * R ** 2 / rn ** 5 * (r * (1 - 5 * z2) + [0, 0, 2 * r[2]])
        return np.concatenate([v, -gm * r / rn ** 3 + a_j2 + Rm @ u / y[6],
                               [-np.linalg.norm(u) / c]])
    yc = reference(rhs_cart, np.append(models.mee_to_cartesian(mee, L0, gm), 1.0), u_rtn, x[5])
    miss_km = np.abs(models.mee_to_cartesian(x[:5], L0 + 20.0, gm) - yc[:6])[:3].max() * units.lu_km
    assert miss_km < 1e-5, miss_km
    without = rk78(models.equinoctial_sundman(gm, c), np.concatenate([mee, [0.0, 1.0]]), u_rtn, L0,
                   20.0, tol=1e-13)
    miss_without_km = np.abs(models.mee_to_cartesian(without[:5], L0 + 20.0, gm) - yc[:6])[:3].max()
    assert miss_without_km * units.lu_km > 10.0      # J2 moves the orbit by tens of km
    a, i = 7000.0 / units.lu_km, np.radians(51.0)
    mee, L0 = models.keplerian_to_mee(a, 0.0, i, 1.0, 0.0, 0.0)
    y = rk78(rhs, np.concatenate([mee, [0.0, 1.0]]), np.zeros(3), L0, 20 * np.pi, tol=1e-13)
    raan_rate = -1.5 * np.sqrt(gm / a ** 3) * EARTH_J2 * (R / a) ** 2 * np.cos(i)
    raan_change = np.arctan2(y[4], y[3]) - 1.0
    assert raan_change == pytest.approx(raan_rate * y[5], rel=1e-2)


def test_integrator_errors():
    rhs = lambda t, x, u: x * np.nan
    with pytest.raises(DaddyError, match="NaN"):
        rk78(rhs, np.ones(2), None, 0.0, 1.0)
    # a NaN in the last component only, on the plain-Python paths (one state, a few states)
    last_nan = lambda t, x, u: np.array([0.0, 1.0, np.nan])
    for x, u in ((np.ones(3), np.zeros(1)), (np.ones((3, 2)), np.zeros((1, 2)))):
        with pytest.raises(DaddyError, match="NaN"):
            rk78(last_nan, x, u, 0.0, 1.0)
    with pytest.raises(DaddyError, match="4 components for a state of 3"):
        rk78(lambda t, x, u: np.ones(4), np.ones(3), np.zeros(1), 0.0, 1.0)
    with pytest.raises(DaddyError, match="steps"):
        rk4(rhs, np.ones(2), None, 0.0, 1.0, steps=0)
    with pytest.raises(DaddyError, match="tol"):
        rk78(rhs, np.ones(2), None, 0.0, 1.0, tol=0)


@pytest.mark.parametrize("name", ["earth_mars", "halo_l2_l1", "leo_leo"])
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_dop853_takes_scipys_steps(name, sign):
    """Same scheme and step control as solve_ivp(method="DOP853"): the same number of rhs
    calls and the same state to round-off, forwards and backwards, on float lists (scalar
    components) and arrays (the equinoctial model) alike."""
    case = load_case(name)
    rhs = case.rhs()
    T = sign * case.tof / 8
    u = np.array([0.3, -0.2, 0.1]) * (0.5 / case.units.thrust_unit_n)
    up = np.asarray(models.with_thrust_magnitude(u))
    stats = {}
    with np.errstate(invalid="ignore"):   # LEO: the whole-interval trial steps meet NaN, rejected
        ref = solve_ivp(lambda t, x: np.asarray(rhs(t, x, up), dtype=float), (0.0, T), case.x0,
                        method="DOP853", rtol=1e-12, atol=1e-12, first_step=abs(T))
        x = dop853(rhs, case.x0, u, 0.0, T, stats=stats)
        again = dop853(rhs, case.x0, u, 0.0, T, first_step=abs(T))
    assert stats["rhs_calls"] == ref.nfev and stats["steps"] == len(ref.t) - 1
    assert np.max(np.abs(x - ref.y[:, -1]) / np.maximum(1.0, np.abs(ref.y[:, -1]))) < 1e-13
    # and the default first step (the whole interval) is the one passed to scipy above
    np.testing.assert_array_equal(again, x)


@pytest.mark.parametrize("name", ["earth_mars", "halo_l2_l1", "leo_leo"])
def test_dop853_batch_takes_each_members_own_steps(name):
    """Each member of a batch integrates its own interval (forwards, backwards, one step or
    many, through rejected whole-interval trials) with the single-state scheme's steps: the
    same states to round-off."""
    case = load_case(name)
    rhs = case.rhs()
    rng = np.random.default_rng(7)
    B = 9
    u = rng.uniform(-0.6, 0.6, size=(3, B)) * (0.5 / case.units.thrust_unit_n)
    x = case.x0[:, None] * (1.0 + 1e-3 * rng.normal(size=(case.x0.size, B)))
    t0 = rng.uniform(0.0, 1.0, size=B)
    dt = case.tof * np.array([0.001, 0.01, 0.1, 0.25, -0.001, -0.05, -0.2, 0.0, 0.05])
    with np.errstate(invalid="ignore"):   # LEO: whole-interval trials meet NaN, rejected
        got = dop853_batch(rhs, x, u, t0, dt)
        ref = np.stack([dop853(rhs, x[:, j], u[:, j], t0[j], dt[j]) for j in range(B)], axis=1)
    assert np.max(np.abs(got - ref) / np.maximum(1.0, np.abs(ref))) < 1e-14
    np.testing.assert_array_equal(got[:, 7], x[:, 7])    # a zero-length interval: no step


def test_dop853_errors():
    with pytest.raises(DaddyError, match=r"round-off at t = 0\.(29999|3)"):   # NaN from t = 0.3 on
        dop853(lambda t, x, u: np.array([0.0, 1.0, np.nan if t > 0.3 else 0.0]), np.ones(3),
               np.zeros(1), 0.0, 1.0)
    with pytest.raises(DaddyError, match="4 components for a state of 3"):
        dop853(lambda t, x, u: np.ones(4), np.ones(3), np.zeros(1), 0.0, 1.0)
    with pytest.raises(DaddyError, match="max_steps=3"):
        dop853(lambda t, x, u: x, np.ones(1), np.zeros(1), 0.0, 50.0, max_steps=3)
    with pytest.raises(DaddyError, match="round-off"):                # one member's NaN
        dop853_batch(lambda t, x, u: np.where(t > 0.3, np.nan, 0.0) * np.ones_like(x),
                     np.ones((3, 2)), np.zeros((1, 2)), 0.0, np.array([0.2, 1.0]))
    with pytest.raises(DaddyError, match="max_steps=3"):
        dop853_batch(lambda t, x, u: x, np.ones((1, 2)), np.zeros((1, 2)), 0.0, 50.0,
                     max_steps=3)


@pytest.mark.parametrize("derivative_tol", [None, 1e-8])
def test_flow_step_takes_given_values_as_constant_part(derivative_tol):
    """A DA expansion given the flows already integrated keeps them as its constant part,
    whatever the derivative tolerance; its derivatives are those of the plain expansion."""
    from daddy_core import da
    from daddy_core.problem import flow_step
    case = load_case("earth_mars")
    step = flow_step(case.rhs(), derivative_tol=derivative_tol)
    z = da.variables(np.concatenate([case.x0, [1e-3, 0.0, 0.0]])[:, None], order=2)
    dt = np.array([case.tof / 40])
    plain = step(z[:7], z[7:], dt)
    given = step.expand(z[:7], z[7:], dt, plain.cons + 1.0)
    np.testing.assert_array_equal(given.cons, plain.cons + 1.0)
    np.testing.assert_array_equal(given.gradient(), plain.gradient())


@pytest.mark.parametrize("name", ["earth_mars", "halo_l2_l1", "leo_leo"])
def test_prepared_control_changes_no_value(name):
    """The catalogue models let the integrators append |u| to the control once per integration
    (``Dynamics.prepare_control``): flows and DA expansions are bit-identical to recomputing it at
    every stage, and the rhs takes either form of the control."""
    from daddy_core import da

    case = load_case(name)
    rhs = case.rhs()
    assert rhs.prepare_control is models.with_thrust_magnitude
    u = np.array([0.3, -0.2, 0.1]) * (0.5 / case.units.thrust_unit_n)
    u4 = models.with_thrust_magnitude(u)
    assert u4.shape == (4,) and u4[3] == models.thrust_magnitude(u)
    np.testing.assert_array_equal(rhs(0.0, case.x0, u4), rhs(0.0, case.x0, u))

    def plain_fn(t, x, uu):   # the same model without the prepared control: |u| at every stage
        return rhs.f(t, x, uu)
    plain = Dynamics(plain_fn, scalar_components=True, max_step=rhs.max_step)
    T = case.tof / 40
    for x, uu in ((case.x0, u), (np.stack([case.x0] * 3, axis=1), np.stack([u] * 3, axis=1))):
        np.testing.assert_array_equal(rk78(rhs, x, uu, 0.0, T, h0=T),
                                      rk78(plain, x, uu, 0.0, T, h0=T))
    z = da.variables(np.concatenate([case.x0, u])[:, None], order=2)
    a = rk78(rhs, z[:7], z[7:], 0.0, T, tol=1e-8, h0=T)
    b = rk78(plain, z[:7], z[7:], 0.0, T, tol=1e-8, h0=T)
    np.testing.assert_array_equal(a.c, b.c)


def test_the_dop853_tableau_is_scipys_to_the_last_bit():
    """integrators.dop853 reads its tableau from daddy_core.dop853_tableau (Python floats, so
    that importing the package does not import scipy.integrate): every entry is scipy's."""
    from scipy.integrate._ivp import dop853_coefficients as ref

    from daddy_core import dop853_tableau as tab
    assert tab.N_STAGES == ref.N_STAGES
    assert tab.C == [float(c) for c in ref.C[:ref.N_STAGES]]
    for i in range(ref.N_STAGES):
        row = np.zeros(i)
        for j, a in tab.A_ROWS[i]:
            row[j] = a
        np.testing.assert_array_equal(row, ref.A[i, :i])
    for mine, theirs in ((tab.B, ref.B), (tab.E3, ref.E3), (tab.E5, ref.E5)):
        vec = np.zeros(len(theirs))
        for j, v in mine:
            vec[j] = v
        np.testing.assert_array_equal(vec, theirs)


def test_importing_the_solver_does_not_import_scipy_integrate():
    import subprocess
    import sys
    code = ("import sys, daddy_core.solver, daddy_core.catalogue; "
            "print('scipy.integrate' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_an_attribute_set_on_a_plain_rhs_by_the_old_api_is_a_warning_naming_dynamics():
    """``rhs.scalar_components = True`` (read by earlier versions) is not read now: a
    FutureWarning names the Dynamics field instead of ignoring it silently; the integration is
    the plain function's, as with no attribute."""
    def f(t, x, u):
        return np.array([x[1], -x[0]])

    plain = rk78(f, np.array([1.0, 0.0]), None, 0.0, 1.0, tol=1e-12)
    f.scalar_components = True
    with pytest.warns(FutureWarning, match=r"Dynamics\(rhs, scalar_components=True\)"):
        flagged = rk78(f, np.array([1.0, 0.0]), None, 0.0, 1.0, tol=1e-12)
    np.testing.assert_array_equal(flagged, plain)
