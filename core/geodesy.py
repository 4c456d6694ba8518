"""The project's one geodesy: WGS-84 latitude/longitude <-> local ENU metres, distances, magnetic declination.

Everything that turns degrees of latitude/longitude into metres (or back)
goes through this module: the exports (:mod:`core.export`), the benchmark's
dataset readers (landmarks, GPS tracks) and the desktop tools.

Local tangent plane
    The local East-North-Up frame of :mod:`core` is the tangent plane of the
    WGS-84 ellipsoid at ``origin = (lat0, lon0)`` (degrees, height 0):
    :func:`geodetic_to_enu` is the exact geodetic -> ECEF -> ENU rotation of
    the maintained pure-Python package ``pymap3d`` (a point on the ellipsoid,
    height 0; the small "up" of a distant point is dropped), and
    :func:`enu_to_geodetic` its inverse for points on the ellipsoid (the "up"
    that puts the point back on the ellipsoid is found in two iterations; the
    ENU -> geodetic step is computed here, checked against pymap3d), so
    the two invert each other to well below a millimetre.  Horizontal distances
    in this plane are the ellipsoid's to a millimetre over 5 km (the chord
    shortens by d^3 / 6R^2).  It replaced a flat "radii of curvature at the
    origin" plane (issue #9), which was exact only near the origin: its east
    scale is wrong by ``north / R * tan(lat)``, 0.14 % 5 km north of the
    origin at 60 deg (3.8 m), a tenth of a 1 %-of-distance outage budget.
    ``pymap3d`` is imported on first use, like ``pygeomag``; longitudes come
    back in [-180, 180], so a walk across the antimeridian stays in one piece.

Distance
    :func:`distance_m` is the geodesic distance on the ellipsoid (Vincenty's
    inverse formula, 1975), millimetre-accurate; for the short distances of a
    walk it agrees with the tangent plane to well below a centimetre.

Magnetic declination
    :func:`declination_rad` evaluates the World Magnetic Model (WMM2010 to
    WMM2025, the model whose five-year span contains the date) with the
    pure-Python package ``pygeomag`` (imported only when called, so that
    ``core`` keeps numpy as its only hard dependency; python-for-android
    installs it on the phone from ``buildozer.spec``).  Declination is east of
    true north positive: a compass bearing becomes a true bearing by adding it,
    a heading counter-clockwise from East (:mod:`core`'s ``heading_rad``) by
    subtracting it.
"""

from __future__ import annotations

import datetime as _dt
import math
from functools import lru_cache

import numpy as np

#: WGS-84 semi-major axis (m) and flattening
WGS84_A_M = 6378137.0
WGS84_F = 1.0 / 298.257223563
#: WGS-84 first eccentricity squared, ``f (2 - f)``
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)
#: WGS-84 semi-minor axis (m)
WGS84_B_M = WGS84_A_M * (1.0 - WGS84_F)


def radii_of_curvature(lat_deg: float) -> tuple[float, float]:
    """Meridian and prime-vertical radii of curvature ``(M, N)`` (m) at a geodetic latitude."""
    s = math.sin(math.radians(lat_deg))
    d = 1.0 - WGS84_E2 * s * s
    return WGS84_A_M * (1.0 - WGS84_E2) / d ** 1.5, WGS84_A_M / math.sqrt(d)


def _wrap_deg(d):
    """Degrees to [-180, 180]; values already there are returned unchanged (bit for bit)."""
    d = np.asarray(d, dtype=float)
    return np.where(np.abs(d) <= 180.0, d, (d + 180.0) % 360.0 - 180.0)


def _out(x):
    """Scalars in, Python floats out; arrays in, arrays out."""
    x = np.asarray(x, dtype=float)
    return float(x) if x.ndim == 0 else x


@lru_cache(maxsize=1)
def _pymap3d():
    try:
        import pymap3d  # noqa: PLC0415 - pure Python; imported on first use, like pygeomag
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise RuntimeError("WGS-84 <-> ENU needs the pure-Python package pymap3d: pip install pymap3d") from e
    return pymap3d


