"""The ideal solar sail of Leemans, Carzana and Heiligers (many-revolution solar-sail DDP, the
paper's Sec. II.B), written once for floats, arrays and DA: the Sun's position from a
low-precision analytic ephemeris (``ephemeris``), a smooth cylindrical Earth shadow, the sail normal from two
unbounded controls (the tangent-plane point of its direction), the sail's acceleration, and the locally optimal steering law that is
its initial guess and baseline. The first part of issue 45 (the model; the Sundman-staged
problems and catalogue cases build on it).

Frames and units: Earth-centred inertial, the Earth's equator as xy-plane (ECI, J2000);
positions in any length unit shared by the arguments, accelerations in the units of the
gravitational parameter given. Vectors come as lists of 3 components (floats, arrays or DA,
as the right-hand sides use them; ``np.asarray`` or ``dm.stack`` makes one array).
"""
from __future__ import annotations

import numpy as np

from ..da import functions as dm



def sunlight(r, r_sun, radius: float, width: float):
    """The smoothed sunlight fraction (*batch) at ECI position r (3, *batch): 1 in sunlight, 0
    in the Earth's cylindrical shadow, a product of two logistic steps of ``width`` (the
    position's units) across the shadow's boundaries -- the side facing away from the Sun
    (r . s_hat = 0) and the cylinder of ``radius`` about the Sun line. r_sun: the Sun's
    position (3,) or (3, *batch)."""
    d = dm.sqrt(r_sun[0] * r_sun[0] + r_sun[1] * r_sun[1] + r_sun[2] * r_sun[2])
    along = (r[0] * r_sun[0] + r[1] * r_sun[1] + r[2] * r_sun[2]) / d      # towards the Sun
    rho = dm.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2] - along * along + width * width)
    behind = 0.5 * (1.0 - dm.tanh(along * (1.0 / width)))
    inside = 0.5 * (1.0 + dm.tanh((radius - rho) * (1.0 / width)))
    return 1.0 - behind * inside


def sail_frame(s_hat):
    """The sail frame's axes (3 vectors (3, *batch)): s_hat, the sunlight direction (from the
    Sun to the sail, unit), p = the ECI z-axis made orthogonal to s_hat, q = s_hat x p.
    Interpretation (the paper's eq. 4-5 lost their symbols): the clock angle is measured from
    p, so that at 90 deg the normal lies in the plane of s_hat and the equator when the Sun is
    in it (the paper's in-plane steering of its 2-D case). Undefined for sunlight along z (the
    Sun's declination stays within 23.5 deg)."""
    s0, s1, s2 = s_hat[0], s_hat[1], s_hat[2]
    p0, p1, p2 = -s2 * s0, -s2 * s1, 1.0 - s2 * s2          # z - (z . s) s
    pn = 1.0 / dm.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
    p0, p1, p2 = p0 * pn, p1 * pn, p2 * pn
    q = (s1 * p2 - s2 * p1, s2 * p0 - s0 * p2, s0 * p1 - s1 * p0)
    return (s0, s1, s2), (p0, p1, p2), q


def sail_normal(w1, w2, s_hat):
    """The sail's unit normal (a list of 3 components (*batch)) from the controls (w1, w2): the
    point where the normal's line crosses the plane tangent to the unit sphere at s_hat, in the
    sail frame's (p, q) axes (``sail_frame``): n = (s_hat + w1 p + w2 q) / sqrt(1 + w1^2 + w2^2).
    So tan(cone) = |w| and the clock angle is atan2(w2, w1) (``cone_clock``); every w faces the
    Sun (n . s_hat > 0) and the normal turns edge-on only as |w| -> inf.

    Why not the paper's cone and clock angles in a tanh box: the clock angle is undefined at a
    zero cone angle (the Sun-facing guess), where its gradient and curvature vanish, and the
    tanh box flattens exponentially towards 90 deg, where a long step leaves the controls
    stranded (design notes: the sail's controls)."""
    s, p, q = sail_frame(s_hat)
    inv = 1.0 / dm.sqrt(1.0 + w1 * w1 + w2 * w2)
    return [(s[i] + w1 * p[i] + w2 * q[i]) * inv for i in range(3)]


def cone_clock(w1, w2):
    """(cone, clock) [rad] of the normal of controls (w1, w2) (``sail_normal``): cone in
    [0, 90 deg), clock in (-180, 180] deg."""
    w1, w2 = np.asarray(w1, float), np.asarray(w2, float)
    return np.arctan(np.hypot(w1, w2)), np.arctan2(w2, w1)


def normal_controls(cone, clock):
    """The controls (w1, w2) of the normal at cone angle ``cone`` (|cone| < 90 deg; a negative
    cone is the opposite clock) and clock angle ``clock`` [rad] (``sail_normal``'s inverse)."""
    t = np.tan(np.asarray(cone, float))
    return t * np.cos(clock), t * np.sin(clock)


def sail_acceleration(r, r_sun, n, beta: float, gm_sun: float, light=1.0):
    """The ideal sail's acceleration (a list of 3 components (*batch); the paper's eq. 6): light beta gm_sun /
    |r_s|^2 (s_hat . n)^2 n, r_s = r - r_sun the Sun-to-sail vector, n the unit normal
    (``sail_normal``, n . s_hat >= 0; a list or (3, *batch)), beta the lightness number, light the sunlight fraction
    (``sunlight``)."""
    rs = [r[i] - r_sun[i] for i in range(3)]
    d2 = rs[0] * rs[0] + rs[1] * rs[1] + rs[2] * rs[2]
    cos_a = (rs[0] * n[0] + rs[1] * n[1] + rs[2] * n[2]) / dm.sqrt(d2)
    scale = light * (beta * gm_sun) / d2 * cos_a * cos_a
    return [scale * n[i] for i in range(3)]


def locally_optimal_cone(theta):
    """The cone angle alpha* [rad] that maximises the sail's acceleration along a direction at
    angle theta [rad] from the sunlight, (cos alpha)^2 cos(theta - alpha) (McInnes, Solar
    Sailing, sec. 4.3.2): tan alpha* = (-3 cos theta + sqrt(9 cos^2 theta + 8 sin^2 theta)) /
    (4 sin theta); alpha* = 0 at theta = 0, and alpha* -> 90 deg as theta -> 180 deg."""
    theta = np.asarray(theta, float)
    c, s = np.cos(theta), np.sin(theta)
    return np.sign(s) * np.arctan2(-3.0 * c + np.sqrt(9.0 * c * c + 8.0 * s * s), 4.0 * np.abs(s))
