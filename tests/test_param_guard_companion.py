"""The companion guards parameter writes itself (not only the ground service): a name outside the
autopilot's table, a value out of range, an empty one, or more than 50 % of a change while armed without
``force`` is refused with a 400 naming the field and nothing is sent (the autopilot's value, read by an
independent pymavlink ground station, is unchanged); a forced write is applied, answered with the old
value read first. The table is the autopilot's own: the model's metadata for the bundled model (it says
so in AUTOPILOT_VERSION), ArduPilot's documented ranges for ArduCopter SITL (``TASKFLIGHT_ARDUCOPTER``).
"""

from __future__ import annotations

import pytest

from harness.flight_session import FlightSession, SessionSpec

pytestmark = pytest.mark.integration

SPEEDUP = 3.0
FLIGHT_SESSION = SessionSpec("param_guard", SPEEDUP)
NAME = "WPNAV_RADIUS"  # in both tables (cm); a waypoint acceptance radius changes nothing while hovering


def observed(session: FlightSession, name: str) -> float:
    """The autopilot's value now, asked by the pymavlink ground station (not through the companion)."""
    return session.gcs.param(name)


def test_the_companion_refuses_what_its_table_does_not_allow(flight_session: FlightSession) -> None:
    s = flight_session
    s.ensure_airborne()
    got = s.http.get(f"/params/{NAME}")
    assert got.status_code == 200, got.text
    p = got.json()
    assert p["autopilot"] == ("model" if s.kind == "model" else "arducopter"), (s.kind, p)
    assert p["min"] is not None and p["min"] <= p["value"] <= p["max"] and p["units"] == "cm"
    before = observed(s, NAME)
    for body, field in (({"value": 1.0}, "name"), ({"value": p["max"] * 10}, "value"),
                        ({"value": ""}, "value"), ({"value": "wide"}, "value"),
                        ({"value": before * 1.8}, "force")):
        path = f"/params/{'NO_SUCH_PARAM_Y' if field == 'name' else NAME}"
        r = s.http.put(path, json=body)
        assert r.status_code == 400 and r.json()["error"].startswith(f"{field}: "), (body, r.text)
    assert observed(s, NAME) == pytest.approx(before), "a refused write changed the autopilot"
    r = s.http.put(f"/params/{NAME}", json={"value": before * 1.8, "force": True})  # the operator forces
    assert r.status_code == 200, r.text
    assert r.json()["old"] == pytest.approx(before) and r.json()["value"] == pytest.approx(before * 1.8)
    assert observed(s, NAME) == pytest.approx(before * 1.8, rel=1e-5)
    r = s.http.put(f"/params/{NAME}", json={"value": before})  # back: -44 %, within the bound
    assert r.status_code == 200 and observed(s, NAME) == pytest.approx(before, rel=1e-5), r.text
