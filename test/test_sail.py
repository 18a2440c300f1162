"""The ideal solar sail's model (daddy_core.dynamics.sail; issue 45's first part): the Sun's
ephemeris, the Earth's smoothed shadow, the sail normal and acceleration, the steering law --
each against an independent value or a brute-force check, on floats and DA alike."""
import math

import numpy as np
import pytest

from daddy_core import da
from daddy_core.dynamics import ephemeris, sail
from daddy_core.dynamics.units import AU_KM, MU_SUN_KM3_S2 as GM_SUN

R_EARTH_KM = 6378.1363


def test_the_sun_at_j2000_is_where_the_almanac_puts_it():
    """2000-01-01 12:00 TT: apparent right ascension 18h 45m 09s (281.29 deg), declination
    -23.03 deg, distance 0.98333 AU (Astronomical Almanac 2000; the low-precision series keeps
    0.01 deg and 1e-3 in distance)."""
    r = np.asarray(ephemeris.sun_position_km(0.0), float)
    d = np.linalg.norm(r)
    ra = math.degrees(math.atan2(r[1], r[0])) % 360.0
    dec = math.degrees(math.asin(r[2] / d))
    assert ra == pytest.approx(281.29, abs=0.02)
    assert dec == pytest.approx(-23.03, abs=0.02)
    assert d / AU_KM == pytest.approx(0.98333, abs=2e-4)
    # half a year later the Sun is on the other side, near the June solstice's declination
    r2 = np.asarray(ephemeris.sun_position_km(182.6 * 86400.0), float)
    assert np.dot(r, r2) < 0 and math.degrees(math.asin(r2[2] / np.linalg.norm(r2))) > 23.0


def test_the_shadow_is_the_earths_cylinder_smoothed_over_its_width():
    sun = np.array([AU_KM, 0.0, 0.0])
    w = 10.0
    points = {(-42164.0, 0.0): 0.0, (42164.0, 0.0): 1.0, (0.0, 42164.0): 1.0,
              (-42164.0, R_EARTH_KM - 100.0): 0.0, (-42164.0, R_EARTH_KM + 100.0): 1.0,
              (-42164.0, R_EARTH_KM): 0.5}
    for (x, y), expected in points.items():
        light = sail.sunlight(np.array([x, y, 0.0]), sun, R_EARTH_KM, w)
        assert light == pytest.approx(expected, abs=1e-3), (x, y)
    # the exit from the shadow of a GEO orbit at the geometric angle, to the width's accuracy
    nu = np.linspace(math.pi - 0.3, math.pi + 0.3, 20001)
    r = 42164.0 * np.array([np.cos(nu), np.sin(nu), np.zeros_like(nu)])
    light = sail.sunlight(r, sun, R_EARTH_KM, w)
    half = nu[np.argmin(np.abs(light - 0.5)[nu > math.pi]) + np.count_nonzero(nu <= math.pi)]
    assert half - math.pi == pytest.approx(math.asin(R_EARTH_KM / 42164.0), abs=w / 42164.0)


def test_the_normal_is_a_unit_vector_that_faces_the_sun_at_its_cone_and_clock():
    rng = np.random.default_rng(4)
    s = rng.normal(size=(3, 500))
    s /= np.linalg.norm(s, axis=0)
    s[2] *= 0.4
    s /= np.linalg.norm(s, axis=0)
    w1, w2 = rng.normal(scale=3.0, size=(2, 500))
    n = np.asarray(sail.sail_normal(w1, w2, s), float)
    assert np.allclose(np.linalg.norm(n, axis=0), 1.0, atol=1e-12)
    cone, clock = sail.cone_clock(w1, w2)
    np.testing.assert_allclose(np.einsum("ik,ik->k", n, s), np.cos(cone), atol=1e-12)
    # the clock angle from the sail frame's p axis towards q
    _, p, q = (np.asarray(a, float) for a in sail.sail_frame(s))
    np.testing.assert_allclose(np.arctan2(np.einsum("ik,ik->k", n, q), np.einsum("ik,ik->k", n, p)),
                               clock, atol=1e-12)
    # normal_controls inverts cone_clock
    np.testing.assert_allclose(np.array(sail.normal_controls(cone, clock)), [w1, w2], atol=1e-9)
    # the clock angle at 90 deg keeps the normal in the equator when the Sun is in it
    n90 = np.asarray(sail.sail_normal(*sail.normal_controls(0.7, math.pi / 2),
                                      np.array([1.0, 0.0, 0.0])), float)
    assert abs(n90[2]) < 1e-15 and n90[0] == pytest.approx(math.cos(0.7))


def test_the_acceleration_is_the_ideal_sails_and_its_da_derivatives_are_its_own():
    sun = np.asarray(ephemeris.sun_position_km(0.0), float)
    r = np.array([42164.0, 0.0, 0.0])
    beta = 0.011
    s_hat = (r - sun) / np.linalg.norm(r - sun)
    n = np.asarray(sail.sail_normal(0.0, 0.0, s_hat), float)
    a = np.asarray(sail.sail_acceleration(r, sun, n, beta, GM_SUN), float)
    # facing the Sun: beta times the Sun's gravity at that distance, along the sunlight
    g_sun = GM_SUN / np.dot(r - sun, r - sun)
    np.testing.assert_allclose(a, beta * g_sun * s_hat, rtol=1e-12)
    # derivatives in (r, w1, w2) from DA against central differences
    z0 = np.array([r[0], r[1], r[2], 0.4, -1.1])

    def f(z):
        nn = sail.sail_normal(z[3], z[4], sail.sail_frame(_unit(z[:3] - sun))[0])
        light = sail.sunlight(z[:3], sun, R_EARTH_KM, 10.0)
        return da.functions.stack(sail.sail_acceleration(z[:3], sun, nn, beta, GM_SUN, light))

    J = np.asarray(f(da.variables(z0, order=1)).gradient())
    for j in range(5):
        h = 1e-3 if j < 3 else 1e-6
        e = np.zeros(5)
        e[j] = h
        fd = (np.asarray(f(z0 + e), float) - np.asarray(f(z0 - e), float)) / (2 * h)
        np.testing.assert_allclose(J[:, j], fd, rtol=1e-5, atol=1e-16)


def _unit(v):
    return v / da.functions.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])


@pytest.mark.parametrize("theta_deg", [0.0, 20.0, 60.0, 90.0, 135.0, 170.0, -60.0])
def test_the_steering_law_maximises_the_acceleration_along_a_direction(theta_deg):
    theta = math.radians(theta_deg)
    alpha = np.linspace(-math.pi / 2, math.pi / 2, 200001)
    gain = np.cos(alpha) ** 2 * np.cos(theta - alpha)
    best = alpha[np.argmax(gain)]
    assert float(sail.locally_optimal_cone(theta)) == pytest.approx(best, abs=2e-5)
