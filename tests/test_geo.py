"""ArduPilot-compatible NED <-> geodetic conversion (taskflight_common/geo.py) against WGS84 (pymap3d)."""

from __future__ import annotations

import math
import random

import pymap3d
import pytest

from taskflight_common.geo import LOCATION_SCALING_FACTOR, geodetic_to_ned, ned_to_geodetic

ORIGINS = [(-35.363261, 149.165230, 584.0), (58.39, 15.57, 80.0), (0.0, 179.999, 0.0), (70.0, -20.0, 10.0)]


def test_ardupilot_constant() -> None:
    # ArduPilot: LOCATION_SCALING_FACTOR = RADIUS_OF_EARTH * pi / 180 * 1e-7 with 6378100 m
    assert pytest.approx(6378100 * math.pi / 180 * 1e-7, rel=1e-12) == LOCATION_SCALING_FACTOR


@pytest.mark.parametrize("origin", ORIGINS)
def test_round_trip_exact(origin: tuple[float, float, float]) -> None:
    rng = random.Random(1)
    for _ in range(200):
        n, e, d = rng.uniform(-3000, 3000), rng.uniform(-3000, 3000), rng.uniform(-500, 100)
        lat, lon, alt = ned_to_geodetic(origin, n, e, d)
        assert -180.0 <= lon <= 180.0
        back = geodetic_to_ned(origin, lat, lon, alt)
        assert back == pytest.approx((n, e, d), abs=1e-6)


@pytest.mark.parametrize("origin", ORIGINS[:2])
def test_close_to_wgs84_within_a_few_km(origin: tuple[float, float, float]) -> None:
    rng = random.Random(2)
    for _ in range(100):
        n, e = rng.uniform(-2000, 2000), rng.uniform(-2000, 2000)
        lat, lon, _alt = ned_to_geodetic(origin, n, e, 0.0)
        wn, we, _wd = pymap3d.geodetic2ned(lat, lon, origin[2], *origin)
        dist = math.hypot(n, e)
        assert math.hypot(wn - n, we - e) <= 0.004 * dist + 0.01
