"""Perturbing accelerations of an Earth-centred orbit in the inertial frame (ECI, the Earth's
axis along z), written once for floats, arrays and DA: the Earth's zonal harmonics J2-J4 and
the third-body gravity of a point mass (the Sun, the Moon). Positions (3, *batch) in any length
unit shared with the radius and gravitational parameters given."""
from __future__ import annotations

from ..da import functions as dm


def zonal_acceleration(r, gm: float, radius: float, j2: float = 0.0, j3: float = 0.0,
                       j4: float = 0.0):
    """The acceleration (a list of 3 components) of the zonal harmonics J2, J3, J4 at ECI position r: the
    gradient of -gm/r sum_n J_n (R/r)^n P_n(z/r) (Vallado, Fundamentals of Astrodynamics, 4th
    ed., eq. 8-30 and its J3, J4 companions)."""
    x, y, z = r[0], r[1], r[2]
    r2 = x * x + y * y + z * z
    inv_r = 1.0 / dm.sqrt(r2)
    u = z * inv_r                          # z / r = sin(latitude)
    s = u * u
    mu_r3 = gm * inv_r * inv_r * inv_r     # gm / r^3
    rr = radius * inv_r                    # R / r
    fxy = fz = az = 0.0 * x                # a = [fxy x, fxy y, fz z + az]
    if j2:
        c = -1.5 * j2 * mu_r3 * rr * rr
        fxy = fxy + c * (1.0 - 5.0 * s)
        fz = fz + c * (3.0 - 5.0 * s)
    if j3:
        c = -2.5 * j3 * mu_r3 * rr * rr * rr
        fxy = fxy + c * u * (3.0 - 7.0 * s)
        az = az + c * (u * z * (6.0 - 7.0 * s) - 0.6 * r2 * inv_r)
    if j4:
        c = 1.875 * j4 * mu_r3 * rr * rr * rr * rr
        fxy = fxy + c * (1.0 - 14.0 * s + 21.0 * s * s)
        fz = fz + c * (5.0 - (70.0 / 3.0) * s + 21.0 * s * s)
    return [fxy * x, fxy * y, fz * z + az]


def third_body_acceleration(r, r_body, gm_body: float):
    """The tidal acceleration (a list of 3 components) of a point mass gm_body at r_body on a spacecraft at r,
    both from the Earth's centre: gm_body ((r_body - r) / |r_body - r|^3 - r_body / |r_body|^3)."""
    d = [r_body[i] - r[i] for i in range(3)]
    d2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
    b2 = r_body[0] * r_body[0] + r_body[1] * r_body[1] + r_body[2] * r_body[2]
    cd = gm_body / (d2 * dm.sqrt(d2))
    cb = gm_body / (b2 * dm.sqrt(b2))
    return [cd * d[i] - cb * r_body[i] for i in range(3)]
