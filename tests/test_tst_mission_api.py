"""The mission layer on the companion's HTTP surface, flying each autopilot (seed 000 Sec. VII).

Per autopilot (the bundled model; ArduCopter SITL with ``TASKFLIGHT_ARDUCOPTER``): ``POST /mission``
with the scan-and-search YAML (delegated to the indoor platform completed from the vehicle's home and
battery), ``/mission/start``, the operator's pause / continue / enough, and ``GET /mission`` with each
node's Fig. 4 flags, Fig. 5 status and progress; bad and rejected missions answer 400 / 422 and change
nothing; requests the flags forbid answer 409.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from harness.flight_session import FlightSession, SessionSpec
from harness.timing import wait_for

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[1]
SCAN_AND_SEARCH = (ROOT / "mission_specs" / "scan_and_search.yaml").read_text()
YAML = {"Content-Type": "application/yaml"}
SPEEDUP = 3.0


FLIGHT_SESSION = SessionSpec("mission", SPEEDUP, localized=True, missions=True)


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


def test_bad_and_rejected_missions_change_nothing(flight_session: FlightSession) -> None:
    before = mission(flight_session)
    bad = SCAN_AND_SEARCH.replace("type: take-off", "type: teleport")
    r = flight_session.http.post("/mission", content=bad, headers=YAML)
    assert r.status_code == 400 and "<request>:" in r.json()["error"]
    assert "unknown task type" in r.json()["error"]
    far = SCAN_AND_SEARCH.replace("[-35.363261, 149.165296, 2.0]", "[-35.362261, 149.165296, 2.0]")  # 111 m N
    r = flight_session.http.post("/mission", content=far, headers=YAML)
    assert r.status_code == 422 and any("outside the fence" in x for x in r.json()["reasons"])
    r = flight_session.http.post("/mission", content="{not json",
                                 headers={"Content-Type": "application/json"})
    assert r.status_code == 400
    r = flight_session.http.post("/mission", content=SCAN_AND_SEARCH, headers={"Content-Type": "text/plain"})
    assert r.status_code == 415
    assert mission(flight_session) == before
    assert flight_session.post("/mission/pause").status_code == 409  # nothing running


def test_fly_the_mission_with_break_in_resume_and_enough(flight_session: FlightSession) -> None:
    flight_session.ensure_on_ground()
    r = flight_session.http.post("/mission", content=SCAN_AND_SEARCH, headers=YAML)
    assert r.status_code == 200, r.text
    body = r.json()
    scan = node(body["tree"], "scan")
    assert scan["expansion"] >= 8 and scan["info"] is None and scan["state"] == "idle"
    assert flight_session.post("/mission/start").status_code == 200
    assert mission(flight_session)["state"] == "executing", mission(flight_session)
    r = flight_session.post("/mission/pause")
    assert r.status_code == 409 and "can_be_paused is false" in r.json()["error"]  # the take-off
    wait_for(lambda: mission(flight_session)["active_node"] == "scan", flight_session.wall(60), "the scan")
    wait_for(lambda: node(mission(flight_session)["tree"], "scan")["progress"].get("waypoint", 0) >= 3,
             flight_session.wall(60), "wp 3")
    scan = node(mission(flight_session)["tree"], "scan")
    assert scan["info"] == {"can_be_aborted": True, "can_be_paused": True, "can_be_enoughed": True}
    assert scan["progress"]["text"].startswith("waypoint ")
    r = flight_session.post("/mission/pause", {"routine_id": "hover"})
    assert r.status_code == 200 and r.json()["status"]["paused"]
    assert node(mission(flight_session)["tree"], "scan")["status"]["paused"]
    flight_session.sim_wait(2.0)
    assert flight_session.post("/mission/continue").status_code == 200
    flight_session.sim_wait(2.0)
    r = flight_session.post("/mission/enough")
    assert r.status_code == 200
    scan = node(mission(flight_session)["tree"], "scan")
    assert scan["state"] == "succeeded" and scan["progress"]["skipped"]
    wait_for(lambda: mission(flight_session)["state"] == "succeeded", flight_session.wall(120),
             f"the mission's end: {mission(flight_session)}")
    wait_for(lambda: not flight_session.armed(), flight_session.wall(30), "landed and disarmed")
    land = node(mission(flight_session)["tree"], "land")
    assert land["state"] == "succeeded" and land["status"]["succeeded"]
