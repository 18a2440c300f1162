"""Low-precision analytic ephemerides of the Sun and the Moon (Montenbruck & Gill, Satellite
Orbits, sec. 3.3.2), geocentric, in the Earth's mean equator and equinox of J2000 (EME2000),
written once for floats, arrays and DA: the time may be a state of the problem (the Sundman-
staged sail), so that the Sun direction and the Moon move with it.

Time: seconds since J2000 (2000-01-01 12:00 TT; TT ~ UTC + 69 s, below the series' accuracy).
Accuracy over 1950-2050: the Sun ~0.1-1 % in distance and 0.01 deg in direction, the Moon
several arcminutes and ~500 km. ``RANGE_S`` is the span where the series hold; a caller checks
its epochs against it (``check_epoch``).
"""
from __future__ import annotations

import math

from ..da import functions as dm
from ..errors import DaddyError

# obliquity of the ecliptic at J2000 (Montenbruck & Gill, eq. 3.43)
OBLIQUITY_RAD = math.radians(23.43929111)
JULIAN_CENTURY_S = 36525.0 * 86400.0
# the series' span: 1950-2050 (Montenbruck & Gill state their accuracy over it)
RANGE_S = (-50.0 * 365.25 * 86400.0, 50.0 * 365.25 * 86400.0)
_ARCSEC = math.pi / (180.0 * 3600.0)


def check_epoch(t_s: float, name: str) -> None:
    """A DaddyError naming ``name`` when t_s [s since J2000] is outside the series' span."""
    if not (isinstance(t_s, (int, float)) and math.isfinite(t_s)
            and RANGE_S[0] <= t_s <= RANGE_S[1]):
        raise DaddyError(f"{name} must lie within 1950-2050 (the low-precision Sun and Moon "
                         f"ephemerides' span), got {t_s!r} s from J2000")


def _equatorial(r, lon, lat):
    """Ecliptic spherical (r, longitude, latitude) -> EME2000 Cartesian (3, *batch)."""
    ce, se = math.cos(OBLIQUITY_RAD), math.sin(OBLIQUITY_RAD)
    cb = dm.cos(lat)
    x, y, z = r * dm.cos(lon) * cb, r * dm.sin(lon) * cb, r * dm.sin(lat)
    return dm.stack([x, y * ce - z * se, y * se + z * ce])


def sun_position_km(t_s):
    """The Sun's geocentric position [km] (3, *batch) at t_s seconds since J2000 (eq. 3.44-3.46):
    mean anomaly M, ecliptic longitude 282.94 deg + M + 6892" sin M + 72" sin 2M, latitude 0."""
    T = t_s * (1.0 / JULIAN_CENTURY_S)
    M = math.radians(357.5256) + math.radians(35999.049) * T
    lon = (math.radians(282.9400) + M + (6892.0 * _ARCSEC) * dm.sin(M)
           + (72.0 * _ARCSEC) * dm.sin(2.0 * M))
    r = (149.619 - 2.499 * dm.cos(M) - 0.021 * dm.cos(2.0 * M)) * 1e6
    return _equatorial(r, lon, 0.0 * lon)


def moon_position_km(t_s):
    """The Moon's geocentric position [km] (3, *batch) at t_s seconds since J2000 (eq. 3.47-3.48:
    Brown's theory's leading terms in longitude, latitude and distance)."""
    T = t_s * (1.0 / JULIAN_CENTURY_S)
    two_pi = 2.0 * math.pi
    L0 = two_pi * (0.606433 + 1336.851344 * T)      # mean longitude
    l = two_pi * (0.374897 + 1325.552410 * T)       # the Moon's mean anomaly
    lp = two_pi * (0.993133 + 99.997361 * T)        # the Sun's mean anomaly
    D = two_pi * (0.827361 + 1236.853086 * T)       # the Moon's elongation
    F = two_pi * (0.259086 + 1342.227825 * T)       # argument of latitude
    s = dm.sin
    dL = (22640.0 * s(l) - 4586.0 * s(l - 2.0 * D) + 2370.0 * s(2.0 * D) + 769.0 * s(2.0 * l)
          - 668.0 * s(lp) - 412.0 * s(2.0 * F) - 212.0 * s(2.0 * l - 2.0 * D)
          - 206.0 * s(l + lp - 2.0 * D) + 192.0 * s(l + 2.0 * D) - 165.0 * s(lp - 2.0 * D)
          - 125.0 * s(D) - 110.0 * s(l + lp) + 148.0 * s(l - lp) - 55.0 * s(2.0 * F - 2.0 * D))
    lon = L0 + dL * _ARCSEC
    S = F + (dL + 412.0 * s(2.0 * F) + 541.0 * s(lp)) * _ARCSEC
    h = F - 2.0 * D
    N = (-526.0 * s(h) + 44.0 * s(l + h) - 31.0 * s(h - l) - 23.0 * s(lp + h)
         + 11.0 * s(h - lp) - 25.0 * s(F - 2.0 * l) + 21.0 * s(F - l))
    lat = (18520.0 * s(S) + N) * _ARCSEC
    c = dm.cos
    r = (385000.0 - 20905.0 * c(l) - 3699.0 * c(2.0 * D - l) - 2956.0 * c(2.0 * D)
         - 570.0 * c(2.0 * l) + 246.0 * c(2.0 * l - 2.0 * D) - 205.0 * c(lp - 2.0 * D)
         - 171.0 * c(l + 2.0 * D) - 152.0 * c(l + lp - 2.0 * D))
    return _equatorial(r, lon, lat)
