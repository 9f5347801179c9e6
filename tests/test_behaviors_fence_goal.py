"""A GO_TO_POINT beyond the autopilot's own fence never reports goal_achieved (seed 001 Sec. 6.2.1).

A separate ground station (pymavlink, the session's observer) sets the autopilot's circle fence
(FENCE_TYPE 2, FENCE_RADIUS 30 m, FENCE_ENABLE 1): the companion does not know it. Its operational
envelope allows a point 80 m north, so GO_TO_POINT is accepted and its setpoints fly there; the
autopilot ignores the GUIDED targets beyond its fence (ArduCopter's ``check_destination_within_fence``)
and the vehicle stops near it (the last accepted target moves on with its velocity for GUID_TIMEOUT,
3 s, then the vehicle brakes). The behavior's status is sampled over the whole run: never
``goal_achieved``; with FENCE_ACTION 0 (report only) it ends ``wrong_progress`` (or ``time_out``), with
FENCE_ACTION 1 (RTL) the autopilot takes the vehicle at the breach and it ends ``interrupted``.
Per autopilot: the bundled model; ArduCopter SITL with ``TASKFLIGHT_ARDUCOPTER``.
"""

from __future__ import annotations

import math
import threading
from typing import Any

import pytest

from companion.flight import Envelope
from companion.safety import SafetyConfig
from harness.flight_session import FlightSession, SessionSpec
from harness.timing import wait_for

pytestmark = pytest.mark.integration

SPEEDUP = 5.0
RADIUS_M = 30.0
GOAL_N = 80.0  # beyond the fence by more than GUID_TIMEOUT's 3 s of the last accepted target's velocity
# the autopilot's own fence is what stops the vehicle here: the companion's safety monitor, which would
# return it home at the breach (an emergency RTL, tests/test_safety_monitor.py), is off
FLIGHT_SESSION = SessionSpec("fence_goal", SPEEDUP, behaviors=True, localized=True,
                             envelope=Envelope.box(-100, 100, -100, 100, altitude_ceiling=30.0),
                             safety=SafetyConfig(enabled=False))


def ensure_flying_home(f: FlightSession) -> None:
    """Flying at 5 m over home, the fence off (each test also runs alone)."""
    f.gcs.set_param("FENCE_ENABLE", 0)
    if f.layer is not None and f.layer.beliefs.holds("flight_state(self, flying)"):
        go = f.activate("GO_TO_POINT coordinate: (0, 0, 5)")
    else:
        go = f.activate("TAKE_OFF altitude: 5")
    assert go["accepted"], go
    wait_for(lambda: f.ended(go["activation_id"]) is not None, f.wall(90), f"{go['behavior']} ended")
    assert f.ended(go["activation_id"])["cause"] == "goal_achieved"  # type: ignore[index]


def fly_beyond_the_fence(f: FlightSession, action: int) -> tuple[list[str], dict[str, Any], float]:
    """GO_TO_POINT 80 m north under the autopilot's 30 m circle fence with FENCE_ACTION ``action``: the
    behavior's state sampled every 50 ms of wall time until it ended, its end, the farthest distance."""
    ensure_flying_home(f)
    for name, value in (("FENCE_TYPE", 2), ("FENCE_RADIUS", RADIUS_M), ("FENCE_ACTION", action),
                        ("FENCE_ENABLE", 1)):
        f.gcs.set_param(name, value)  # another ground station: the companion is not told
    go = f.activate(f"GO_TO_POINT coordinate: ({GOAL_N:g}, 0, 5)")
    assert go["accepted"], go
    aid = go["activation_id"]
    samples: list[str] = []  # "active" or the end's cause, per sample
    farthest = [0.0]
    stop = threading.Event()

    def sample() -> None:
        while not stop.is_set():
            view = f.http.get("/behaviors").json()
            end = next((e for e in view["ended"] if e["activation_id"] == aid), None)
            samples.append(end["cause"] if end else
                           "active" if any(a["activation_id"] == aid for a in view["active"]) else "?")
            n, e, _ = f.pos()
            farthest[0] = max(farthest[0], math.hypot(n, e))
            stop.wait(0.05)

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    try:
        wait_for(lambda: f.ended(aid) is not None, f.wall(200), "end of the GO_TO_POINT")
    finally:
        stop.set()
        sampler.join(5)
    end = f.ended(aid)
    assert end is not None
    assert samples.count("active") > 10, samples[:20]
    return samples, end, farthest[0]


def test_go_to_point_beyond_the_autopilots_fence_is_never_achieved(flight_session: FlightSession) -> None:
    """FENCE_ACTION 0 (report only): the autopilot keeps GUIDED and ignores the targets beyond its fence."""
    samples, end, farthest = fly_beyond_the_fence(flight_session, 0)
    assert "goal_achieved" not in samples, samples[-20:]
    assert end["cause"] in ("wrong_progress", "time_out"), end
    assert farthest < GOAL_N - 10.0, farthest  # held short of the point by the fence
    f = flight_session
    wait_for(lambda: "KEEP_HOVERING" in {a["behavior"] for a in f.http.get("/behaviors").json()["active"]},
             f.wall(5), "KEEP_HOVERING after the failure")
    f.wait_still(20)
    held = f.pos()
    f.gcs.set_param("FENCE_ENABLE", 0)  # the fence lifted: the vehicle hovers where it is, it does not fly on
    f.sim_wait(10)
    assert math.dist(f.pos()[:2], held[:2]) < 3.0, (held, f.pos())
    ensure_flying_home(f)


def test_fence_breach_rtl_interrupts_and_is_never_achieved(flight_session: FlightSession) -> None:
    """FENCE_ACTION 1 (RTL, ArduCopter's default): the autopilot takes the vehicle at the breach."""
    samples, end, _ = fly_beyond_the_fence(flight_session, 1)
    assert "goal_achieved" not in samples, samples[-20:]
    assert end["cause"] in ("wrong_progress", "time_out", "interrupted"), end
    flight_session.gcs.set_param("FENCE_ENABLE", 0)


def test_speed_beyond_the_envelope_is_refused_over_http(flight_session: FlightSession) -> None:
    """No silent clamp: the format check holds a speed against the queue's limits (400 with the reason)."""
    f = flight_session
    for path in ("/behaviors/activate", "/behaviors/check"):
        r = f.post(path, {"text": "GO_TO_POINT coordinate: (10, 0, 5) speed: 20"})
        assert r.status_code == 400, r.text
        reason = r.json()["error"]
        assert "speed: 20 m/s is beyond the flight envelope's horizontal speed limit 5 m/s" in reason
    r = f.post("/behaviors/check", {"text": "GO_TO_POINT coordinate: (10, 0, 5) speed: 5"})
    assert r.status_code == 200 and r.json()["params"]["speed"] == 5.0
