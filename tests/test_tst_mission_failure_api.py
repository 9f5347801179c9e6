"""Missions that fail safely and can be followed, on the companion's HTTP surface flying the model.

* A companion whose autopilot never answers refuses ``POST /mission`` and ``/mission/start`` with 503 and
  the reason (it used to accept the mission and say ``executing`` for ever).
* A node that fails (``guarded-fly-to`` of :mod:`harness.guarded_leaf`: a fly-to that needs the
  operator's clearance) with ``retries: 2`` is tried three times, then the mission's ``on_failure: land``
  lands the vehicle (the independent ground station sees it disarm on the ground); the operator grants
  the clearance and ``POST /mission/resume`` flies the rest from the failed node.
* An abort with ``on_failure: land`` lands.
* ``GET /mission/events`` and ``GET /behaviors/events`` long-poll: they answer what happened after
  ``since`` and block until ``timeout`` when nothing has.
"""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Iterator
from typing import Any

import httpx
import pytest

from companion.builder import CompanionConfig, build_companion
from companion.tst.platform import bundled_platform
from harness.flight_session import FlightSession, SessionSpec
from harness.guarded_leaf import CLEARANCE, GuardedFlyTo, guarded_leaf
from harness.timing import wait_for
from taskflight_common.ports import free_ports

pytestmark = pytest.mark.integration

SPEEDUP = 3.0
FLIGHT_SESSION = SessionSpec("mfail", SPEEDUP, autopilots=(), localized=True, missions=True)
JSON = {"Content-Type": "application/json"}
# 6 m north of the model's default home (CMAC, -35.363261, 149.165230), 3 m up
NORTH_6 = [-35.363207, 149.165230, 3.0]


def mission(on_failure: str, second: dict[str, Any]) -> dict[str, Any]:
    return {"mission": "fail-safe", "on_failure": on_failure, "tree": {
        "type": "S", "id": "root", "children": [
            {"type": "take-off", "id": "up"},
            second,
            {"type": "land", "id": "down", "params": {"land_at_current_position_flag": True}}]}}


@pytest.fixture(scope="module")
def guarded() -> Iterator[GuardedFlyTo]:
    with guarded_leaf() as leaf:
        yield leaf


def on_ground(f: FlightSession) -> None:
    """Landed and disarmed as the companion sees it (every test here ends on the ground; a vehicle still
    flying is landed through the executive layer, which owns the queue)."""
    if f.armed() and f.alt() > 0.5:
        f.post("/behaviors/activate", {"text": "LAND", "requester": "operator"})
    wait_for(lambda: not f.armed(), f.wall(60), "landed and disarmed (the companion's mirror)")


def state(f: FlightSession) -> dict[str, Any]:
    return f.http.get("/mission").json()


def events(f: FlightSession, since: int = 0) -> list[dict[str, Any]]:
    return f.http.get("/mission/events", params={"since": since}).json()["events"]


def test_a_companion_without_its_autopilot_refuses_missions_with_503(tmp_path: Any) -> None:
    port = free_ports(1, socket.SOCK_DGRAM)[0]  # nothing listens there
    companion = build_companion(CompanionConfig(f"udpout:127.0.0.1:{port}", control_port=0,
                                                platform=bundled_platform("indoor")))
    companion.start()
    try:
        assert companion.server is not None
        with httpx.Client(base_url=companion.server.url, timeout=10.0) as http:
            body = mission("hover", {"type": "hover", "id": "h", "params": {"duration": 1}})
            del body["on_failure"]  # a mission as any client sends it
            r = http.post("/mission", json=body)
            assert r.status_code == 503, r.text
            assert "not connected" in r.json()["error"] and "no heartbeat" in r.json()["error"]
            r = http.post("/mission/start")
            assert r.status_code == 503 and "not connected" in r.json()["error"]
            st = http.get("/mission").json()
            assert st["state"] == "none" and "not connected" in st["readiness"]
    finally:
        companion.close()


def test_retries_then_land_then_resume_from_the_failed_node(flight_session: FlightSession,
                                                            guarded: GuardedFlyTo) -> None:
    f = flight_session
    on_ground(f)
    assert f.missions is not None and f.layer is not None
    f.missions.base_platform = bundled_platform("indoor").with_tasks(
        (*bundled_platform("indoor").tasks, guarded.name))
    f.layer.beliefs.remove(CLEARANCE)
    since = f.http.get("/mission/events").json()["last_seq"]
    body = mission("land", {"type": "guarded-fly-to", "id": "go", "retries": 2,
                            "params": {"position": NORTH_6, "fly_straight_line_flag": True}})
    r = f.http.post("/mission", json=body)
    assert r.status_code == 200, r.text
    assert f.post("/mission/start").status_code == 200
    wait_for(lambda: state(f)["state"] == "failed", f.wall(90), f"the mission's failure: {state(f)}")
    seen = events(f, since)
    failed = [e for e in seen if e["event"] == "node_finished" and e["node"] == "go"]
    assert [e["state"] for e in failed] == ["failed"] * 3 and "no clearance" in failed[0]["reason"]
    assert [e["attempt"] for e in seen if e["event"] == "node_retry"] == [2, 3]
    (policy,) = [e for e in seen if e["event"] == "on_failure"]
    assert policy["policy"] == "land" and policy["applied"], policy
    assert f.gcs.ned()[2] < -1.0  # it had taken off
    wait_for(lambda: not f.gcs.armed(), f.wall(60), "landed and disarmed (the ground station sees it)")
    assert -f.gcs.ned()[2] < 0.3 and state(f)["failed_node"] == "go"

    f.http.post("/beliefs", json={"add": [CLEARANCE]})  # the operator fixes the cause
    r = f.post("/mission/resume")
    assert r.status_code == 409 and "take_off: true" in r.json()["error"]  # on the ground: say so
    r = f.post("/mission/resume", {"take_off": True})
    assert r.status_code == 200, r.text
    tree = r.json()["tree"]
    assert [c["id"] for c in tree["children"]] == ["resume-take-off", "root"]
    assert [c["id"] for c in tree["children"][1]["children"]] == ["go", "down"]
    wait_for(lambda: f.gcs.ned()[0] > 5.0, f.wall(90), "at the guarded fly-to's point")
    wait_for(lambda: state(f)["state"] == "succeeded", f.wall(90), f"the rest flown: {state(f)}")
    wait_for(lambda: not f.gcs.armed(), f.wall(30), "landed at the end")


