"""The ground service flying a team over loopback: ``taskflight up --vehicles 3``
(3 models in one process, 3 companion processes on a team link, ``taskflight ground`` as the team's
station; tests/up_support.UpRig adds a pymavlink ground station per vehicle).

Team tasks of every type added and cancelled through REST, seen allocated (``GET /api/tasks``) and
flown (positions read from the models over MAVLink by pymavlink ground stations, not from the service);
a break-in with stick samples over the WebSocket moves the vehicle and it stops when they stop, then
resume and enough; the camera's detection as an event; a gain changed in flight read back from the
autopilot. The SIGKILL restart is in :mod:`test_ground_restart`.
"""

from __future__ import annotations

import json
import math
import threading
import time
from collections.abc import Callable
from typing import Any

import pytest
import yaml
from shapely.geometry import LineString, Point, Polygon

from harness import ROOT
from harness.ground import GroundRig
from harness.team import HOME, geo
from harness.timing import wait_for

pytestmark = pytest.mark.integration

# the up_rig fixture's camera scenario: every vehicle's camera sees a person 1 m north of where it takes off
UP_SCENARIO = "objects:\n  - {id: 7, class: person, position: [1.0, 0.0]}\n"
SCAN_AND_SEARCH = yaml.safe_load((ROOT / "mission_specs" / "scan_and_search.yaml").read_text())
# the outdoor platform's floor is 3 m: the final fly-to at 5 m
SCAN_AND_SEARCH["tree"]["children"][2]["params"]["position"][2] = 5.0


def local(p: tuple[float, ...] | list[float]) -> tuple[float, float]:
    """(east, north) metres of a (lat, lon, ...) point from the fleet's home (flat earth: < 1 km)."""
    return ((p[1] - HOME[1]) * 111_320.0 * math.cos(math.radians(HOME[0])), (p[0] - HOME[0]) * 111_320.0)


def visited(rig: GroundRig, shape: Any, tol: float, since: float = 0.0) -> list[int]:
    """The vehicles whose MAVLink track came within ``tol`` m of ``shape`` after ``since``."""
    return [i for i in range(rig.n)
            if any(shape.distance(Point(local(s[1:]))) <= tol for s in list(rig.tracks[i]) if s[0] >= since)]


def post(rig: GroundRig, path: str, body: Any = None) -> Any:
    with rig.ground.http() as c:
        return c.post(path, json=body)


def add(rig: GroundRig, body: dict[str, Any]) -> dict[str, Any]:
    r = post(rig, "/api/tasks", body)
    for _ in range(3):  # seed 003: take the smaller N offered (it shrinks if vehicles get busy meanwhile)
        if not (r.status_code == 409 and "offer" in r.json()):
            break
        r = post(rig, "/api/tasks", {**body, "vehicles": r.json()["offer"]})
    assert r.status_code == 201, r.text
    return r.json()


def state(rig: GroundRig, tid: int) -> str:
    return rig.tasks()[tid]["state"]


def test_team_tasks_of_every_type_added_flown_and_cancelled(up_rig: GroundRig) -> None:
    t0 = time.monotonic()
    visit = add(up_rig, {"type": "visit", "point": list(geo(20, -10, 6)), "name": "visit"})["ids"][0]
    area_pts = [geo(15, 20), geo(15, 35), geo(30, 35), geo(30, 20)]
    area = add(up_rig, {"type": "area_scan", "area": [list(p) for p in area_pts], "vehicles": 2,
                        "altitude": 6})
    ids = [visit, *area["ids"]]
    wait_for(lambda: all(up_rig.tasks()[t]["holder"] is not None or state(up_rig, t) == "done" for t in ids),
             up_rig.wall(60), "the visit and the area parts allocated")
    wait_for(lambda: all(state(up_rig, t) == "done" for t in ids), up_rig.wall(300),
             lambda: f"flown: {up_rig.report()}")
    assert visited(up_rig, Point(local(geo(20, -10))), 2.5, t0), "nobody flew to the visit point (MAVLink)"
    assert visited(up_rig, Polygon([local(p) for p in area_pts]), 0.5, t0), "nobody scanned the area"
    t1 = time.monotonic()
    line = [geo(-15, -10, 6), geo(-15, 10, 6)]
    patrol = add(up_rig, {"type": "patrol_line", "points": [list(p) for p in line],
                          "name": "patrol"})["ids"][0]
    border_pts = [geo(40, -20, 6), geo(40, 0, 6), geo(40, 20, 6)]
    border = add(up_rig, {"type": "border_patrol", "points": [list(p) for p in border_pts], "vehicles": 2})
    live = [patrol, *border["ids"]]
    wait_for(lambda: all(state(up_rig, t) == "active" for t in live), up_rig.wall(120),
             lambda: f"patrols: {up_rig.report()}")
    holder = up_rig.tasks()[patrol]["holder"]
    wait_for(lambda: holder - 1 in visited(up_rig, LineString([local(p) for p in line]), 1.5, t1),
             up_rig.wall(60),
             "the patrol's holder on its line (MAVLink)")
    _break_in_on_a_team_task(up_rig, holder, patrol)
    with up_rig.ground.http() as c:
        assert c.delete(f"/api/tasks/{patrol}").json() == {"cancelled": [patrol]}
        assert sorted(c.delete(f"/api/tasks/{border['group']}").json()["cancelled"]) == sorted(border["ids"])
    wait_for(lambda: all(state(up_rig, t) == "cancelled" for t in live), 10, "cancelled")
    wait_for(lambda: all(not v["claims"] or all(c["state"] == "done" for c in v["claims"])
                         for v in up_rig.vehicles().values()), up_rig.wall(60), "every vehicle idle again")
    # idle, they hover by default (KEEP_HOVERING ends on E_User): nobody is asked to confirm anything
    wait_for(lambda: not any(v["confirmation_required"] for v in up_rig.vehicles().values()), 10,
             f"no confirmation asked of idle vehicles: {up_rig.vehicles()}")
    # and no cancelled task's tree flies on (seed 003: a vehicle with nothing to do loiters where it is)
    wait_for(lambda: all(v["mission"]["state"] != "executing" for v in up_rig.vehicles().values()),
             up_rig.wall(5),
             f"no tree executing on idle vehicles: {up_rig.vehicles()}")
    with up_rig.ground.http() as c:
        kinds = {e["kind"] for e in c.get("/api/events").json()["events"]}
        history = c.get("/api/assignments", params={"task": visit}).json()["assignments"]
    assert {"task_added", "task_state", "task_cancelled"} <= kinds
    assert [h["state"] for h in history][-1] == "done" and any(h["holder"] for h in history)


