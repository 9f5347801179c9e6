"""The ground service sends every vehicle home: ``POST /api/fleet/rtl`` on a fleet of 3.

A fleet of 3 models, 3 companion processes on a team link and ``taskflight ground`` (harness.ground
GroundRig). Each vehicle is taken out of the team and flown out (its companion's behaviors, as the
operator); one ``POST /api/fleet/rtl`` forwards RTL to every companion and answers per vehicle; each
vehicle's own pymavlink ground station then sees it disarmed on the ground at its home, and the service's
events record the command. ``POST /api/vehicles/{id}/rtl`` on a vehicle on the ground answers 409 with
its companion's reason.
"""

from __future__ import annotations

import math
from typing import Any

import httpx
import pytest

from harness.ground import COMPANION_TOKEN, GroundRig
from harness.timing import wait_for

pytestmark = pytest.mark.integration

OUT = {1: (12.0, 6.0), 2: (-10.0, 8.0), 3: (6.0, -12.0)}


def companion(rig: GroundRig, vid: int) -> httpx.Client:
    return httpx.Client(base_url=f"http://127.0.0.1:{rig.control_ports[vid - 1]}", timeout=10.0,
                        headers={"Authorization": f"Bearer {COMPANION_TOKEN}"})


def run(c: httpx.Client, text: str, rig: GroundRig, sim_s: float) -> dict[str, Any]:
    r = c.post("/behaviors/activate", json={"text": text, "requester": "operator"})
    assert r.status_code == 200 and r.json()["accepted"], r.text
    aid = r.json()["activation_id"]

    def end() -> dict[str, Any] | None:
        return next((e for e in c.get("/behaviors").json()["ended"] if e["activation_id"] == aid), None)
    wait_for(lambda: end() is not None, rig.wall(sim_s), f"{text} ended")
    out = end()
    assert out is not None
    return out


def test_fleet_rtl_brings_every_vehicle_home(ground_rig: GroundRig) -> None:
    rig = ground_rig
    with rig.ground.http() as g:
        r = g.post("/api/vehicles/1/rtl")
        assert r.status_code == 409 and "flight_state" in r.json()["error"], r.text  # on the ground
        for vid, (n, e) in OUT.items():
            assert g.post(f"/api/vehicles/{vid}/take", json={"reason": "fleet RTL test"}).status_code == 200
            with companion(rig, vid) as c:
                assert run(c, "TAKE_OFF altitude: 5", rig, 60)["cause"] == "goal_achieved"
                c.post("/behaviors/activate", json={"text": f"GO_TO_POINT coordinate: ({n}, {e}, 6)",
                                                    "requester": "operator"}).raise_for_status()
        for vid, (n, e) in OUT.items():
            wait_for(lambda vid=vid, n=n, e=e: math.dist(rig.gcs[vid - 1].ned()[:2], (n, e)) < 3.0,
                     rig.wall(60), f"vehicle {vid} out")
        r = g.post("/api/fleet/rtl")
        assert r.status_code == 200, r.text
        results = {x["vehicle"]: x for x in r.json()["results"]}
        assert set(results) == {1, 2, 3}, results
        assert all(x["ok"] and x["answer"]["accepted"] for x in results.values()), results
        for vid in OUT:
            rig.gcs[vid - 1].wait_autopilot_disarmed(rig.wall(120))
            n, e, d = rig.gcs[vid - 1].ned()
            assert math.hypot(n, e) < 2.0 and -d < 0.5, (vid, n, e, d)
        events = g.get("/api/events").json()["events"]
        fleet = [x for x in events if x["kind"] == "rtl" and x["message"].startswith("fleet RTL")]
        assert fleet and fleet[-1]["data"]["returning"] == [1, 2, 3], fleet
        audit = [x for x in g.get("/api/audit").json()["entries"] if x["action"] == "rtl"]
        assert {x["target"] for x in audit} >= {"vehicle 1", "vehicle 2", "vehicle 3"}, audit
