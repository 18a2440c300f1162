"""Equations of motion from the paper, written once for floats, numpy arrays and DA.

Every right-hand side has the signature ``rhs(t, x, u) -> dx/dt`` (a closure over its constants,
built by the factory functions below, returned as a ``Dynamics`` that says it reads x and u by
index and prepares the thrust magnitude once per integration), with ``x`` of shape (7, *batch) = [r (3), v (3), m] (or
equinoctial elements + mass) and ``u`` of shape (3, *batch) the thrust in normalised force units.
Accelerations are thrust / mass; the mass rate is -|u| / c with c = g0 Isp in normalised units.

|u| is computed as sqrt(u.u + THRUST_FLOOR^2): the mass flow is not differentiable at zero thrust,
and the floor (1e-12 force units, i.e. ~1e-12 N-scale) keeps every expansion finite at u = 0 at a
propellant cost below 1e-9 kg over any catalogue transfer.
"""
from __future__ import annotations

import math

import numpy as np

from ..da import functions as dm
from .rhs import Dynamics

THRUST_FLOOR = 1e-12


def thrust_magnitude(u):
    """Regularised thrust norm sqrt(|u|^2 + THRUST_FLOOR^2), shape (*batch)."""
    return dm.sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2] + THRUST_FLOOR ** 2)


def with_thrust_magnitude(u):
    """The control with its regularised magnitude appended, [u_0, u_1, u_2, |u|] (4, *batch).

    The right-hand sides below declare it as ``Dynamics.prepare_control``: the integrators call it
    once per integration (the control is constant over a stage) and pass the result as u, so
    the magnitude -- a quarter of a DA right-hand side's products and its square root -- is not
    recomputed at each of RK78's 13 stages. The values are the same either way."""
    if len(u) > 3:
        return u
    return dm.stack([u[0], u[1], u[2], thrust_magnitude(u)])


def thrust_norm(u):
    """|u| of a thrust control u = [u_0, u_1, u_2, ...]: the prepared magnitude u[3] of a
    ``thrust_dynamics`` right-hand side (exact, also where the exact fuel form hands it
    u_max s at s = 0), else the regularised ``thrust_magnitude``. A mass flow written with it
    is what the exact fuel end game needs (``throttle``)."""
    return u[3] if len(u) > 3 else thrust_magnitude(u)


def thrust_dynamics(rhs, **options) -> Dynamics:
    """A user's right-hand side rhs(t, x, u) whose first three control components are a thrust
    vector, declared as such: the integrators hand it u = [u_0, u_1, u_2, |u|]
    (``with_thrust_magnitude``) and its mass flow reads ``thrust_norm(u)``. A problem built on
    it with a thrust bound (``Problem.u_max``) and a fuel cost (``fuel.FuelStageCost``, e.g.
    ``pseudo_huber_stage_cost``) has the exact fuel form: a fuel-optimal solve ends at the
    bang-bang optimum, as the catalogue's models do (docs/library.md). ``options``: the other
    ``Dynamics`` fields (``scalar_components``, ``max_step``)."""
    return Dynamics(rhs, prepare_control=with_thrust_magnitude, **options)


def _indexed(rhs, max_step: float | None = None) -> Dynamics:
    """A right-hand side below: it reads x and u by index only, and takes the prepared
    control of ``with_thrust_magnitude``."""
    return thrust_dynamics(rhs, scalar_components=True, max_step=max_step)


# The Sundman-transformed model's step bound [rad of true longitude]: one RK78 step of 2 pi / 10
# keeps a ballistic orbit's period to round-off (~1e-15 relative) up to e = 0.3, and to 2e-6
# at e = 0.725 (a GTO), where 2 pi / 32 is needed (measured; the time is nearly a quadrature in
# L, which RK78's error estimate does not see: ``Dynamics.max_step``). Eccentric transfers take
# stages of at most 2 pi / 32 from their case files; the bound keeps long integrations outside
# a solve (checks, tests) from striding over whole orbits.
SUNDMAN_MAX_STEP = 2 * math.pi / 10


def double_integrator_step(x, u, dt):
    """Discrete double integrator (paper eq. 17) as the reference code steps it: explicit Euler.

    x = [r (3), v (3)], u = acceleration (3), dt = stage length; r+ = r + v dt, v+ = v + u dt.
    """
    return dm.stack([x[0] + x[3] * dt, x[1] + x[4] * dt, x[2] + x[5] * dt,
                     x[3] + u[0] * dt, x[4] + u[1] * dt, x[5] + u[2] * dt])


