"""A mission with WHILE / IF over the camera's beliefs, against the bundled model.

``mission_specs/search_and_inspect.yaml``: scan the area while no person is visible; the simulated
downward camera (``mission_specs/scenario_person.yaml``) sees one; the WHILE enoughs the scan, the IF
hovers over the person and asks the operator (REQUEST_OPERATOR_ASSISTANCE); the operator confirms and
the vehicle lands there.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from companion.sensing.scenario import Scenario
from harness.flight_session import FlightSession, SessionSpec
from harness.timing import wait_for

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[1]


FLIGHT_SESSION = SessionSpec("search", 3.0, autopilots=(), localized=True, missions=True,
                             scenario=Scenario.load(ROOT / "mission_specs" / "scenario_person.yaml"))


def test_scan_until_a_person_is_seen_then_hover_over_it_and_ask(flight_session: FlightSession) -> None:
    text = (ROOT / "mission_specs" / "search_and_inspect.yaml").read_text()
    r = flight_session.http.post("/mission", content=text, headers={"Content-Type": "application/yaml"})
    assert r.status_code == 200, r.text
    assert flight_session.post("/mission/start").status_code == 200
    wait_for(lambda: flight_session.http.get("/mission").json()["active_node"] == "ask",
             flight_session.wall(120),
             f"asking the operator: {flight_session.http.get('/mission').json()}")
    assert flight_session.layer is not None
    # the person, and nothing else, was seen (again, if it left the footprint while the vehicle braked and
    # turned back over it: each entry into view is a sighting)
    assert {d.object_id for d in flight_session.layer.camera.detections} == {7}
    assert flight_session.layer.camera.detections[0].data_uuid == "search-1"
    assert flight_session.layer.beliefs.holds("waiting_for(self, operator)")
    n, e, _ = flight_session.pos()
    assert math.dist((n, e), (6.0, 1.5)) < 0.5  # above the person
    assert flight_session.post("/user_confirm").status_code == 200  # the operator: land here
    wait_for(lambda: flight_session.http.get("/mission").json()["state"] == "succeeded",
             flight_session.wall(60), "the mission's end")
    wait_for(lambda: not flight_session.armed(), flight_session.wall(30), "landed and disarmed")
    assert math.dist(flight_session.pos()[:2], (6.0, 1.5)) < 0.7
