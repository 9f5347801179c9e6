"""Local NED <-> geodetic conversions exactly as ArduPilot does them (``AP_Common/Location.cpp``).

ArduPilot converts between its EKF origin's local NED frame and latitude/longitude with a spherical
flat-earth approximation: ``LOCATION_SCALING_FACTOR`` metres per 1e-7 degree of latitude and that times
``cos(latitude)`` per 1e-7 degree of longitude. The model uses the same conversion so that a ground
station's or companion's lat/lon and a local NED target land exactly where ArduCopter would put them;
it is also about 300 times cheaper than an ellipsoidal conversion (pymap3d), which matters when
telemetry streams GLOBAL_POSITION_INT at simulation speed. Against WGS84 (pymap3d) the difference is
below 0.4 % of the distance from the origin (tested), i.e. centimetres over the few kilometres a
copter's local frame spans.
"""

from __future__ import annotations

import math

#: metres per 1e-7 degree of latitude (ArduPilot: RADIUS_OF_EARTH 6378100 m)
LOCATION_SCALING_FACTOR = 0.011131884502145034
LOCATION_SCALING_FACTOR_INV = 89.83204953368922
_DEG_PER_M = 1e-7 * LOCATION_SCALING_FACTOR_INV


def longitude_scale(lat_deg: float) -> float:
    """cos(latitude), never below 0.01 (ArduPilot's ``Location::longitude_scale``)."""
    return max(math.cos(math.radians(lat_deg)), 0.01)


#: vehicles in one row of a simulated fleet's homes (the next row is one spacing south of it)
HOMES_PER_ROW = 10


def home_offset(i: int, spacing_m: float) -> tuple[float, float]:
    """(north, east) metres of vehicle ``i``'s home (from 0) from vehicle 0's in a simulated fleet: every
    ``spacing_m`` east, in rows of :data:`HOMES_PER_ROW`, each row ``spacing_m`` south of the previous
    (the bundled model's fleet and ``taskflight up --autopilot arducopter`` alike). Rows keep a large fleet
    inside a platform's operating area: 50 vehicles in one line at 5 m would reach 245 m east, outside the
    bundled platforms' 200 m envelope, where none of their missions would be accepted."""
    row, col = divmod(i, HOMES_PER_ROW)
    return -spacing_m * row, spacing_m * col


def ned_to_geodetic(origin: tuple[float, float, float], n: float, e: float, d: float
                    ) -> tuple[float, float, float]:
    """(lat deg, lon deg, alt m AMSL) of the NED offset (n, e, d) metres from ``origin`` (lat, lon, alt)."""
    lat0, lon0, alt0 = origin
    dlat = n * _DEG_PER_M
    dlon = e * _DEG_PER_M / longitude_scale(lat0 + dlat / 2.0)
    lon = lon0 + dlon
    if lon > 180.0:
        lon -= 360.0
    elif lon < -180.0:
        lon += 360.0
    return (lat0 + dlat, lon, alt0 - d)


def geodetic_to_ned(origin: tuple[float, float, float], lat: float, lon: float, alt: float
                    ) -> tuple[float, float, float]:
    """NED offset (m) of (lat, lon, alt AMSL) from ``origin`` (lat, lon, alt); inverse of the above."""
    lat0, lon0, alt0 = origin
    dlon = lon - lon0
    if dlon > 180.0:
        dlon -= 360.0
    elif dlon < -180.0:
        dlon += 360.0
    n = (lat - lat0) / _DEG_PER_M
    e = dlon / _DEG_PER_M * longitude_scale((lat + lat0) / 2.0)
    return (n, e, alt0 - alt)


def check_point(p: list[float], where: str = "") -> list[float]:
    """A ``[lat, lon]`` or ``[lat, lon, alt]`` of finite numbers with latitude and longitude in range;
    ValueError prefixed with ``where`` (e.g. ``points[3]``) otherwise. For request bodies."""
    prefix = f"{where}: " if where else ""
    if len(p) not in (2, 3) or not all(math.isfinite(v) for v in p):
        raise ValueError(f"{prefix}expected [lat, lon] or [lat, lon, alt] of finite numbers")
    if not (-90.0 <= p[0] <= 90.0 and -180.0 <= p[1] <= 180.0):
        raise ValueError(f"{prefix}latitude or longitude out of range")
    return p
