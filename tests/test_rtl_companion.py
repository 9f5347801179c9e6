"""RTL on the companion, flying each autopilot (the model; ArduCopter SITL with ``TASKFLIGHT_ARDUCOPTER``).

``POST /rtl`` activates the RTL behavior as the caller's requester: the vehicle climbs to the return
altitude, flies home inside the envelope and lands; the behavior ends ``goal_achieved`` only once the
vehicle is measured on the ground at home, which an independent pymavlink ground station confirms
(disarmed, at home). An emergency LAND (the safety monitor's requester, asked in-process: no HTTP caller
may claim it) cannot be replaced by the mission or the operator, through ``/behaviors/activate`` or
``/rtl``.
"""

from __future__ import annotations

import math

import pytest

from companion.flight import Envelope
from harness.flight_session import FlightSession, SessionSpec

pytestmark = pytest.mark.integration

SPEEDUP = 5.0
FLIGHT_SESSION = SessionSpec("rtl", SPEEDUP, localized=True, behaviors=True,
                             envelope=Envelope.box(-40, 40, -40, 40, altitude_ceiling=30.0))


def fly_out(f: FlightSession, point: tuple[float, float, float]) -> None:
    if not f.armed() or f.alt() < 1.0:
        take_off = f.activate("TAKE_OFF altitude: 5")
        assert take_off["accepted"], take_off
        assert f.wait_end(take_off["activation_id"], 60)["cause"] == "goal_achieved"
    go = f.activate(f"GO_TO_POINT coordinate: ({point[0]}, {point[1]}, {point[2]})")
    assert go["accepted"], go
    assert f.wait_end(go["activation_id"], 60)["cause"] == "goal_achieved"


def test_post_rtl_brings_the_vehicle_home_and_it_lands(flight_session: FlightSession) -> None:
    f = flight_session
    r = f.post("/rtl")
    assert r.status_code == 409 and "flight_state" in r.json()["error"], r.text  # on the ground: refused
    fly_out(f, (15.0, 10.0, 5.0))
    r = f.post("/rtl", {"altitude": 8})
    assert r.status_code == 200, r.text
    answer = r.json()
    assert answer["accepted"] and answer["behavior"] == "RTL", answer
    assert answer["stopped"] == ["KEEP_HOVERING"], answer
    rtl = next(a for a in f.http.get("/behaviors").json()["active"] if a["behavior"] == "RTL")
    assert rtl["requester"] == "operator" and rtl["return_altitude"] == 8.0, rtl
    t0 = f.sim_time()
    # the independent observer: disarmed, on the ground, at home
    f.gcs.wait_autopilot_disarmed(f.wall(120))
    n, e, d = f.gcs.ned()
    assert math.hypot(n, e) < 2.0 and -d < 0.5, (n, e, d)
    top = max(alt for _, _, alt in f.heard_since(t0))
    assert top > 7.0, f"climbed to the return altitude first (highest {top:.1f} m)"
    end = f.wait_end(answer["activation_id"], 10)
    assert end["cause"] == "goal_achieved", end


def test_lower_requesters_cannot_replace_an_emergency_land(flight_session: FlightSession) -> None:
    f = flight_session
    fly_out(f, (5.0, 0.0, 5.0))
    assert f.layer is not None
    land = f.layer.coordinator.activate("LAND", "emergency")  # as the safety monitor asks
    assert land.accepted, land
    for requester in ("mission", "operator"):
        r = f.post("/behaviors/activate", {"text": "GO_TO_POINT coordinate: (10, 0, 5)",
                                           "requester": requester})
        go = r.json()
        assert r.status_code == 409 and not go["accepted"], r.text
        assert "LAND (requested by emergency" in go["reason"], go
        r = f.post("/rtl", {"requester": requester})
        assert r.status_code == 409 and "emergency" in r.json()["error"], r.text
    r = f.post("/rtl", {"requester": "emergency"})
    assert r.status_code == 403, r.text
    r = f.post("/behaviors/inhibit", {"behavior": "LAND", "requester": "operator"})
    inhibit = r.json()
    assert r.status_code == 409 and not inhibit["accepted"] and "priority" in inhibit["reason"], r.text
    active = {a["behavior"]: a["requester"] for a in f.http.get("/behaviors").json()["active"]}
    assert active.get("LAND") == "emergency", active
    f.gcs.wait_autopilot_disarmed(f.wall(90))
    assert f.wait_end(str(land.activation_id), 10)["cause"] == "goal_achieved"