def geodetic_to_enu(lat_deg, lon_deg, origin_lat_lon: tuple[float, float]):
    """(lat_deg, lon_deg) on the ellipsoid -> local ``(east_m, north_m)`` about ``origin_lat_lon`` (scalars or arrays)."""
    lat0, lon0 = (float(v) for v in origin_lat_lon)
    lat = np.asarray(lat_deg, dtype=float)
    lon = np.asarray(lon_deg, dtype=float)
    east, north, _ = _pymap3d().geodetic2enu(lat, lon, np.zeros(lat.shape), lat0, lon0, 0.0)
    return _out(east), _out(north)


class _Scalar:
    """The math functions of :func:`_enu_to_geodetic` for Python floats (numpy's cost ~1 us a call each)."""
    sin, cos, sqrt, atan2, hypot, degrees = math.sin, math.cos, math.sqrt, math.atan2, math.hypot, math.degrees


class _Array:
    """... and for arrays."""
    sin, cos, sqrt, atan2, hypot, degrees = np.sin, np.cos, np.sqrt, np.arctan2, np.hypot, np.degrees


@lru_cache(maxsize=8)
def _origin_frame(lat0_deg: float, lon0_deg: float) -> tuple:
    """The origin's ``(sin lat, cos lat, sin lon, cos lon)`` and ECEF position (m): the same for every point of
    a walk, so computed once per origin, not per point."""
    la, lo = math.radians(lat0_deg), math.radians(lon0_deg)
    sla, cla, slo, clo = math.sin(la), math.cos(la), math.sin(lo), math.cos(lo)
    n0 = WGS84_A_M / math.sqrt(1.0 - WGS84_E2 * sla * sla)
    return sla, cla, slo, clo, n0 * cla * clo, n0 * cla * slo, n0 * (1.0 - WGS84_E2) * sla


def _enu_to_geodetic(e, n, up, lat0_deg: float, lon0_deg: float, xp):
    """ENU (m) about a point on the ellipsoid -> geodetic ``(lat_rad, lon_rad, h_m)``: the ENU -> ECEF rotation,
    then the fixed-point iteration ``lat = atan2(z + e2 N sin(lat), p)`` (Bowring's start, 5 iterations: 1e-15
    rad at heights below 10 km).  Written once for floats and arrays (``xp``); tested against pymap3d."""
    sla, cla, slo, clo, x0, y0, z0 = _origin_frame(lat0_deg, lon0_deg)
    t = cla * up - sla * n  # the origin's ENU axes in ECEF
    x = x0 + clo * t - slo * e
    y = y0 + slo * t + clo * e
    z = z0 + sla * up + cla * n
    p = xp.hypot(x, y)
    lat = xp.atan2(z, p * (1.0 - WGS84_E2))
    for _ in range(5):
        s = xp.sin(lat)
        lat = xp.atan2(z + WGS84_E2 * WGS84_A_M / xp.sqrt(1.0 - WGS84_E2 * s * s) * s, p)
    s = xp.sin(lat)
    h = p * xp.cos(lat) + z * s - WGS84_A_M * xp.sqrt(1.0 - WGS84_E2 * s * s)
    return lat, xp.atan2(y, x), h