def two_body(gm: float, exhaust_speed: float):
    """Sun-centred two-body problem with mass (paper eq. 18), Cartesian, normalised. Scalar
    components, as ``cr3bp`` (why: see there)."""
    inv_c = -1.0 / exhaust_speed

    def rhs(t, x, u):
        k = (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]) ** -1.5 * gm   # gm / r^3
        inv_m = 1.0 / x[6]
        return dm.vector([x[3], x[4], x[5], u[0] * inv_m - x[0] * k, u[1] * inv_m - x[1] * k,
                         u[2] * inv_m - x[2] * k, thrust_norm(u) * inv_c])
    return _indexed(rhs)


def cr3bp(mu: float, exhaust_speed: float):
    """Earth-Moon circular restricted three-body problem with mass (paper eq. 19).

    Rotating barycentric frame; primaries at (-mu, 0, 0) and (1 - mu, 0, 0). Written on scalar
    components: on one float state every operation is a scalar operation (small stacked arrays
    cost an order of magnitude more per operation), and on DA the
    product count is within a few of a stacked form.
    """
    gm1, gm2 = 1.0 - mu, mu
    inv_c = -1.0 / exhaust_speed

    def rhs(t, x, u):
        px, py, pz = x[0], x[1], x[2]
        d1, d2 = px + mu, px + (mu - 1.0)         # x offsets from the Earth and the Moon
        yz2 = py * py + pz * pz
        k1 = (d1 * d1 + yz2) ** -1.5 * gm1        # (1 - mu) / r1^3
        k2 = (d2 * d2 + yz2) ** -1.5 * gm2        # mu / r2^3
        ksum = k1 + k2
        inv_m = 1.0 / x[6]
        ax = x[4] * 2.0 + px - d1 * k1 - d2 * k2 + u[0] * inv_m
        ay = x[3] * -2.0 + py - py * ksum + u[1] * inv_m
        az = u[2] * inv_m - pz * ksum
        return dm.vector([x[3], x[4], x[5], ax, ay, az, thrust_norm(u) * inv_c])
    return _indexed(rhs)


def equinoctial(gm: float, exhaust_speed: float):
    """Earth-centred Gauss equations in equinoctial elements with mass (paper eqs. 20-21).

    x = [a, p, q, r, s, L, m] with p = e sin(Om + om), q = e cos(Om + om), r = tan(i/2) sin Om,
    s = tan(i/2) cos Om; u = thrust in the radial / transverse / normal frame.

    The paper's printed eq. 20 is garbled in two places; this follows the standard form it
    derives from: dL/dt = sqrt(mu / a^3) Psi^2 / B^3 - sqrt(a / mu) B / Psi (r cos L - s sin L) f_N
    (the paper prints sqrt(mu / a) and sqrt(a^3 / mu), which are not dimensionally consistent).
    """
    def rhs(t, x, u):
        a, p, q, r, s, L, m = x[0], x[1], x[2], x[3], x[4], x[5], x[6]
        inv_m = 1.0 / m
        fr, ft, fn = u[0] * inv_m, u[1] * inv_m, u[2] * inv_m
        sL, cL = dm.sin(L), dm.cos(L)
        B = dm.sqrt(1.0 - p * p - q * q)
        psi = 1.0 + p * sL + q * cL
        inv_psi = 1.0 / psi
        sam = dm.sqrt(a * (1.0 / gm))  # sqrt(a / mu)
        rc = r * cL - s * sL
        g = 1.0 + r * r + s * s
        da_ = a * sam * 2.0 / B * ((q * sL - p * cL) * fr + psi * ft)
        dp = B * sam * (-cL * fr + ((p + sL) * inv_psi + sL) * ft - q * rc * inv_psi * fn)
        dq = B * sam * (sL * fr + ((q + cL) * inv_psi + cL) * ft + p * rc * inv_psi * fn)
        dr = B * sam * g * sL * inv_psi * fn * 0.5
        ds = B * sam * g * cL * inv_psi * fn * 0.5
        dL = psi * psi / (B * B * B * a * sam) - B * sam * inv_psi * rc * fn
        return dm.vector([da_, dp, dq, dr, ds, dL, thrust_norm(u) * (-1.0 / exhaust_speed)])
    return _indexed(rhs)


