"""The mission layer on the companion's HTTP surface, flying each autopilot (seed 000 Sec. VII).

Per autopilot (the bundled model; ArduCopter SITL with ``TASKFLIGHT_ARDUCOPTER``): ``POST /mission``
with the scan-and-search YAML (delegated to the indoor platform completed from the vehicle's home and
battery), ``/mission/start``, the operator's pause / continue / enough, and ``GET /mission`` with each
node's Fig. 4 flags, Fig. 5 status and progress; bad and rejected missions answer 400 / 422 and change
nothing; requests the flags forbid answer 409.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from harness.autopilot import AUTOPILOTS
from harness.flight_session import FlightSession
from harness.timing import wait_for

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[1]
SCAN_AND_SEARCH = (ROOT / "mission_specs" / "scan_and_search.yaml").read_text()
YAML = {"Content-Type": "application/yaml"}
SPEEDUP = 3.0


@pytest.fixture(scope="module", params=AUTOPILOTS)
def f(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Iterator[FlightSession]:
    session = FlightSession(request.param, tmp_path_factory.mktemp(f"mission_{request.param}"), SPEEDUP,
                            missions=True)
    try:
        wait_for(lambda: session.node.link.mirror.snapshot().home is not None, session.wall(30), "home")
        assert session.layer is not None  # a healthy estimate: the motion behaviors need SELF_LOCALIZE
        wait_for(lambda: session.layer.coordinator.is_active("SELF_LOCALIZE"), session.wall(60), "localized")
        yield session
    finally:
        session.close()


def mission(f: FlightSession) -> dict[str, Any]:
    return f.http.get("/mission").json()


def node(tree: dict[str, Any], node_id: str) -> dict[str, Any]:
    if tree["id"] == node_id:
        return tree
    for c in tree.get("children", []):
        found = node(c, node_id)
        if found:
            return found
    return {}


def test_bad_and_rejected_missions_change_nothing(f: FlightSession) -> None:
    before = mission(f)
    bad = SCAN_AND_SEARCH.replace("type: take-off", "type: teleport")
    r = f.http.post("/mission", content=bad, headers=YAML)
    assert r.status_code == 400 and "<request>:" in r.json()["error"]
    assert "unknown task type" in r.json()["error"]
    far = SCAN_AND_SEARCH.replace("[-35.363261, 149.165296, 2.0]", "[-35.362261, 149.165296, 2.0]")  # 111 m N
    r = f.http.post("/mission", content=far, headers=YAML)
    assert r.status_code == 422 and any("outside the fence" in x for x in r.json()["reasons"])
    r = f.http.post("/mission", content="{not json", headers={"Content-Type": "application/json"})
    assert r.status_code == 400
    r = f.http.post("/mission", content=SCAN_AND_SEARCH, headers={"Content-Type": "text/plain"})
    assert r.status_code == 415
    assert mission(f) == before
    assert f.post("/mission/pause").status_code == 409  # nothing running


def test_fly_the_mission_with_break_in_resume_and_enough(f: FlightSession) -> None:
    f.ensure_on_ground()
    r = f.http.post("/mission", content=SCAN_AND_SEARCH, headers=YAML)
    assert r.status_code == 200, r.text
    body = r.json()
    scan = node(body["tree"], "scan")
    assert scan["expansion"] >= 8 and scan["info"] is None and scan["state"] == "idle"
    assert f.post("/mission/start").status_code == 200
    assert mission(f)["state"] == "executing", mission(f)
    r = f.post("/mission/pause")
    assert r.status_code == 409 and "can_be_paused is false" in r.json()["error"]  # the take-off
    wait_for(lambda: mission(f)["active_node"] == "scan", f.wall(60), "the scan")
    wait_for(lambda: node(mission(f)["tree"], "scan")["progress"].get("waypoint", 0) >= 3, f.wall(60), "wp 3")
    scan = node(mission(f)["tree"], "scan")
    assert scan["info"] == {"can_be_aborted": True, "can_be_paused": True, "can_be_enoughed": True}
    assert scan["progress"]["text"].startswith("waypoint ")
    r = f.post("/mission/pause", {"routine_id": "hover"})
    assert r.status_code == 200 and r.json()["status"]["paused"]
    assert node(mission(f)["tree"], "scan")["status"]["paused"]
    f.sim_wait(2.0)
    assert f.post("/mission/continue").status_code == 200
    f.sim_wait(2.0)
    r = f.post("/mission/enough")
    assert r.status_code == 200
    scan = node(mission(f)["tree"], "scan")
    assert scan["state"] == "succeeded" and scan["progress"]["skipped"]
    wait_for(lambda: mission(f)["state"] == "succeeded", f.wall(120), f"the mission's end: {mission(f)}")
    wait_for(lambda: not f.armed(), f.wall(30), "landed and disarmed")
    land = node(mission(f)["tree"], "land")
    assert land["state"] == "succeeded" and land["status"]["succeeded"]
