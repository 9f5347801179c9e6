"""The ground service killed with SIGKILL mid-mission and restarted on its database: every task, assignment
and audit entry is back, and the vehicles never stopped (their MAVLink
tracks kept moving while it was down: the team needs no ground station to go on).

A fleet of 3 models, 3 companion processes on a team link and ``taskflight ground`` started by the test
(tests/ground_support.GroundRig), so that the service alone can be killed and started again.
"""

from __future__ import annotations

import math
import time

import pytest
from test_ground_flight import add, local, state

from harness.ground import GroundRig
from harness.team import geo
from harness.timing import wait_for

pytestmark = pytest.mark.integration


def test_sigkill_mid_mission_and_restart_loses_nothing(ground_rig: GroundRig) -> None:
    line = [geo(-20, -15, 6), geo(-20, 15, 6)]
    body = {"type": "patrol_line", "points": [list(p) for p in line], "name": "long patrol"}
    patrol = add(ground_rig, body)["ids"][0]
    wait_for(lambda: state(ground_rig, patrol) == "active", ground_rig.wall(120), "the patrol flown")
    with ground_rig.ground.http() as c:
        tasks_before = c.get("/api/tasks").json()["tasks"]
        audit_before = c.get("/api/audit").json()["entries"]
        assign_before = c.get("/api/assignments").json()["assignments"]
    holder = next(t for t in tasks_before if t["id"] == patrol)["holder"]
    ground_rig.ground.kill()
    killed = time.monotonic()
    time.sleep(3.0)  # the service is down for 3 s of wall time: the vehicles go on
    ground_rig.ground.start()
    down = [s for s in ground_rig.tracks[holder - 1] if s[0] >= killed]
    assert len(down) > 10
    assert max(math.dist(local(a[1:]), local(down[0][1:])) for a in down) > 1.0, "the holder stopped"
    with ground_rig.ground.http() as c:
        tasks_after = c.get("/api/tasks").json()["tasks"]
        assert [(t["id"], t["kind"], t["state"], t["holder"], t["version"]) for t in tasks_after] == \
            [(t["id"], t["kind"], t["state"], t["holder"], t["version"]) for t in tasks_before]
        assert c.get("/api/audit").json()["entries"][:len(audit_before)] == audit_before
        assert c.get("/api/assignments").json()["assignments"][:len(assign_before)] == assign_before
    wait_for(lambda: ground_rig.vehicles()[holder]["task"] == patrol, 30,
             "the holder still flying the patrol")
    wait_for(lambda: ground_rig.ready(), 30, "the fleet picked up again")
    assert state(ground_rig, patrol) == "active" and ground_rig.tasks()[patrol]["holder"] == holder
    with ground_rig.ground.http() as c:
        assert c.delete(f"/api/tasks/{patrol}").status_code == 200  # the restarted service commands
        new = c.post("/api/tasks", json={"type": "visit", "point": list(geo(5, 5, 6))}).json()["ids"][0]
    assert new > max(t["id"] for t in tasks_before)
    wait_for(lambda: state(ground_rig, new) == "done", ground_rig.wall(120),
             "a task given after the restart flown")