def equinoctial_sundman(gm: float, exhaust_speed: float, j2: float = 0.0, j2_radius: float = 0.0):
    """Earth-centred Gauss equations in modified equinoctial elements with the true longitude L
    as the independent variable (a Sundman transformation, dt = dL / Ldot): rhs(L, x, u) = dx/dL.

    x = [p, f, g, h, k, t, m]: the semi-latus rectum p, f = e cos(Om + om), g = e sin(Om + om),
    h = tan(i/2) cos Om, k = tan(i/2) sin Om (Walker et al. 1985), the time t and the mass; u =
    thrust in the radial / transverse / normal frame. L leaves the state: an integration gives
    it as its independent variable, a float (or a (B,) array over a batch of stages) even inside
    a DA expansion, so its sine and cosine are float operations.

    Ldot is the full rate, sqrt(gm p) (w / p)^2 + sqrt(p / gm) (h sin L - k cos L) a_n / w with
    w = 1 + f cos L + g sin L, so L stays the true longitude under normal thrust (the Keplerian
    term alone, as in some Sundman transformations, would make it a neighbouring angle). Equal
    stages in L are equal arcs of the orbit: for a near-circular orbit near-equal durations
    that one RK78 step integrates, for an eccentric one short near perigee where the dynamics
    are fast, which equal stages in time are not.

    ``j2`` > 0 adds the Earth's oblateness (zonal harmonic J2 with its reference radius
    ``j2_radius``, in the units of p) to the thrust acceleration, in RTN (Betts, Practical
    Methods for Optimal Control, 2nd ed., sec. 6.3): with r = p / w, hk as below, s2 = 1 + h^2 +
    k^2 and C = -3/2 gm J2 R^2 / r^4, a_r = C (1 - 12 hk^2 / s2^2), a_t = 8 C hk (h cos L + k sin
    L) / s2^2, a_n = 4 C (1 - h^2 - k^2) hk / s2^2 -- the gradient of the J2 potential in the
    orbit's frame, the Earth's axis along z of the elements' inertial frame.
    """
    inv_sqrt_gm = gm ** -0.5
    inv_c = -1.0 / exhaust_speed
    j2c = -1.5 * gm * j2 * j2_radius ** 2

    def rhs(L, x, u):
        p, h, k, m = x[0], x[3], x[4], x[6]
        sL, cL = dm.sin(L), dm.cos(L)
        inv_m = 1.0 / m
        ar, at, an = u[0] * inv_m, u[1] * inv_m, u[2] * inv_m
        if j2c:
            w = 1.0 + x[1] * cL + x[2] * sL
            wp = w * (1.0 / p)                     # 1 / r
            c = wp * wp * (wp * wp) * j2c          # -3/2 gm J2 R^2 / r^4
            hk = h * sL - k * cL
            inv_s2 = 1.0 / (1.0 + h * h + k * k)
            c_hk = c * hk * (inv_s2 * inv_s2)      # C hk / s2^2
            ar = ar + c - c_hk * hk * 12.0
            at = at + c_hk * (h * cL + k * sL) * 8.0
            an = an + c_hk * (1.0 - h * h - k * k) * 4.0
        rates, tau = _gauss_sundman(x, sL, cL, ar, at, an, inv_sqrt_gm)
        return dm.vector([*rates, thrust_norm(u) * inv_c * tau])
    return _indexed(rhs, SUNDMAN_MAX_STEP)


def _gauss_sundman(x, sL, cL, ar, at, an, inv_sqrt_gm: float):
    """The Gauss equations of the modified equinoctial elements and the time with the true
    longitude as the independent variable: ([dp, df, dg, dh, dk, dt] / dL, dt/dL) under the
    RTN acceleration (ar, at, an), x = [p, f, g, h, k, ...], sL, cL = sin L, cos L."""
    p, f, g, h, k = x[0], x[1], x[2], x[3], x[4]
    w = 1.0 + f * cL + g * sL
    inv_w = 1.0 / w
    sq = dm.sqrt(p) * inv_sqrt_gm     # sqrt(p / gm)
    hk = h * sL - k * cL
    s2 = 1.0 + h * h + k * k
    at_w, an_w = at * inv_w, an * inv_w
    # dt/dL = 1 / Ldot; Ldot = sqrt(gm / p^3) w^2 + sqrt(p / gm) hk a_n / w
    tau = 1.0 / (w * w * (1.0 / (sq * p)) + sq * hk * an_w)
    sqt = sq * tau
    an_half = an_w * s2 * 0.5 * sqt
    return [p * at_w * 2.0 * sqt,
            (ar * sL + ((w + 1.0) * cL + f) * at_w - g * hk * an_w) * sqt,
            (((w + 1.0) * sL + g) * at_w - ar * cL + f * hk * an_w) * sqt,
            an_half * cL,
            an_half * sL,
            tau], tau


