"""In-flight gain tuning through the companion's own MAVLink link (seed 003 Sec. II, the Process Monitor).

``PUT /params/{name}`` on the companion's control surface sends PARAM_SET to the autopilot and answers with
the PARAM_VALUE it sent back (the read-back); ``GET /params/{name}`` asks with PARAM_REQUEST_READ. Against
each autopilot (the bundled model; ArduCopter SITL with ``TASKFLIGHT_ARDUCOPTER``), in the air.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from harness.autopilot import AUTOPILOTS
from harness.flight_session import FlightSession

pytestmark = pytest.mark.integration

SPEEDUP = 3.0


@pytest.fixture(scope="module", params=AUTOPILOTS)
def f(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Iterator[FlightSession]:
    session = FlightSession(request.param, tmp_path_factory.mktemp(f"params_{request.param}"), SPEEDUP)
    try:
        yield session
    finally:
        session.close()


def test_gain_set_in_flight_is_read_back_from_the_autopilot(f: FlightSession) -> None:
    f.ensure_airborne()
    before = f.http.get("/params/ATC_RAT_RLL_P")
    assert before.status_code == 200, before.text
    old = before.json()["value"]
    new = round(old * 1.2, 4)
    r = f.http.put("/params/ATC_RAT_RLL_P", json={"value": new})
    assert r.status_code == 200, r.text
    assert r.json()["name"] == "ATC_RAT_RLL_P" and r.json()["value"] == pytest.approx(new, rel=1e-5)
    # asked again, the autopilot holds the new value (not the companion's memory of it)
    assert f.http.get("/params/ATC_RAT_RLL_P").json()["value"] == pytest.approx(new, rel=1e-5)
    assert f.phase() == "ENGAGED"  # still flying the queue
    r = f.http.put("/params/ATC_RAT_RLL_P", json={"value": old})
    assert r.status_code == 200 and r.json()["value"] == pytest.approx(old, rel=1e-5)


def test_bad_parameter_requests_change_nothing(f: FlightSession) -> None:
    got = f.http.get("/params/ATC_RAT_RLL_P")
    assert got.status_code == 200, got.text
    value = got.json()["value"]
    r = f.http.put("/params/atc_rat_rll_p", json={"value": 1.0})
    assert r.status_code == 400 and "parameter name" in r.json()["error"]
    r = f.http.put("/params/ATC_RAT_RLL_P", json={"value": "high"})
    assert r.status_code == 400 and "value" in r.json()["error"]
    r = f.http.put("/params/ATC_RAT_RLL_P", content=b"{nope", headers={"Content-Type": "application/json"})
    assert r.status_code == 400
    r = f.http.put("/params/NO_SUCH_PARAM_X", json={"value": 1.0})
    assert r.status_code == 504 and "no PARAM_VALUE" in r.json()["error"]
    assert f.http.get("/params/ATC_RAT_RLL_P").json()["value"] == value
