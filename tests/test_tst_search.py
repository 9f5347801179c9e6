"""A mission with WHILE / IF over the camera's beliefs, against the bundled model.

``mission_specs/search_and_inspect.yaml``: scan the area while no person is visible; the simulated
downward camera (``mission_specs/scenario_person.yaml``) sees one; the WHILE enoughs the scan, the IF
hovers over the person and asks the operator (REQUEST_OPERATOR_ASSISTANCE); the operator confirms and
the vehicle lands there.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path

import pytest

from companion.sensing.scenario import Scenario
from harness.flight_session import FlightSession
from harness.timing import wait_for

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def f(tmp_path: Path) -> Iterator[FlightSession]:
    session = FlightSession("model", tmp_path, 3.0, missions=True,
                            scenario=Scenario.load(ROOT / "mission_specs" / "scenario_person.yaml"))
    try:
        wait_for(lambda: session.node.link.mirror.snapshot().home is not None, session.wall(30), "home")
        assert session.layer is not None  # a healthy estimate: the motion behaviors need SELF_LOCALIZE
        wait_for(lambda: session.layer.coordinator.is_active("SELF_LOCALIZE"), session.wall(60), "localized")
        yield session
    finally:
        session.close()


def test_scan_until_a_person_is_seen_then_hover_over_it_and_ask(f: FlightSession) -> None:
    text = (ROOT / "mission_specs" / "search_and_inspect.yaml").read_text()
    r = f.http.post("/mission", content=text, headers={"Content-Type": "application/yaml"})
    assert r.status_code == 200, r.text
    assert f.post("/mission/start").status_code == 200
    wait_for(lambda: f.http.get("/mission").json()["active_node"] == "ask", f.wall(120),
             f"asking the operator: {f.http.get('/mission').json()}")
    assert f.layer is not None and [d.object_id for d in f.layer.camera.detections] == [7]
    assert f.layer.camera.detections[0].data_uuid == "search-1"
    assert f.layer.beliefs.holds("waiting_for(self, operator)")
    n, e, _ = f.pos()
    assert math.dist((n, e), (6.0, 1.5)) < 0.5  # above the person
    assert f.post("/user_confirm").status_code == 200  # the operator: land here
    wait_for(lambda: f.http.get("/mission").json()["state"] == "succeeded", f.wall(60), "the mission's end")
    wait_for(lambda: not f.armed(), f.wall(30), "landed and disarmed")
    assert math.dist(f.pos()[:2], (6.0, 1.5)) < 0.7