def mee_frame(x, sL, cL):
    """The orbit's position r = (p / w) r_hat and its radial, transverse and normal unit
    vectors in the inertial frame, from modified equinoctial elements x = [p, f, g, h, k, ...]
    at true longitude L (sL, cL its sine and cosine; Walker et al. 1985): (r, r_hat, t_hat,
    n_hat), each a list of 3 components (floats, arrays or DA)."""
    p, f, g, h, k = x[0], x[1], x[2], x[3], x[4]
    inv_s2 = 1.0 / (1.0 + h * h + k * k)
    a2, hk2 = h * h - k * k, 2.0 * h * k
    r_hat = [(cL + a2 * cL + hk2 * sL) * inv_s2, (sL - a2 * sL + hk2 * cL) * inv_s2,
             (h * sL - k * cL) * (2.0 * inv_s2)]
    n_hat = [k * (2.0 * inv_s2), h * (-2.0 * inv_s2), (1.0 - h * h - k * k) * inv_s2]
    t_hat = [n_hat[1] * r_hat[2] - n_hat[2] * r_hat[1], n_hat[2] * r_hat[0] - n_hat[0] * r_hat[2],
             n_hat[0] * r_hat[1] - n_hat[1] * r_hat[0]]
    radius = p / (1.0 + f * cL + g * sL)
    return [radius * c for c in r_hat], r_hat, t_hat, n_hat


def rtn_basis(r, v) -> np.ndarray:
    """(3, 3) columns: the radial, transverse and normal unit vectors of the osculating orbit
    of position r and velocity v (3,) (floats): an RTN vector w is ``rtn_basis(r, v) @ w`` in
    the inertial frame."""
    r, v = np.asarray(r, float), np.asarray(v, float)
    h = np.cross(r, v)
    radial, normal = r / np.linalg.norm(r), h / np.linalg.norm(h)
    return np.column_stack([radial, np.cross(normal, radial), normal])


def earth_cartesian(gm: float, exhaust_speed: float, j2: float = 0.0, j2_radius: float = 0.0):
    """The Earth-centred problem in Cartesian coordinates and in time, rhs(t, x, u): x = [r (3),
    v (3), m] in the inertial frame of the equinoctial elements, u the thrust in RTN (as
    ``equinoctial_sundman`` takes it), J2 as the gradient of the zonal potential, -3/2 J2 gm
    R^2 / r^5 [x (1 - 5 z^2/r^2), y (1 - 5 z^2/r^2), z (3 - 5 z^2/r^2)]. What the guidance
    loop propagates between estimates (the Sundman model's independent variable is the true
    longitude, an estimate's is the time); written by component like the other models, so it
    also takes arrays and DA."""
    inv_c = -1.0 / exhaust_speed
    j2c = -1.5 * gm * j2 * j2_radius ** 2

    def rhs(t, x, u):
        # Component by component (no numpy calls on floats: this runs at every step of every
        # prediction), the RTN axes as rtn_basis builds them: radial r / |r|, normal h / |h|,
        # transverse (h x r) / (|h| |r|).
        x0, x1, x2, v0, v1, v2 = x[0], x[1], x[2], x[3], x[4], x[5]
        rn2 = x0 * x0 + x1 * x1 + x2 * x2
        inv_r = 1.0 / dm.sqrt(rn2)
        h0, h1, h2 = x1 * v2 - x2 * v1, x2 * v0 - x0 * v2, x0 * v1 - x1 * v0
        inv_h = 1.0 / dm.sqrt(h0 * h0 + h1 * h1 + h2 * h2)
        inv_m = 1.0 / x[6]
        ur, un = u[0] * inv_r * inv_m, u[2] * inv_h * inv_m
        ut = u[1] * inv_r * inv_h * inv_m
        grav = -gm * inv_r * inv_r * inv_r
        a0 = x0 * (grav + ur) + (h1 * x2 - h2 * x1) * ut + h0 * un
        a1 = x1 * (grav + ur) + (h2 * x0 - h0 * x2) * ut + h1 * un
        a2 = x2 * (grav + ur) + (h0 * x1 - h1 * x0) * ut + h2 * un
        if j2c:
            inv_r2 = inv_r * inv_r
            z2 = x2 * x2 * inv_r2
            c = j2c * inv_r2 * inv_r2 * inv_r
            a0 = a0 + c * x0 * (1.0 - 5.0 * z2)
            a1 = a1 + c * x1 * (1.0 - 5.0 * z2)
            a2 = a2 + c * x2 * (3.0 - 5.0 * z2)
        return dm.vector([v0, v1, v2, a0, a1, a2, thrust_norm(u) * inv_c])
    return _indexed(rhs)


