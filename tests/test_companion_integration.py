"""The companion flying the bundled model over loopback UDP (issue 4 "done means"; seed 000 Sec. IV-V).

One model process (lockstep, ``SPEEDUP`` x) for the module, reached through a :class:`WireTap` that
counts what the companion puts on the wire; one :class:`QuadNode` with its HTTP control surface; a
pymavlink ground station. The tests run in file order as one flight: take-off, three WithHor
waypoints, a heading Point, a wait, a joystick ExtVel segment ended by user_confirm, pause_direct and
run, pause_after_current, stop, reset, landing; then take-off again, a GCS override to LOITER, and the
loss of the companion. Every streamed setpoint is recorded for the continuity test. Deadlines are
wall time derived from simulated durations.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import mavlink_support
import pytest
from companion_support import WireTap, cmd
from mavlink_support import GUIDED, LAND, LOITER, RTL, Gcs, SitlProcess, free_port, wait_for

from companion.control import ControlServer
from companion.flight import Setpoint
from companion.flight.simulate import step_violations
from companion.node import QuadNode

# 5x (not the support module's 10x): the companion, the HTTP surface and the joystick feed run on the
# wall clock, so a slower model leaves a loaded 2-core CI machine room to keep up
SPEEDUP = 5.0


def wall(sim_s: float) -> float:
    return mavlink_support.wall(sim_s, SPEEDUP)


class Flight:
    """Everything the tests share."""

    def __init__(self, state_dir: Path) -> None:
        port = free_port()
        self.sitl = SitlProcess(
            [f"udpin:127.0.0.1:{port}"], state_dir, speedup=SPEEDUP, extra=["--no-persist"]
        )
        self.tap = WireTap(port)
        self.gcs = Gcs(port, SPEEDUP, background=True)
        self.node = QuadNode(f"udpout:127.0.0.1:{self.tap.port}", rate_hz=20.0)
        self.streamed: list[Setpoint] = []
        self.node.setpoint_listeners.append(lambda sp, f, t: self.streamed.append(sp))
        self.node.start()
        self.server = ControlServer(self.node, port=0).start()
        self.http = httpx.Client(base_url=self.server.url, timeout=10.0)

    # --- helpers ---------------------------------------------------------------------------------------
    def post(self, path: str, body: Any = None) -> httpx.Response:
        return self.http.post(path, json=body) if body is not None else self.http.post(path)

    def status(self) -> dict[str, Any]:
        return self.node.queue.status().to_dict()

    def pos(self) -> tuple[float, float, float]:
        p = self.node.link.mirror.snapshot().position
        assert p is not None
        return p

    def speed(self) -> float:
        return math.hypot(*self.node.link.mirror.snapshot().velocity)

    def wait_index(self, index: int, sim_s: float) -> None:
        wait_for(
            lambda: self.status()["current_command_index"] >= index,
            wall(sim_s),
            f"command index {index} (status {self.status()})",
        )

    def wait_near(self, target: tuple[float, float, float], tol: float, sim_s: float) -> None:
        wait_for(
            lambda: math.dist(self.pos(), target) < tol,
            wall(sim_s),
            f"vehicle within {tol} m of {target} (at {self.pos()})",
        )

    def wait_still(self, sim_s: float) -> None:
        wait_for(lambda: self.speed() < 0.3, wall(sim_s), f"vehicle at rest (speed {self.speed():.2f})")

    def sim_time(self) -> float:
        return self.node.clock.now()

    def close(self) -> None:
        self.http.close()
        self.server.close()
        self.node.close()
        self.gcs.close()
        self.tap.close()
        self.sitl.stop()


@pytest.fixture(scope="module")
def f(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Flight]:
    flight = Flight(tmp_path_factory.mktemp("companion_sitl"))
    try:
        wait_for(lambda: flight.node.link.mirror.snapshot().position is not None, 30, "telemetry")
        yield flight
    finally:
        flight.close()


def test_takeoff(f: Flight) -> None:
    r = f.post(
        "/commands", {"vertical": {"mode": "POS", "altitude": 5, "take_off": True}, "end": {"e_v": True}}
    )
    assert r.status_code == 200, r.text
    assert r.json() == {"indices": [0]}
    assert f.post("/run").status_code == 200
    wait_for(lambda: f.node.supervisor.phase.value == "ENGAGED", wall(10), "airborne")
    st = f.status()
    assert st["queue_system_status"] == "RUNNING" and st["queue_status"] == "RUNNING"
    f.wait_index(1, 15)
    f.wait_near((0.0, 0.0, -5.0), 0.8, 10)
    snap = f.node.link.mirror.snapshot()
    assert snap.mode == GUIDED and snap.armed
    st = f.status()
    assert st["current_command_status"] == "UNKNOWN"  # nothing after the take-off yet
    wait_for(lambda: f.status()["is_synced"], wall(3), "is_synced (POSITION_TARGET_LOCAL_NED echo)")


def test_three_waypoints_with_hor(f: Flight) -> None:
    wps = [(10.0, 0.0, 6.0), (10.0, 10.0, 8.0), (0.0, 10.0, 6.0)]
    for n, e, alt in wps:
        f.node.add_command(
            cmd(
                {
                    "horizontal": {"mode": "POS", "north": n, "east": e},
                    "vertical": {"mode": "WITH_HOR", "altitude": alt},
                    "end": {"e_h": True, "e_v": True},
                }
            )
        )
    for i, (n, e, alt) in enumerate(wps, start=1):
        f.wait_index(i + 1, 30)
        # the command ends when the reference arrives; the vehicle is close behind
        f.wait_near((n, e, -alt), 1.0, 5)
        assert f.status()["queue_status"] == "RUNNING"
    f.wait_near((0.0, 10.0, -6.0), 0.5, 5)


def test_heading_point(f: Flight) -> None:
    # look at a point due south-east of the vehicle (at (0, 10))
    f.node.add_command(
        cmd({"heading": {"mode": "POINT", "north": -20.0, "east": 30.0}, "end": {"e_hd": True}})
    )
    f.wait_index(5, 15)
    expected = math.atan2(30.0 - 10.0, -20.0 - 0.0)
    wait_for(
        lambda: (
            abs(math.remainder(f.node.link.mirror.snapshot().yaw - expected, 2 * math.pi)) < math.radians(8)
        ),
        wall(5),
        "yaw towards the point",
    )
    assert math.dist(f.pos()[:2], (0.0, 10.0)) < 1.0


def test_wait(f: Flight) -> None:
    t0 = f.sim_time()
    f.node.add_command(cmd({"end": {"e_wait": 3.0}}))
    f.wait_index(6, 10)
    # two ticks of slack: the test reads its estimate of the autopilot clock between the node's ticks
    assert f.sim_time() - t0 >= 3.0 - 0.1
    assert math.dist(f.pos(), (0.0, 10.0, -6.0)) < 1.0


def test_joystick_ext_vel_until_user_confirm(f: Flight) -> None:
    f.node.add_command(
        cmd(
            {
                "horizontal": {"mode": "EXT_VEL"},
                "vertical": {"mode": "EXT_VEL"},
                "heading": {"mode": "EXT_VEL"},
                "end": {"e_user": True},
            }
        )
    )
    wait_for(lambda: f.status()["confirmation_required_status"], wall(3), "confirmation required")
    start = f.pos()
    t_end = f.sim_time() + 4.0
    while f.sim_time() < t_end:  # a joystick pushing north at 1.5 m/s, 10 Hz of simulated time
        # validity 2 s: a late HTTP round trip on a busy machine must not let the sample go stale (the
        # stale -> zero-velocity behaviour is the flight layer's unit tests' business)
        r = f.post("/external/ext_vel", {"values": [1.5, 0.0, 0.0, 0.0], "validity_s": 2.0})
        assert r.status_code == 200, r.text
        t_next = f.sim_time() + 0.1
        wait_for(lambda t=t_next: f.sim_time() >= t, 2, "0.1 s of simulated time", 0.002)
    moved = f.pos()[0] - start[0]
    assert moved > 3.0, f"the joystick moved the vehicle {moved:.2f} m north"
    assert f.node.link.stats["tx_setpoint"] > 0
    assert f.post("/user_confirm").status_code == 200
    f.wait_index(7, 3)
    f.wait_still(6)  # the stream went stale / the next command holds: it stops


def test_pause_direct_then_run(f: Flight) -> None:
    here = f.pos()
    target = (here[0], here[1] + 20.0, -6.0)
    f.node.add_command(
        cmd(
            {
                "horizontal": {"mode": "POS", "north": target[0], "east": target[1], "speed": 3.0},
                "vertical": {"mode": "POS", "altitude": 6.0},
                "end": {"e_h": True, "e_v": True},
            }
        )
    )
    wait_for(lambda: f.speed() > 2.0, wall(8), "flying east")
    assert f.post("/pause_direct").status_code == 200
    st = f.status()
    assert st["queue_status"] == "WAITING_FOR_BEHAVIOR_AND_CONTINUING"
    assert st["current_command_status"] == "PAUSED" and st["current_command_index"] == 7
    assert st["confirmation_required_status"]  # the hover behaviour ends on user_confirm
    f.wait_still(8)
    paused_at = f.pos()
    assert math.dist(paused_at, target) > 5.0
    assert f.post("/run").status_code == 200
    assert f.status()["current_command_status"] == "RUNNING"
    f.wait_index(8, 20)
    f.wait_near(target, 1.0, 5)


def test_pause_after_current(f: Flight) -> None:
    a = (f.pos()[0] - 10.0, f.pos()[1], -6.0)
    b = (a[0], a[1] - 10.0, -6.0)
    for n, e, d in (a, b):
        f.node.add_command(
            cmd(
                {
                    "horizontal": {"mode": "POS", "north": n, "east": e},
                    "vertical": {"mode": "POS", "altitude": -d},
                    "end": {"e_h": True, "e_v": True},
                }
            )
        )
    wait_for(lambda: f.speed() > 1.0, wall(5), "flying to A")
    assert f.post("/pause_after_current", {"behaviour_id": "hover"}).status_code == 200
    assert f.status()["queue_status"] == "RUNNING"  # still flying the current command
    wait_for(
        lambda: f.status()["queue_status"] == "WAITING_FOR_BEHAVIOR_AND_CONTINUING", wall(15), "the pause"
    )
    st = f.status()
    assert st["current_command_index"] == 9 and st["current_command_status"] == "PAUSED"
    f.wait_near(a, 1.0, 5)
    f.wait_still(5)
    held = f.pos()
    t = f.sim_time() + 2.0
    wait_for(lambda: f.sim_time() >= t, wall(2), "2 s hovering")
    # held on the (GPS-grade) estimate: decimetres of jitter, no drift
    assert math.dist(f.pos(), held) < 0.8 and f.status()["current_command_index"] == 9
    assert f.post("/user_confirm").status_code == 200  # ends the hover behaviour: on to B
    f.wait_index(10, 20)
    f.wait_near(b, 1.0, 5)


def test_stop_then_reset_mid_flight(f: Flight) -> None:
    far = (f.pos()[0] + 40.0, f.pos()[1], -6.0)
    f.node.add_command(
        cmd(
            {
                "horizontal": {"mode": "POS", "north": far[0], "east": far[1], "speed": 3.0},
                "vertical": {"mode": "POS", "altitude": 6.0},
                "end": {"e_h": True},
            }
        )
    )
    wait_for(lambda: f.speed() > 2.0, wall(8), "flying north")
    assert f.post("/stop").status_code == 200
    st = f.status()
    assert st["queue_status"] == "STOPPED" and st["current_command_status"] == "STOPPED"
    f.wait_still(8)
    stopped_at = f.pos()
    assert math.dist(stopped_at, far) > 20.0
    assert f.post("/run").status_code == 200  # resumes the stopped command
    wait_for(lambda: f.speed() > 2.0, wall(8), "flying north again")
    assert f.post("/reset").status_code == 200
    st = f.status()
    assert st["queue_status"] == "STOPPED" and st["current_command_index"] == 0
    assert st["current_command_status"] == "UNKNOWN" and f.node.queue.commands == ()
    f.wait_still(8)
    hover = f.pos()
    t = f.sim_time() + 2.0
    wait_for(lambda: f.sim_time() >= t, wall(2), "2 s")
    assert math.dist(f.pos(), hover) < 0.8, "hovers where it is after reset"
    assert math.dist(hover, far) > 10.0
    assert f.node.supervisor.phase.value == "ENGAGED"


def test_bad_input_changes_nothing(f: Flight) -> None:
    before = (f.status(), f.node.queue.commands)
    cases = [
        ("/commands", {"horizontal": {"mode": "POS", "north": 1.0}, "end": {"e_h": True}}, 400, "east"),
        ("/commands", {"vertical": {"mode": "DNU"}, "end": {"e_v": True}}, 400, "e_v"),
        ("/commands", {"commands": [{"end": {"e_wait": 1}}, {"end": {}}]}, 400, "commands[1]"),
        ("/user_confirm", None, 409, "nothing is waiting"),
        ("/external/ext_vel", {"values": [1.0, 2.0], "validity_s": 0.5}, 400, "4 values"),
        ("/external/ext_vel", {"values": [1.0, 0.0, 0.0, 0.0], "validity_s": -1}, 400, "validity"),
        ("/external/no_such", {"values": [1.0]}, 400, "unknown stream"),
        ("/pause_direct", {"behaviour_id": "nope"}, 400, "unknown behaviour"),
    ]
    for path, body, code, text in cases:
        r = f.post(path, body)
        assert r.status_code == code, (path, r.text)
        assert text in r.json()["error"], r.json()
    r = f.http.post("/commands", content=b"{not json")
    assert r.status_code == 400 and "malformed JSON" in r.json()["error"]
    after = (f.status(), f.node.queue.commands)
    assert after == before


def test_landing_with_allow_landing(f: Flight) -> None:
    here = f.pos()
    f.node.add_command(
        cmd({"vertical": {"mode": "POS", "altitude": 0.0, "allow_landing": True}, "end": {"e_v": True}})
    )
    f.node.run()
    wait_for(lambda: f.node.link.mirror.snapshot().mode == LAND, wall(15), "LAND mode")
    wait_for(lambda: not f.node.link.mirror.snapshot().armed, wall(30), "landed and disarmed")
    f.wait_index(1, 5)
    assert math.dist(f.pos()[:2], here[:2]) < 1.5
    assert f.pos()[2] > -0.5
    wait_for(lambda: f.node.supervisor.phase.value == "IDLE", wall(2), "link idle after the landing")


def test_streamed_setpoints_are_continuous(f: Flight) -> None:
    assert len(f.streamed) > 500
    violations = step_violations(f.streamed, f.node.queue.limits)
    assert violations == [], violations[:5]


def test_override_by_gcs_stops_streaming(f: Flight) -> None:
    f.node.reset()
    f.node.add_command(
        cmd({"vertical": {"mode": "POS", "altitude": 5, "take_off": True}, "end": {"e_v": True}})
    )
    f.node.add_command(
        cmd(
            {
                "horizontal": {"mode": "POS", "north": 30.0, "east": 0.0, "speed": 3.0},
                "vertical": {"mode": "POS", "altitude": 5.0},
                "end": {"e_h": True},
            }
        )
    )
    f.node.run()
    f.wait_index(1, 20)
    wait_for(lambda: f.speed() > 2.0, wall(8), "flying north")
    assert f.gcs.set_mode(LOITER) == 0
    wait_for(lambda: f.status()["queue_system_status"] == "OVERRIDDEN", wall(2), "OVERRIDDEN")
    st = f.status()
    assert st["queue_status"] == "STOPPED" and not st["is_synced"]
    assert "LOITER" in (f.node.supervisor.override_reason or "")
    t = f.sim_time() + 0.3
    wait_for(lambda: f.sim_time() >= t, wall(1), "in-flight packets")
    count = f.tap.count("SET_POSITION_TARGET_LOCAL_NED")
    t = f.sim_time() + 3.0
    wait_for(lambda: f.sim_time() >= t, wall(3), "3 s")
    assert f.tap.count("SET_POSITION_TARGET_LOCAL_NED") == count, "setpoints still sent after the override"
    assert f.node.link.mirror.snapshot().mode == LOITER
    # verbs that need the vehicle are refused while overridden
    assert f.post("/run").status_code == 409
    # the GCS gives the vehicle back: the override is lifted, the queue waits for run()
    assert f.gcs.set_mode(GUIDED) == 0
    wait_for(lambda: f.status()["queue_system_status"] == "RUNNING", wall(2), "override lifted")
    assert f.status()["queue_status"] == "STOPPED"


def test_companion_loss_stops_within_guid_timeout(f: Flight) -> None:
    """ArduCopter (ModeGuided posvelaccel): without new targets the velocity and acceleration feed-forward
    are zeroed after GUID_TIMEOUT and the vehicle brakes and holds. Until then the last target's
    feed-forward is integrated, so a companion that dies while accelerating leaves the vehicle
    accelerating for up to GUID_TIMEOUT (ArduCopter's update_pos_vel_accel does the same).

    Judged on positions (the estimated speed of an outdoor GPS-grade estimate jitters by a few dm/s)."""
    f.gcs.set_param("FS_GCS_ENABLE", 1)
    f.gcs.set_param("GUID_TIMEOUT", 3.0)
    f.node.run()
    wait_for(lambda: f.speed() > 2.0, wall(10), "flying north again")
    f.node.close()  # the companion dies mid-flight
    f.t_loss = f.sim_time()  # type: ignore[attr-defined]
    m0 = f.gcs.msg("LOCAL_POSITION_NED")
    p_loss, v_loss = (m0.x, m0.y), (m0.vx, m0.vy)
    track: list[tuple[float, tuple[float, float, float]]] = []

    def stopped() -> bool:
        m = f.gcs.msg("LOCAL_POSITION_NED")
        t = m.time_boot_ms / 1000.0
        if not track or t > track[-1][0]:
            track.append((t, (m.x, m.y, m.z)))
        old = [s for s in track if s[0] <= t - 1.0]
        return bool(old) and math.dist(old[-1][1], track[-1][1]) < 0.3

    # GUID_TIMEOUT (3 s) with the feed-forward, then a jerk-limited stop from at most the envelope speed
    wait_for(stopped, wall(12.0), "stopped after GUID_TIMEOUT")
    t_stop, held = track[-1]
    assert t_stop - f.t_loss < 3.0 + 8.0  # type: ignore[attr-defined]
    # no fly-back: it stopped ahead of where it was at the loss, along its direction of motion
    ahead = (held[0] - p_loss[0]) * v_loss[0] + (held[1] - p_loss[1]) * v_loss[1]
    assert ahead > 0.0
    t = int((t_stop + 3.0) * 1000)
    wait_for(lambda: f.gcs.msg("LOCAL_POSITION_NED").time_boot_ms >= t, wall(4), "3 s")
    now = f.gcs.msg("LOCAL_POSITION_NED")
    assert math.dist((now.x, now.y, now.z), held) < 0.7, "holds where it stopped"


def test_gcs_failsafe_only_when_the_gcs_is_lost(f: Flight) -> None:
    """The companion's heartbeat is not a GCS heartbeat (ArduCopter counts system MAV_GCS_SYSID only):
    while the GCS is there nothing happens after the companion's loss; when the ground link goes too,
    FS_GCS_ENABLE's action (1: RTL) follows FS_GCS_TIMEOUT (5 s)."""
    if not hasattr(f, "t_loss"):
        f.node.close()
        f.t_loss = f.sim_time()  # type: ignore[attr-defined]
    assert f.gcs.msg("PARAM_VALUE") is not None
    t = int((f.t_loss + 8.0) * 1000)  # type: ignore[attr-defined]
    wait_for(lambda: f.gcs.msg("LOCAL_POSITION_NED").time_boot_ms >= t, wall(8), "8 s after the loss")
    assert f.gcs.mode() == GUIDED, "no failsafe while the GCS is connected"
    f.gcs.heartbeats.clear()
    wait_for(lambda: f.gcs.mode() == RTL, wall(5 + 3), "GCS failsafe RTL")