def _break_in_on_a_team_task(rig: GroundRig, vid: int, task: int) -> None:
    """The operator breaks in on a vehicle flying a team task (seed 000 Sec. VII through seed 003's process
    monitor): the task's tree pauses, the stick moves the vehicle, the team keeps the task with it (a
    break-in is not a take-over), and resume flies the task on."""
    i = vid - 1
    r = post(rig, f"/api/vehicles/{vid}/pause")
    assert r.status_code == 200, r.text
    wait_for(lambda: rig.vehicles()[vid]["mission"]["state"] == "paused", 10, "the team task's tree paused")
    # a real wait (the break-in ends on resume): the service reads it from the companion's next /status
    wait_for(lambda: rig.vehicles()[vid]["confirmation_required"], 10, "the break-in shown as a wait")
    alt0 = rig.position(i)[2]
    errors = _stick(rig, vid, [0.0, 0.0, -1.0, 0.0], rig.wall(12.0),  # up at 1 m/s
                    until=lambda: rig.position(i)[2] - alt0 > 3.0)
    assert len(errors) < 5, errors[:3]
    climbed = rig.position(i)[2] - alt0
    assert climbed > 2.0, f"the stick moved vehicle {vid} up {climbed:.1f} m (GLOBAL_POSITION_INT)"
    assert rig.tasks()[task]["holder"] == vid and state(rig, task) == "active", rig.tasks()[task]
    assert post(rig, f"/api/vehicles/{vid}/resume").status_code == 200
    wait_for(lambda: rig.vehicles()[vid]["mission"]["state"] == "executing", 10, "the team task resumed")
    assert rig.tasks()[task]["holder"] == vid


def test_gain_changed_in_flight_is_read_back_from_the_autopilot(up_rig: GroundRig) -> None:
    g = up_rig.gcs[0]
    wait_for(lambda: g.armed() and (up_rig.position(0) or (0, 0, 0))[2] > 1.0, up_rig.wall(60),
             "vehicle 1 flying")
    with up_rig.ground.http() as c:
        old = c.get("/api/vehicles/1/params/ATC_RAT_RLL_P").json()["value"]
        new = round(old * 1.2, 3)  # in flight: within the 50 % a write may change without force
        r = c.put("/api/vehicles/1/params/ATC_RAT_RLL_P", json={"value": new})
        assert r.status_code == 200, r.text
        assert r.json()["name"] == "ATC_RAT_RLL_P" and r.json()["value"] == pytest.approx(new, abs=1e-5)
        assert c.get("/api/vehicles/1/params/ATC_RAT_RLL_P").json()["value"] == pytest.approx(new, abs=1e-5)
        audit = c.get("/api/audit").json()["entries"][-1]
    assert (audit["action"], audit["status"], audit["role"]) == ("param", 200, "operator")
    # read back from the autopilot itself by an independent ground station
    with g._lock:
        g.last.pop("PARAM_VALUE", None)
    g.conn.mav.param_request_read_send(g.target, 1, b"ATC_RAT_RLL_P", -1)
    m = g.wait(lambda: g.last.get("PARAM_VALUE"), 10, "PARAM_VALUE")
    assert m.param_id == "ATC_RAT_RLL_P" and m.param_value == pytest.approx(new, abs=1e-5)