def keplerian_to_equinoctial(a, e, i_rad, raan_rad, argp_rad, nu_rad):
    """Keplerian elements -> [a, p, q, r, s, L] (paper eq. 21), true longitude L: the modified
    elements' f, g, h, k in the paper's order and names (p = g, q = f, r = k, s = h)."""
    (_, f, g, h, k), L = keplerian_to_mee(a, e, i_rad, raan_rad, argp_rad, nu_rad)
    return np.array([a, g, f, k, h, L])


def keplerian_to_mee(a, e, i_rad, raan_rad, argp_rad, nu_rad):
    """Keplerian elements -> modified equinoctial [p, f, g, h, k] (5,) and the true longitude L."""
    lp = raan_rad + argp_rad
    t = np.tan(i_rad / 2.0)
    return (np.array([a * (1.0 - e * e), e * np.cos(lp), e * np.sin(lp), t * np.cos(raan_rad),
                      t * np.sin(raan_rad)]), float(lp + nu_rad))


def mee_to_cartesian(mee, L, gm: float) -> np.ndarray:
    """Modified equinoctial [p, f, g, h, k] at true longitude L -> position and velocity (6,)
    (Walker et al. 1985; Betts), in the units of p with gravitational parameter gm; element-wise
    on arrays: mee (5, K) and L (K,) give (6, K)."""
    p, f, g, h, k = mee[:5]
    alpha2 = h * h - k * k
    s2 = 1.0 + h * h + k * k
    cL, sL = np.cos(L), np.sin(L)
    rad = p / (1.0 + f * cL + g * sL)
    pos = rad / s2 * np.array([cL + alpha2 * cL + 2 * h * k * sL,
                               sL - alpha2 * sL + 2 * h * k * cL,
                               2 * (h * sL - k * cL)])
    c = np.sqrt(gm / p) / s2
    vel = -c * np.array([sL + alpha2 * sL - 2 * h * k * cL + g - 2 * f * h * k + alpha2 * g,
                         -cL + alpha2 * cL + 2 * h * k * sL - f + 2 * g * h * k + alpha2 * f,
                         -2 * (h * cL + k * sL + f * h + g * k)])
    return np.concatenate([pos, vel])


def cartesian_to_mee(rv, gm: float):
    """Position and velocity (6,) -> modified equinoctial [p, f, g, h, k] (5,) and the true
    longitude L in [0, 2 pi), the inverse of ``mee_to_cartesian`` (prograde elements: singular
    for a retrograde equatorial orbit only)."""
    r, v = np.asarray(rv[:3], float), np.asarray(rv[3:6], float)
    hv = np.cross(r, v)
    hn = np.linalg.norm(hv)
    rn = np.linalg.norm(r)
    p = hn * hn / gm
    hx, hy, hz = hv / hn
    h, k = -hy / (1.0 + hz), hx / (1.0 + hz)
    # the equinoctial frame's unit vectors
    s2 = 1.0 + h * h + k * k
    fhat = np.array([1.0 - k * k + h * h, 2 * k * h, -2 * k]) / s2
    ghat = np.array([2 * k * h, 1.0 + k * k - h * h, 2 * h]) / s2
    evec = np.cross(v, hv) / gm - r / rn
    f, g = evec @ fhat, evec @ ghat
    L = np.arctan2(r @ ghat, r @ fhat) % (2 * np.pi)
    return np.array([p, f, g, h, k]), float(L)


def equinoctial_to_cartesian(x, gm: float):
    """[a, p, q, r, s, L] -> position and velocity (6,), for plotting and checks; gm in the
    units of a (no default: in the catalogue's Earth units it is 4 pi^2, not 1)."""
    a, p, q, r, s, L = x[:6]
    # the modified elements of Walker et al.: f = q, g = p, h = s (cos), k = r (sin)
    return mee_to_cartesian([a * (1.0 - p * p - q * q), q, p, s, r], L, gm)
