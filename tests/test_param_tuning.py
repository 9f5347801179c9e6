"""In-flight gain tuning through the companion's own MAVLink link (seed 003 Sec. II, the Process Monitor).

``PUT /params/{name}`` on the companion's control surface sends PARAM_SET to the autopilot and answers with
the PARAM_VALUE it sent back (the read-back); ``GET /params/{name}`` asks with PARAM_REQUEST_READ. Against
each autopilot (the bundled model; ArduCopter SITL with ``TASKFLIGHT_ARDUCOPTER``), in the air.
"""

from __future__ import annotations

import pytest

from harness.flight_session import FlightSession, SessionSpec

pytestmark = pytest.mark.integration

SPEEDUP = 3.0


FLIGHT_SESSION = SessionSpec("params", SPEEDUP)


def test_gain_set_in_flight_is_read_back_from_the_autopilot(flight_session: FlightSession) -> None:
    flight_session.ensure_airborne()
    before = flight_session.http.get("/params/ATC_RAT_RLL_P")
    assert before.status_code == 200, before.text
    old = before.json()["value"]
    new = round(old * 1.2, 4)
    r = flight_session.http.put("/params/ATC_RAT_RLL_P", json={"value": new})
    assert r.status_code == 200, r.text
    assert r.json()["name"] == "ATC_RAT_RLL_P" and r.json()["value"] == pytest.approx(new, rel=1e-5)
    # asked again, the autopilot holds the new value (not the companion's memory of it)
    assert flight_session.http.get("/params/ATC_RAT_RLL_P").json()["value"] == pytest.approx(new, rel=1e-5)
    assert flight_session.phase() == "ENGAGED"  # still flying the queue
    r = flight_session.http.put("/params/ATC_RAT_RLL_P", json={"value": old})
    assert r.status_code == 200 and r.json()["value"] == pytest.approx(old, rel=1e-5)


def test_bad_parameter_requests_change_nothing(flight_session: FlightSession) -> None:
    got = flight_session.http.get("/params/ATC_RAT_RLL_P")
    assert got.status_code == 200, got.text
    value = got.json()["value"]
    r = flight_session.http.put("/params/atc_rat_rll_p", json={"value": 1.0})
    assert r.status_code == 400 and "parameter name" in r.json()["error"]
    r = flight_session.http.put("/params/ATC_RAT_RLL_P", json={"value": "high"})
    assert r.status_code == 400 and "value" in r.json()["error"]
    r = flight_session.http.put("/params/ATC_RAT_RLL_P", content=b"{nope",
                                headers={"Content-Type": "application/json"})
    assert r.status_code == 400
    r = flight_session.http.put("/params/NO_SUCH_PARAM_X", json={"value": 1.0})  # not in the table
    assert r.status_code == 400 and r.json()["error"].startswith("name: NO_SUCH_PARAM_X"), r.text
    r = flight_session.http.get("/params/NO_SUCH_PARAM_X")  # a read asks the autopilot: unknown
    assert r.status_code == 504 and "no PARAM_VALUE" in r.json()["error"]
    assert flight_session.http.get("/params/ATC_RAT_RLL_P").json()["value"] == value