def _stick(rig: GroundRig, vid: int, values: list[float], seconds: float,
           until: Callable[[], bool] | None = None) -> list[dict[str, Any]]:
    """Stick samples at 20 Hz over the WebSocket for ``seconds`` of wall time, or until ``until()`` holds (a
    loaded machine runs the simulation slower than its speed-up: judge by what moved, not by the clock);
    returns the error messages."""
    errors: list[dict[str, Any]] = []
    r = post(rig, f"/api/vehicles/{vid}/stick/lease")
    assert r.status_code == 200, r.text
    lease, seq = r.json()["lease_id"], 0
    with rig.ground.ws() as ws:
        stop = threading.Event()

        def read() -> None:
            while not stop.is_set():
                try:
                    m = json.loads(ws.recv(timeout=0.2))
                except TimeoutError:
                    continue
                except Exception:
                    return
                if m["type"] == "error":
                    errors.append(m)

        reader = threading.Thread(target=read, daemon=True)
        reader.start()
        end = time.monotonic() + seconds
        while time.monotonic() < end and not (until is not None and until()):
            seq += 1
            ws.send(json.dumps({"type": "joystick", "vehicle": vid, "lease": lease, "seq": seq,
                                "values": values, "validity_s": 0.5}))
            time.sleep(0.05)
        stop.set()
        reader.join(2)
    return errors


def test_break_in_with_the_joystick_then_resume_and_enough(up_rig: GroundRig) -> None:
    i, vid = 2, 3
    if up_rig.gcs[i].armed():  # flying after the team's tasks: the mission starts with a take-off
        r = post(up_rig, f"/api/vehicles/{vid}/land")
        assert r.status_code == 200, r.text
        wait_for(lambda: not up_rig.gcs[i].armed(), up_rig.wall(90),
                 "vehicle 3 landed and disarmed (MAVLink)")
    r = post(up_rig, f"/api/vehicles/{vid}/mission", {**SCAN_AND_SEARCH, "start": True})
    assert r.status_code == 200, r.text

    def mission() -> dict[str, Any]:
        return up_rig.vehicles()[vid]["mission"]

    wait_for(lambda: mission()["node"] == "scan" and (mission()["progress"] or "").startswith("waypoint"),
             up_rig.wall(120), f"the scan under way: {mission()}")
    r = post(up_rig, f"/api/vehicles/{vid}/pause")
    assert r.status_code == 200, r.text
    start = up_rig.position(i)
    def moved() -> float:
        return local(up_rig.position(i))[1] - local(start)[1]

    # north at 1.5 m/s: 8 m take ~6 s of autopilot time (2 s of wall time at 3x); up to 24 s of autopilot time
    errors = _stick(up_rig, vid, [1.5, 0.0, 0.0, 0.0], up_rig.wall(24.0), until=lambda: moved() > 8.0)
    assert len(errors) < 5, errors[:3]  # a loaded machine may miss a sample's deadline now and then
    north = moved()
    assert north > 5.0, f"moved {north:.1f} m north under the stick"
    # the samples stopped: the vehicle stops within the validity (0.5 s) plus its braking
    wait_for(lambda: math.hypot(*up_rig.velocity(i)[:2]) < 0.3, up_rig.wall(3.0),
             "stopped after the last sample")
    held = up_rig.position(i)
    time.sleep(1.5)
    assert math.dist(local(held), local(up_rig.position(i))) < 0.5, "drifting without samples"
    assert post(up_rig, f"/api/vehicles/{vid}/resume").status_code == 200
    wait_for(lambda: mission()["state"] == "executing", 10, "resumed")
    r = post(up_rig, f"/api/vehicles/{vid}/enough")
    assert r.status_code == 200, r.text
    wait_for(lambda: mission()["node"] in ("fly-to", "land") or mission()["state"] == "succeeded",
             up_rig.wall(60), lambda: f"the mission goes on after enough: {mission()}")
    wait_for(lambda: mission()["state"] == "succeeded", up_rig.wall(120),
             lambda: f"the mission's end: {mission()}")
    with up_rig.ground.http() as c:
        actions = [e["action"] for e in c.get("/api/audit").json()["entries"]]
        assert c.get("/api/missions", params={"vehicle": vid}).json()["missions"][-1]["status"] == 200
    assert {"mission", "pause", "joystick", "resume", "enough"} <= set(actions)
    # the camera saw the person during the scan: a detection event with where it is
    with up_rig.ground.http() as c:
        seen = [e for e in c.get("/api/events", params={"kind": "detection"}).json()["events"]
                if e["vehicle"] == vid]
    assert seen and seen[0]["data"]["kind"] == "person", seen
    assert math.dist(local((seen[0]["data"]["lat"], seen[0]["data"]["lon"])), (10.0, 1.0)) < 1.0
    assert post(up_rig, f"/api/vehicles/{vid}/release").status_code == 200  # back into the team