def enu_to_geodetic(east_m, north_m, origin_lat_lon: tuple[float, float]):
    """Local ``(east_m, north_m)`` about ``origin_lat_lon`` -> (lat_deg, lon_deg) of the point on the ellipsoid.

    The inverse of :func:`geodetic_to_enu` (pymap3d) computed here, not by pymap3d: its per-call overhead (three
    calls, about 0.5 ms a point) was the GPS fusion's largest cost per step on the phone.  The two agree to
    1e-10 degrees (a test compares them)."""
    lat0, lon0 = (float(v) for v in origin_lat_lon)
    scalar = np.ndim(east_m) == 0 and np.ndim(north_m) == 0
    xp = _Scalar if scalar else _Array
    e, n = (float(east_m), float(north_m)) if scalar else (np.asarray(east_m, dtype=float),
                                                          np.asarray(north_m, dtype=float))
    m, nn = radii_of_curvature(lat0)
    up = -(e * e + n * n) / (2.0 * math.sqrt(m * nn))  # the ellipsoid below the tangent plane
    for _ in range(2):
        up = up - _enu_to_geodetic(e, n, up, lat0, lon0, xp)[2]
    lat, lon, _ = _enu_to_geodetic(e, n, up, lat0, lon0, xp)
    return _out(xp.degrees(lat)), _out(_wrap_deg(xp.degrees(lon)))


def distance_m(lat1_deg: float, lon1_deg: float, lat2_deg: float, lon2_deg: float) -> float:
    """Geodesic distance (m) between two points on the WGS-84 ellipsoid (Vincenty's inverse formula).

    Converges to 1e-12 rad; for nearly antipodal points, where Vincenty's
    iteration may not converge, it raises ``ValueError``.
    """
    a, b, f = WGS84_A_M, WGS84_B_M, WGS84_F
    lam0 = math.radians(float(_wrap_deg(lon2_deg - lon1_deg)))
    u1 = math.atan((1.0 - f) * math.tan(math.radians(lat1_deg)))
    u2 = math.atan((1.0 - f) * math.tan(math.radians(lat2_deg)))
    su1, cu1, su2, cu2 = math.sin(u1), math.cos(u1), math.sin(u2), math.cos(u2)
    lam = lam0
    for _ in range(200):
        sl, cl = math.sin(lam), math.cos(lam)
        sin_s = math.hypot(cu2 * sl, cu1 * su2 - su1 * cu2 * cl)
        if sin_s == 0.0:
            return 0.0  # coincident points
        cos_s = su1 * su2 + cu1 * cu2 * cl
        sigma = math.atan2(sin_s, cos_s)
        sin_alpha = cu1 * cu2 * sl / sin_s
        cos2_alpha = 1.0 - sin_alpha * sin_alpha
        cos_2sm = cos_s - 2.0 * su1 * su2 / cos2_alpha if cos2_alpha != 0.0 else 0.0  # equatorial line
        c = f / 16.0 * cos2_alpha * (4.0 + f * (4.0 - 3.0 * cos2_alpha))
        lam_prev = lam
        lam = lam0 + (1.0 - c) * f * sin_alpha * (
            sigma + c * sin_s * (cos_2sm + c * cos_s * (-1.0 + 2.0 * cos_2sm * cos_2sm)))
        if abs(lam - lam_prev) < 1e-12:
            break
    else:
        raise ValueError("distance_m: Vincenty's formula did not converge (nearly antipodal points)")
    u_sq = cos2_alpha * (a * a - b * b) / (b * b)
    big_a = 1.0 + u_sq / 16384.0 * (4096.0 + u_sq * (-768.0 + u_sq * (320.0 - 175.0 * u_sq)))
    big_b = u_sq / 1024.0 * (256.0 + u_sq * (-128.0 + u_sq * (74.0 - 47.0 * u_sq)))
    d_sigma = big_b * sin_s * (cos_2sm + big_b / 4.0 * (
        cos_s * (-1.0 + 2.0 * cos_2sm * cos_2sm)
        - big_b / 6.0 * cos_2sm * (-3.0 + 4.0 * sin_s * sin_s) * (-3.0 + 4.0 * cos_2sm * cos_2sm)))
    return float(b * big_a * (sigma - d_sigma))


# ---------------------------------------------------------------------------
# World Magnetic Model


