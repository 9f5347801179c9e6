"""The operator's fence through the companion into the autopilot, on the model and on ArduCopter SITL.

``POST /fence`` on the companion's control surface uploads the polygon with the MAVLink mission protocol
(mission type FENCE, one MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION item per vertex, ``param1`` the
vertex count, as ArduCopter stores it) and enables it (FENCE_TYPE's polygon bit, FENCE_ENABLE 1); the
test's own pymavlink ground station downloads the autopilot's fence plan and reads the parameters. Bad
points are refused with a 400 naming the field and change nothing.
"""

from __future__ import annotations

import math
from typing import Any

import pytest

from harness.fence import VERTEX_INCLUSION, param, read_fence
from harness.flight_session import FlightSession, SessionSpec

pytestmark = pytest.mark.integration

FLIGHT_SESSION = SessionSpec("fence_upload", 5.0)


def here(g: Any) -> tuple[float, float]:
    """The vehicle's latitude and longitude (GLOBAL_POSITION_INT: ArduCopter streams no HOME_POSITION)."""
    m = g.fresh("GLOBAL_POSITION_INT", 30)
    return m.lat * 1e-7, m.lon * 1e-7


def square(home: tuple[float, ...], half_m: float) -> list[list[float]]:
    dlat = half_m / 111_320.0
    dlon = half_m / (111_320.0 * math.cos(math.radians(home[0])))
    return [[home[0] + dlat, home[1] - dlon], [home[0] + dlat, home[1] + dlon],
            [home[0] - dlat, home[1] + dlon], [home[0] - dlat, home[1] - dlon]]


def test_the_fence_posted_is_the_autopilots(flight_session: FlightSession) -> None:
    s = flight_session
    g = s.gcs
    points = square(here(g), 80.0)
    r = s.post("/fence", {"points": points, "enable": True})
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["vertices"] == 4 and body["enabled"] is True and body["fence_type"] & 4
    items = read_fence(g)
    assert [it[0] for it in items] == [VERTEX_INCLUSION] * 4
    assert all(it[1] == 4 for it in items)
    for it, p in zip(items, points, strict=True):
        assert abs(it[2] - p[0]) < 2e-7 and abs(it[3] - p[1]) < 2e-7
    assert param(g, "FENCE_ENABLE") == 1.0
    assert int(param(g, "FENCE_TYPE")) & 4


def test_bad_points_are_refused_and_change_nothing(flight_session: FlightSession) -> None:
    s = flight_session
    before = read_fence(s.gcs)
    bad = [[10.0, 20.0], [95.0, 20.0], [10.0, 21.0]]
    r = s.post("/fence", {"points": bad})
    assert r.status_code == 400 and "points[1]" in r.json()["error"], r.text
    r = s.post("/fence", {"points": [[10.0, 20.0], [10.0, 21.0]]})
    assert r.status_code == 400 and "points" in r.json()["error"], r.text
    assert read_fence(s.gcs) == before


def test_a_fence_sent_in_flight_is_enabled(flight_session: FlightSession) -> None:
    """A fleet is often in the air when the operator sends a fence: FENCE_ENABLE 0 -> 1 is not a gain's
    bounded change (the guarded parameter writes' 50 % rule in flight), the operator's confirmation
    suffices."""
    s = flight_session
    g = s.gcs
    s.gcs.set_param("FENCE_ENABLE", 0.0)
    assert param(g, "FENCE_ENABLE") == 0.0
    s.ensure_airborne()
    assert s.armed()
    points = square(here(g), 120.0)  # around the vehicle: it stays inside
    r = s.post("/fence", {"points": points, "enable": True})
    assert r.status_code == 200, r.text
    assert r.json()["enabled"] is True
    assert param(g, "FENCE_ENABLE") == 1.0
    assert len(read_fence(g)) == 4
    s.ensure_on_ground()
