"""``GET /mission/detections``: what a mission's scans saw, over HTTP, against the bundled model.

The scan-and-search mission (seed 000 Fig. 15) with ``generate_scan_specs_flag`` flies over a scenario
with two objects inside its area and one far outside; the simulated downward camera sees the two while
the scan runs; the route returns them with the scan's node id, data_uuid, time, object and position, and
the scan specs the flag generated: a sub-area of interest around each detection, a scan-ground node ready
to fly (Sec. VI-E: "a sub-area of interest to be subsequently scanned")."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from companion.sensing.scenario import Scenario, SceneObject
from companion.tst.spec import mission_from_dict
from harness.flight_session import FlightSession, SessionSpec
from harness.timing import wait_for
from taskflight_common.geo import ned_to_geodetic

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[1]
OBJECTS = [SceneObject(7, "person", 6.0, 1.5), SceneObject("car1", "car", 9.0, -3.0),
           SceneObject(9, "person", -40.0, 40.0)]  # the last one far from every path
FLIGHT_SESSION = SessionSpec("detections", 3.0, autopilots=(), localized=True, missions=True,
                             scenario=Scenario(OBJECTS))


def test_the_scans_detections_and_specs_are_returned(flight_session: FlightSession) -> None:
    http = flight_session.http
    before = http.get("/mission/detections")
    assert before.status_code == 200 and before.json()["detections"] == []
    flag = "data_uuid: scan-and-search-1\n        generate_scan_specs_flag: true"
    text = (ROOT / "mission_specs" / "scan_and_search.yaml").read_text().replace(
        "data_uuid: scan-and-search-1", flag)
    r = http.post("/mission", content=text, headers={"Content-Type": "application/yaml"})
    assert r.status_code == 200, r.text
    assert flight_session.post("/mission/start").status_code == 200
    wait_for(lambda: http.get("/mission").json()["state"] in ("succeeded", "failed"),
             flight_session.wall(240), "the mission's end")
    assert http.get("/mission").json()["state"] == "succeeded"
    body = http.get("/mission/detections").json()
    home = flight_session.node.link.mirror.snapshot().home
    assert home is not None
    assert body["mission"] == "scan-and-search"
    seen = {d["object"]: d for d in body["detections"]}
    assert set(seen) == {7, "car1"}, body
    for obj in OBJECTS[:2]:
        d = seen[obj.id]
        assert d["node"] == "scan" and d["data_uuid"] == "scan-and-search-1" and d["kind"] == obj.cls
        assert d["position_ned"] == [obj.n, obj.e, 0.0]
        lat, lon, _ = ned_to_geodetic((home[0], home[1], 0.0), obj.n, obj.e, 0.0)
        assert d["position"] == pytest.approx([lat, lon], abs=1e-7)  # around the vehicle's home
        assert d["t"] > 0 and math.dist(d["vehicle_neu"][:2], (obj.n, obj.e)) < 15
    times = [d["t"] for d in body["detections"]]
    assert times == sorted(times)
    [specs] = body["scan_specs"]
    assert specs["node"] == "scan" and specs["specs"]["lines"] >= 2
    areas = {a["object"]: a for a in specs["areas_of_interest"]}
    assert set(areas) == {7, "car1"}
    scan = areas[7]["scan"]
    assert scan["type"] == "scan-ground" and scan["params"]["data_uuid"] == "scan-and-search-1/7"
    # the sub-area is a mission a ground station can send next: it parses, centred on the person
    follow_up = mission_from_dict({"mission": "look-closer", "tree": {**scan, "id": "closer"}})
    lats = [p[0] for p in follow_up.root.params["area"]]
    assert min(lats) < seen[7]["position"][0] < max(lats)