#: WMM releases in pygeomag: (first year, module, attribute); each is valid for five years
_WMM_MODELS = ((2025.0, "pygeomag.wmm.wmm_2025", "WMM_2025"), (2020.0, "pygeomag.wmm.wmm_2020", "WMM_2020"),
               (2015.0, "pygeomag.wmm.wmm_2015v2", "WMM_2015v2"), (2010.0, "pygeomag.wmm.wmm_2010", "WMM_2010"))


def decimal_year(when) -> float:
    """A date as a decimal year: ``datetime`` (naive = UTC), ``date``, or a number that already is one."""
    if isinstance(when, bool):
        raise TypeError("decimal_year: a date, datetime or decimal year is needed, not a bool")
    if isinstance(when, (int, float)):
        return float(when)
    if isinstance(when, _dt.datetime):
        t = when if when.tzinfo is None else when.astimezone(_dt.timezone.utc).replace(tzinfo=None)
        start = _dt.datetime(t.year, 1, 1)
        length = (_dt.datetime(t.year + 1, 1, 1) - start).total_seconds()
        return t.year + (t - start).total_seconds() / length
    if isinstance(when, _dt.date):
        start = _dt.date(when.year, 1, 1)
        return when.year + (when - start).days / (_dt.date(when.year + 1, 1, 1) - start).days
    raise TypeError(f"decimal_year: a date, datetime or decimal year is needed, got {type(when).__name__}")


def unix_ns_to_datetime(unix_ns: int) -> _dt.datetime:
    """Unix time in nanoseconds -> timezone-aware UTC ``datetime``."""
    return _dt.datetime.fromtimestamp(int(unix_ns) // 1_000_000_000, tz=_dt.timezone.utc) + \
        _dt.timedelta(microseconds=(int(unix_ns) % 1_000_000_000) // 1000)


@lru_cache(maxsize=None)
def _geomag(first_year: float):
    import importlib

    try:
        from pygeomag import GeoMag
    except ImportError as e:
        raise ImportError("core.geodesy needs the pure-Python package 'pygeomag' for the World Magnetic Model "
                          "(pip install pygeomag; on the phone it is in buildozer.spec's requirements)") from e
    for year, module, attr in _WMM_MODELS:
        if year == first_year:
            return GeoMag(coefficients_data=getattr(importlib.import_module(module), attr))
    raise KeyError(first_year)


def magnetic_field(lat_deg: float, lon_deg: float, alt_m: float, when):
    """The WMM main field at a place and date: ``(declination_rad, inclination_rad, total_uT)``.

    ``alt_m`` is the height above the WGS-84 ellipsoid (m; mean sea level is
    close enough for a compass); ``when`` a ``datetime`` (naive = UTC), a
    ``date`` or a decimal year between 2010.0 and 2030.0.  Declination is east
    of true north positive, inclination below the horizontal positive (the
    northern hemisphere's dip).
    """
    year = decimal_year(when)
    model = next((m for m in _WMM_MODELS if m[0] <= year < m[0] + 5.0), None)
    if model is None and 2030.0 <= year < 2030.5:  # NOAA publishes the next model late in the old one's last year
        model = _WMM_MODELS[0]
    if model is None:
        raise ValueError(f"magnetic_field: no World Magnetic Model for the year {year:.2f} (have 2010.0-2030.0)")
    if not (-90.0 <= lat_deg <= 90.0):
        raise ValueError(f"magnetic_field: latitude {lat_deg} is not in [-90, 90] degrees")
    r = _geomag(model[0]).calculate(glat=float(lat_deg), glon=float(_wrap_deg(lon_deg)), alt=float(alt_m) / 1000.0,
                                    time=year, allow_date_outside_lifespan=True)
    return math.radians(r.d), math.radians(r.i), r.f / 1000.0


def declination_rad(lat_deg: float, lon_deg: float, alt_m: float, when) -> float:
    """Magnetic declination (rad, east of true north positive) from the World Magnetic Model (see :func:`magnetic_field`)."""
    return magnetic_field(lat_deg, lon_deg, alt_m, when)[0]
