"""A flight driven only by behavior activation requests over HTTP (seed 001).

Per autopilot (the bundled model; ArduCopter SITL with ``TASKFLIGHT_ARDUCOPTER``) one companion with
its executive layer and control surface, reached over loopback UDP through the wire tap. The
mission requester asks for TAKE_OFF, GO_TO_POINT, ROTATE and FOLLOW_PATH; an emergency LAND
pre-empts a mission GO_TO_POINT; a point outside the operational envelope ends in wrong_progress.
Termination causes and positions are asserted, the streamed setpoints are checked for continuity on
the wire, the process trace shows the delayed stop, and the flight log becomes a Fig. 10 picture.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest

from companion.flight import Envelope
from harness.flight_session import FlightSession, SessionSpec
from harness.timing import wait_for
from harness.wire_tap import wire_violations

pytestmark = pytest.mark.integration

SPEEDUP = 5.0
ENVELOPE = Envelope.box(-40, 40, -40, 40, altitude_ceiling=30.0)


FLIGHT_SESSION = SessionSpec("behaviors", SPEEDUP, behaviors=True, envelope=ENVELOPE)


def active(f: FlightSession) -> dict[str, str]:
    return {a["behavior"]: a["requester"] for a in f.http.get("/behaviors").json()["active"]}


def run_behavior(f: FlightSession, text: str, sim_s: float, requester: str = "mission") -> dict[str, Any]:
    a = f.activate(text, requester)
    assert a["accepted"], a
    return f.wait_end(a["activation_id"], sim_s)


def ensure_flying(f: FlightSession) -> None:
    wait_for(lambda: "SELF_LOCALIZE" in active(f), f.wall(30), "SELF_LOCALIZE active (a healthy estimate)")
    if f.layer is not None and f.layer.beliefs.holds("flight_state(self, flying)"):
        return
    end = run_behavior(f, "TAKE_OFF altitude: 5", 60)
    assert end["cause"] == "goal_achieved", end
    wait_for(lambda: "KEEP_HOVERING" in active(f), f.wall(5), "KEEP_HOVERING by default once flying")


def near(f: FlightSession, neu: tuple[float, float, float], tol: float, sim_s: float) -> None:
    ned = (neu[0], neu[1], -neu[2])
    f.wait_near(ned, tol, sim_s)


def test_flight_by_activation_requests(flight_session: FlightSession, tmp_path: Path) -> None:
    ensure_flying(flight_session)
    assert active(flight_session)["KEEP_HOVERING"] == "default"
    # the take-off's goal is its reference's arrival (seed 000 Fig. 8): the vehicle follows it
    wait_for(lambda: abs(flight_session.alt() - 5.0) < 0.5, flight_session.wall(5),
             lambda: f"the vehicle at 5 m (at {flight_session.alt():.2f} m)")
    end = run_behavior(flight_session, "GO_TO_POINT coordinate: (10, 0, 6)", 40)
    assert end["cause"] == "goal_achieved", end
    near(flight_session, (10, 0, 6), 1.0, 10)
    end = run_behavior(flight_session, "ROTATE angle: 90", 20)
    assert end["cause"] == "goal_achieved", end
    wait_for(lambda: abs(math.remainder(flight_session.node.link.mirror.snapshot().yaw - math.pi / 2,
                                        2 * math.pi)) < 0.1,
             flight_session.wall(5), "heading east")
    end = run_behavior(flight_session, "FOLLOW_PATH path: ((10, 10, 6), (0, 10, 7))", 60)
    assert end["cause"] == "goal_achieved", end
    near(flight_session, (0, 10, 7), 1.0, 10)
    wait_for(lambda: "KEEP_HOVERING" in active(flight_session), flight_session.wall(3),
             "KEEP_HOVERING between behaviors")
    # delayed stop: the motion controller kept running from the take-off to here; the planner stopped
    # once KEEP_HOVERING took over and started again for FOLLOW_PATH
    trace = [(e.process, e.event) for e in flight_session.layer.processes.trace]
    assert trace.count(("motion_controller", "start")) == 1 and ("motion_controller", "stop") not in trace
    assert trace.count(("trajectory_planner", "start")) == 2
    assert trace.count(("trajectory_planner", "stop")) == 2


def test_emergency_land_preempts_a_mission_go_to_point(flight_session: FlightSession) -> None:
    ensure_flying(flight_session)
    go = flight_session.activate("GO_TO_POINT coordinate: (-20, -20, 8)")
    assert go["accepted"], go
    wait_for(lambda: flight_session.speed() > 1.0, flight_session.wall(10), "on its way")
    assert flight_session.layer is not None  # emergency is no HTTP caller's: the companion's own, in-process
    land = flight_session.layer.coordinator.activate("LAND", "emergency").to_dict()
    assert land["accepted"] and land["stopped"] == ["GO_TO_POINT"], land
    assert flight_session.wait_end(go["activation_id"], 1)["cause"] == "interrupted"
    r = flight_session.post("/behaviors/activate", {"text": "GO_TO_POINT coordinate: (0, 0, 5)",
                                                    "requester": "mission"})
    again = r.json()
    assert r.status_code == 409 and not again["accepted"] and "LAND" in again["reason"] \
        and "emergency" in again["reason"], again
    end = flight_session.wait_end(land["activation_id"], 90)
    assert end["cause"] == "goal_achieved", end
    wait_for(lambda: not flight_session.armed(), flight_session.wall(30), "disarmed after landing")
    assert flight_session.alt() < 0.5
    wait_for(lambda: set(active(flight_session)) == {"SELF_LOCALIZE", "WATCH_GROUND"}, flight_session.wall(3),
             "no flight behavior on the ground")


def test_unreachable_point_never_hangs(flight_session: FlightSession) -> None:
    ensure_flying(flight_session)
    here = flight_session.pos()
    end = run_behavior(flight_session, "GO_TO_POINT coordinate: (70, 0, 6)", 10)  # outside the envelope's box
    assert end["cause"] == "wrong_progress" and "outside" in end["detail"], end
    wait_for(lambda: "KEEP_HOVERING" in active(flight_session), flight_session.wall(3),
             "KEEP_HOVERING after the failure")
    assert math.dist(flight_session.pos(), here) < 1.5  # it did not fly off


def test_bad_requests_change_nothing(flight_session: FlightSession) -> None:
    before = active(flight_session)
    for body, fragment in (({"text": "GO_TO_POINT coordinate: (1, 2)"}, "expected 3 values"),
                           ({"text": "JUMP"}, "unknown behavior"),
                           ({"behavior": "ROTATE", "params": {"angle": "north"}}, "expected a number"),
                           ({"text": "ROTATE angle: 4", "params": {}}, "'params' goes with 'behavior'"),
                           ({"text": "TAKE_OFF", "requester": "pilot"}, "unknown requester")):
        r = flight_session.post("/behaviors/activate", body)
        assert r.status_code == 400 and fragment in r.json()["error"], (body, r.text)
    r = flight_session.post("/behaviors/check", {"text": "GO_TO_POINT coordinate: (1, 2, 3)"})
    assert r.status_code == 200
    assert r.json()["params"] == {"coordinate": [1.0, 2.0, 3.0], "straight_line": True}  # with the default
    r = flight_session.http.get("/beliefs", params={"query": "flight_state(self, ?s"})
    assert r.status_code == 400 and "expected" in r.json()["error"]
    r = flight_session.post("/beliefs", {"add": ["object(57, place)", "position(57, (3.0, 4.5, ?z))"]})
    assert r.status_code == 400
    assert flight_session.http.get("/beliefs", params={"query": "object(57, ?c)"}).json()["bindings"] == []
    r = flight_session.post("/beliefs", {"add": ["object(57, place)", "name(57, point_A)"]})
    assert r.status_code == 200
    got = flight_session.http.get("/beliefs",
                                  params={"query": "object(?x, place), name(?x, ?n)"}).json()["bindings"]
    assert got == [{"x": 57, "n": "point_A"}]
    assert flight_session.post("/behaviors/joystick", {"values": [1, 0, 0, 0]}).status_code == 409
    assert active(flight_session) == before


def test_flight_continuous_on_the_wire_and_timeline(flight_session: FlightSession, tmp_path: Path) -> None:
    msgs = flight_session.tap.kept()
    if len(msgs) < 200:
        pytest.skip("run with the flight tests before it: too few setpoints on the wire")
    violations = wire_violations(msgs, flight_session.node.queue.limits)
    assert violations == [], violations[:5]
    from taskflight.cli import main

    log = flight_session.layer.log.path
    out = tmp_path / "timeline.png"
    assert main(["behaviors", "timeline", str(log), "--out", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 5000