def test_abort_with_on_failure_land_lands(flight_session: FlightSession) -> None:
    f = flight_session
    on_ground(f)
    far = [-35.363126, 149.165230, 3.0]  # 15 m north: long enough to abort on the way
    body = mission("land", {"type": "fly-to", "id": "go", "params": {"position": far, "speed": "slow",
                                                                    "fly_straight_line_flag": True}})
    assert f.http.post("/mission", json=body).status_code == 200
    assert f.post("/mission/start").status_code == 200
    wait_for(lambda: state(f)["active_node"] == "go", f.wall(60), "the fly-to")
    wait_for(lambda: f.gcs.ned()[0] > 2.0, f.wall(30), "on the way")
    r = f.post("/mission/abort")
    assert r.status_code == 200 and r.json()["state"] == "aborted"
    st = state(f)
    assert st["failure_policy"]["policy"] == "land" and st["failure_policy"]["applied"], st
    wait_for(lambda: not f.gcs.armed(), f.wall(60), "landed and disarmed after the abort")
    assert f.gcs.ned()[0] < 14.0 and -f.gcs.ned()[2] < 0.3  # landed on the way, not at the point


def test_mission_events_long_poll(flight_session: FlightSession) -> None:
    f = flight_session
    last = f.http.get("/mission/events").json()["last_seq"]
    t0 = time.monotonic()
    r = f.http.get("/mission/events", params={"since": last, "timeout": 1.0})
    assert r.status_code == 200 and r.json() == {"events": [], "last_seq": last}
    assert time.monotonic() - t0 >= 0.95  # nothing new: it waited for the deadline
    got: list[dict[str, Any]] = []
    poll = threading.Thread(target=lambda: got.append(httpx.get(
        f"{f.server.url}/mission/events", params={"since": last, "timeout": 30.0}, timeout=40).json()))
    poll.start()
    body = mission("hover", {"type": "hover", "id": "h", "params": {"duration": 1}})
    assert f.http.post("/mission", json=body).status_code == 200  # -> mission_loaded
    poll.join(35)
    assert not poll.is_alive() and got[0]["events"][0]["event"] == "mission_loaded"
    assert got[0]["events"][0]["seq"] == last + 1 and got[0]["last_seq"] >= last + 1
    assert f.http.get("/mission/events", params={"since": -1}).status_code == 400


def test_behavior_events_long_poll(flight_session: FlightSession) -> None:
    f = flight_session
    on_ground(f)
    last = f.http.get("/behaviors/events").json()["last_seq"]
    r = f.http.get("/behaviors/events", params={"since": last, "timeout": 0.5})
    assert r.json()["events"] == []
    got: list[dict[str, Any]] = []
    poll = threading.Thread(target=lambda: got.append(httpx.get(
        f"{f.server.url}/behaviors/events", params={"since": last, "timeout": 30.0}, timeout=40).json()))
    poll.start()
    r = f.post("/behaviors/activate", {"text": "GO_TO_POINT coordinate: (3, 0, 2)", "requester": "mission"})
    assert r.status_code == 409 and not r.json()["accepted"]  # on the ground: refused
    poll.join(35)
    assert not poll.is_alive()
    (refused,) = [e for e in got[0]["events"] if e["event"] == "refused"]
    assert refused["behavior"] == "GO_TO_POINT" and refused["requester"] == "mission"
    assert "flight_state" in refused["reason"]
    r = f.post("/behaviors/activate", {"text": "TAKE_OFF altitude: 2", "requester": "mission"})
    assert r.json()["accepted"], r.json()
    aid = r.json()["activation_id"]
    wait_for(lambda: any(e["event"] == "ended" and e["activation_id"] == aid for e in f.http.get(
        "/behaviors/events", params={"since": last}).json()["events"]), f.wall(60), "TAKE_OFF's end")
    seen = f.http.get("/behaviors/events", params={"since": last}).json()["events"]
    assert any(e["event"] == "started" and e["activation_id"] == aid for e in seen)
    (ended,) = [e for e in seen if e["event"] == "ended" and e["activation_id"] == aid]
    assert ended["cause"] == "goal_achieved" and ended["behavior"] == "TAKE_OFF"
    on_ground(f)
