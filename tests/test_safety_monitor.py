"""The companion's safety monitor on the model: a battery that cannot bring the vehicle home.

A mission flies 16 m out and holds there; the model's pack is then made too small for the way back
(``SIM_BATT_CAP_AH``, as ArduPilot SITL names it, set by a separate pymavlink ground station; the
autopilot's own battery failsafe is off, so only the companion can act). The safety monitor, the one
user of the ``emergency`` requester, must take the vehicle down: the mission reports the monitor's
reason, the team-less companion's ``GET /safety`` shows the decision, a mission or operator request
cannot replace the emergency behavior, and the independent observer sees the vehicle disarmed on the
ground.
"""

from __future__ import annotations

import math
from typing import Any

import pytest

from harness.flight_session import FlightSession, SessionSpec
from harness.timing import wait_for

pytestmark = pytest.mark.integration

SPEEDUP = 3.0
FLIGHT_SESSION = SessionSpec("safety", SPEEDUP, autopilots=[pytest.param("model", id="model")],
                             localized=True, missions=True)
HOME_LAT = -35.363261
FAR_N = 16.0
FAR_LAT = HOME_LAT + FAR_N / 111_320.0
MISSION = f"""
mission: far-out
tree:
  type: S
  id: mission
  children:
    - {{type: take-off, id: take-off}}
    - {{type: fly-to, id: out, params: {{position: [{FAR_LAT:.7f}, 149.165230, 3.0], speed: fast,
                                         fly_straight_line_flag: true}}}}
    - {{type: wait, id: hold, params: {{duration: 300}}}}
    - {{type: land, id: land}}
"""


def mission(f: FlightSession) -> dict[str, Any]:
    return f.http.get("/mission").json()


def test_the_safety_monitor_lands_a_vehicle_whose_battery_cannot_bring_it_home(
        flight_session: FlightSession) -> None:
    f = flight_session
    f.ensure_on_ground()
    for name in ("BATT_FS_LOW_ACT", "BATT_FS_CRT_ACT"):  # the autopilot's own battery failsafe: off
        f.gcs.set_param(name, 0)
    r = f.http.post("/mission", content=MISSION, headers={"Content-Type": "application/yaml"})
    assert r.status_code == 200, r.text
    assert f.post("/mission/start").status_code == 200
    wait_for(lambda: mission(f)["active_node"] == "hold" and math.dist(f.pos()[:2], (FAR_N, 0.0)) < 1.0,
             f.wall(90), lambda: f"holding {FAR_N:g} m out ({mission(f)['active_node']}, at {f.pos()})")
    s = f.node.vehicle_status()
    assert s.battery_consumed_mah is not None and s.battery_current is not None, s
    # what the way home needs (the monitor's own estimate: 16 m at the queue's 5 m/s, 3 m down at 1 m/s)
    needed = s.battery_current * (FAR_N / f.node.queue.limits.horizontal_speed + f.alt() / 1.0) / 3.6
    assert not f.http.get("/safety").json()["decisions"]  # nothing decided before
    f.gcs.set_param("SIM_BATT_CAP_AH", round((s.battery_consumed_mah + 0.4 * needed) / 1000.0, 4))

    wait_for(lambda: f.http.get("/safety").json()["last_decision"] is not None, f.wall(10),
             "a decision of the safety monitor")
    safety = f.http.get("/safety").json()
    decision = safety["last_decision"]
    assert decision["check"] == "battery" and decision["accepted"], safety
    assert decision["behavior"] == "LAND" and "cannot bring the vehicle home" in decision["reason"], decision
    assert "battery" in safety["watching"] and safety["thresholds"]["battery_margin"] == 1.5
    # the mission says why it stopped
    m = mission(f)
    assert m["state"] == "aborted", m
    assert "safety monitor" in m["fail_reason"] and "battery" in m["fail_reason"], m
    active = {a["behavior"]: a["requester"] for a in f.http.get("/behaviors").json()["active"]}
    assert active.get(decision["behavior"]) == "emergency", active
    # a lower requester cannot replace the emergency behavior (the coordinator's priority)
    for requester in ("mission", "operator"):
        r = f.post("/behaviors/activate", {"text": f"GO_TO_POINT coordinate: ({FAR_N}, 0, 3)",
                                           "requester": requester})
        assert r.status_code == 409 and not r.json()["accepted"], r.text
        assert "emergency" in r.json()["reason"], r.text
    # judged on the vehicle, by the independent observer
    f.gcs.wait_autopilot_disarmed(f.wall(90))
    assert -f.gcs.ned()[2] < 0.5

    def ended() -> list[dict[str, Any]]:
        return [e for e in f.http.get("/behaviors").json()["ended"]
                if e["activation_id"] == decision["activation_id"]]
    wait_for(lambda: ended(), f.wall(10), "the emergency LAND's end")
    assert ended()[0]["cause"] == "goal_achieved", ended()
