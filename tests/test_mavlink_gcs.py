"""pymavlink as a ground station against the model over loopback UDP (lockstep, 10x).

One SITL process for the module; the tests run in file order and each leaves the vehicle in a known
state (on the ground, disarmed) or says what it expects. Deadlines are wall time derived from the
simulated durations; nothing sleeps and hopes.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil
from test_mavlink_support import SitlProcess, free_port

SPEEDUP = 10.0
M = mavutil.mavlink
STABILIZE, ALT_HOLD, GUIDED, LOITER, LAND = 0, 2, 4, 5, 9
IGNORE_VEL_ACC_YAW = 0b110111111000
IGNORE_POS_ACC_YAW = 0b110111000111


def wall(sim_s: float) -> float:
    """Wall deadline for ``sim_s`` simulated seconds (slack for a loaded 2-core machine)."""
    return 5.0 + 3.0 * sim_s / SPEEDUP


class Gcs:
    """A pymavlink ground station: keeps the latest message of each type and the STATUSTEXTs."""

    def __init__(self, port: int) -> None:
        mavutil.set_dialect("ardupilotmega")
        self.conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=255,
                                               source_component=190)
        self.last: dict[str, Any] = {}
        self.texts: list[str] = []
        self.acks: list[Any] = []
        self.params: dict[str, tuple[float, int]] = {}
        self._hb_t = 0.0

    def pump(self) -> None:
        now = time.monotonic()
        if now - self._hb_t > 0.1:  # 1 Hz in simulated time at 10x
            self._hb_t = now
            self.conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        while True:
            m = self.conn.recv_match(blocking=False)
            if m is None:
                return
            t = m.get_type()
            self.last[t] = m
            if t == "STATUSTEXT":
                self.texts.append(m.text)
            elif t == "COMMAND_ACK":
                self.acks.append(m)
            elif t == "PARAM_VALUE":
                self.params[m.param_id] = (m.param_value, m.param_index)

    def wait(self, pred: Callable[[], Any], timeout_s: float, what: str) -> Any:
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            self.pump()
            r = pred()
            if r:
                return r
            time.sleep(0.002)
        raise AssertionError(f"timed out waiting for {what}; last texts {self.texts[-5:]}")

    def msg(self, t: str) -> Any:
        return self.wait(lambda: self.last.get(t), 10, t)

    def fresh(self, t: str, timeout_s: float = 5.0) -> Any:
        self.last.pop(t, None)
        return self.wait(lambda: self.last.get(t), timeout_s, t)

    def command(self, cmd: int, *p: float) -> int:
        params = list(p) + [0.0] * (7 - len(p))
        self.acks.clear()
        self.conn.mav.command_long_send(1, 1, cmd, 0, *params)
        ack = self.wait(lambda: next((a for a in self.acks if a.command == cmd), None), 10, f"ACK of {cmd}")
        return ack.result

    def set_mode(self, mode: int) -> int:
        return self.command(M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, mode)

    def mode(self) -> int:
        return self.fresh("HEARTBEAT").custom_mode

    def armed(self) -> bool:
        return bool(self.fresh("HEARTBEAT").base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)

    def ned(self) -> tuple[float, float, float]:
        m = self.fresh("LOCAL_POSITION_NED")
        return m.x, m.y, m.z

    def at(self, target: tuple[float, float, float], tol: float, sim_s: float) -> None:
        def close() -> bool:
            m = self.last.get("LOCAL_POSITION_NED")
            return m is not None and math.dist((m.x, m.y, m.z), target) < tol
        self.last.pop("LOCAL_POSITION_NED", None)
        self.wait(close, wall(sim_s), f"position {target}")

    def local_target(self, frame: int, mask: int, x: float = 0, y: float = 0, z: float = 0,
                     vx: float = 0, vy: float = 0, vz: float = 0) -> None:
        self.conn.mav.set_position_target_local_ned_send(0, 1, 1, frame, mask, x, y, z, vx, vy, vz,
                                                         0, 0, 0, 0, 0)


@pytest.fixture(scope="module")
def gcs(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Gcs]:
    port = free_port()
    sitl = SitlProcess([f"udpin:127.0.0.1:{port}"], tmp_path_factory.mktemp("sitl"), speedup=SPEEDUP)
    g = Gcs(port)
    try:
        g.wait(lambda: g.last.get("HEARTBEAT"), 20, "first heartbeat")
        g.wait(lambda: g.last.get("SYS_STATUS") and g.last["SYS_STATUS"].onboard_control_sensors_health
               & M.MAV_SYS_STATUS_PREARM_CHECK, wall(30), "pre-arm checks to pass")
        yield g
    finally:
        g.conn.close()
        sitl.stop()


def test_heartbeat_identifies_an_arducopter(gcs: Gcs) -> None:
    hb = gcs.fresh("HEARTBEAT")
    assert hb.type == M.MAV_TYPE_QUADROTOR and hb.autopilot == M.MAV_AUTOPILOT_ARDUPILOTMEGA
    assert hb.base_mode & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED and hb.get_srcSystem() == 1
    assert gcs.conn.mavlink20()


def test_parameters_list_read_set(gcs: Gcs) -> None:
    gcs.params.clear()
    gcs.conn.mav.param_request_list_send(1, 1)
    first = gcs.wait(lambda: next(iter(gcs.params.values()), None), 10, "first PARAM_VALUE")
    count = gcs.last["PARAM_VALUE"].param_count
    assert first is not None and count > 20
    gcs.wait(lambda: len(gcs.params) == count, 20, f"all {count} parameters")
    gcs.conn.mav.param_request_read_send(1, 1, b"GUID_TIMEOUT", -1)
    gcs.wait(lambda: gcs.last["PARAM_VALUE"].param_id == "GUID_TIMEOUT", 5, "GUID_TIMEOUT by name")
    assert gcs.last["PARAM_VALUE"].param_value == pytest.approx(3.0)
    idx = gcs.params["WPNAV_SPEED"][1]
    gcs.conn.mav.param_request_read_send(1, 1, b"", idx)
    gcs.wait(lambda: gcs.last["PARAM_VALUE"].param_index == idx, 5, "WPNAV_SPEED by index")
    gcs.conn.param_set_send("WPNAV_SPEED", 600.0)
    gcs.wait(lambda: gcs.params["WPNAV_SPEED"][0] == 600.0, 5, "WPNAV_SPEED = 600")
    gcs.texts.clear()
    gcs.conn.param_set_send("WPNAV_SPEED", 99999.0)
    gcs.wait(lambda: any("out of range" in t for t in gcs.texts), 5, "range rejection text")
    gcs.conn.param_fetch_one("WPNAV_SPEED")
    gcs.wait(lambda: gcs.last["PARAM_VALUE"].param_id == "WPNAV_SPEED", 5, "WPNAV_SPEED")
    assert gcs.params["WPNAV_SPEED"][0] == 600.0


def test_mode_changes_and_refused_arm(gcs: Gcs) -> None:
    for mode in (ALT_HOLD, LOITER, STABILIZE, LAND):
        assert gcs.set_mode(mode) == M.MAV_RESULT_ACCEPTED
        gcs.wait(lambda mode=mode: gcs.mode() == mode, 5, f"mode {mode}")
    gcs.conn.mav.set_mode_send(1, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, GUIDED)  # the SET_MODE message
    gcs.wait(lambda: gcs.mode() == GUIDED, 5, "GUIDED by SET_MODE")
    assert gcs.set_mode(77) == M.MAV_RESULT_DENIED
    assert gcs.set_mode(LAND) == M.MAV_RESULT_ACCEPTED
    gcs.texts.clear()
    assert gcs.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_DENIED
    gcs.wait(lambda: any("not armable" in t for t in gcs.texts), 5, "the arming refusal's reason")
    assert not gcs.armed()
    assert gcs.command(31000) == M.MAV_RESULT_UNSUPPORTED


def _go(gcs: Gcs, frame: int, x: float, y: float, z: float, expect: tuple[float, float, float]) -> None:
    gcs.local_target(frame, IGNORE_VEL_ACC_YAW, x, y, z)
    gcs.at(expect, 0.8, 30)


def test_guided_flight_in_every_frame(gcs: Gcs) -> None:
    assert gcs.set_mode(GUIDED) == M.MAV_RESULT_ACCEPTED
    assert gcs.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_ACCEPTED
    assert gcs.armed()
    assert gcs.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 10) == M.MAV_RESULT_ACCEPTED
    gcs.wait(lambda: gcs.fresh("GLOBAL_POSITION_INT").relative_alt > 9500, wall(20), "take-off to 10 m")
    gcs.wait(lambda: gcs.fresh("EXTENDED_SYS_STATE").landed_state == M.MAV_LANDED_STATE_IN_AIR, wall(10),
             "in air")
    home = gcs.msg("HOME_POSITION")
    # local frames
    _go(gcs, M.MAV_FRAME_LOCAL_NED, 10, 0, -10, (10 + home.x, 0 + home.y, -10 + home.z))
    tgt = gcs.fresh("POSITION_TARGET_LOCAL_NED")
    assert (tgt.x, tgt.y) == pytest.approx((10, 0), abs=0.01)
    n, e, d = gcs.ned()
    _go(gcs, M.MAV_FRAME_LOCAL_OFFSET_NED, 0, 8, 0, (n, e + 8, d))
    yaw = gcs.fresh("ATTITUDE").yaw
    n, e, d = gcs.ned()
    _go(gcs, M.MAV_FRAME_BODY_OFFSET_NED, 6, 0, 0, (n + 6 * math.cos(yaw), e + 6 * math.sin(yaw), d))
    yaw = gcs.fresh("ATTITUDE").yaw
    n, e, d = gcs.ned()
    _go(gcs, M.MAV_FRAME_BODY_NED, 0, -5, -2, (n + 5 * math.sin(yaw), e - 5 * math.cos(yaw), d - 2))
    # global frames: 20 m north of home, 15 m above it; then 12 m above it (AMSL)
    lat = home.latitude + int(20 / 111_320 * 1e7)
    gcs.conn.mav.set_position_target_global_int_send(0, 1, 1, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                                                     IGNORE_VEL_ACC_YAW, lat, home.longitude, 15,
                                                     0, 0, 0, 0, 0, 0, 0, 0)
    gcs.wait(lambda: abs(gcs.fresh("GLOBAL_POSITION_INT").lat - lat) < 50
             and abs(gcs.last["GLOBAL_POSITION_INT"].relative_alt - 15000) < 700, wall(30), "global relative")
    gcs.conn.mav.set_position_target_global_int_send(0, 1, 1, M.MAV_FRAME_GLOBAL_INT, IGNORE_VEL_ACC_YAW,
                                                     lat, home.longitude, home.altitude / 1000 + 12,
                                                     0, 0, 0, 0, 0, 0, 0, 0)
    gcs.wait(lambda: abs(gcs.fresh("GLOBAL_POSITION_INT").relative_alt - 12000) < 700, wall(20),
             "global AMSL")


def _speed(gcs: Gcs) -> tuple[float, float]:
    m = gcs.fresh("LOCAL_POSITION_NED")
    return m.vx, m.vy


def test_guided_velocity_and_the_timeout(gcs: Gcs) -> None:
    guid_timeout = 3.0
    # a velocity target, refreshed, in the local frame
    end = time.monotonic() + wall(6)
    while time.monotonic() < end:
        gcs.local_target(M.MAV_FRAME_LOCAL_NED, IGNORE_POS_ACC_YAW, vx=2.0)
        gcs.pump()
        vx, vy = _speed(gcs)
        if abs(vx - 2.0) < 0.2 and abs(vy) < 0.3:
            break
    else:
        raise AssertionError("velocity target not reached")
    # ... in the body frame: body +y is east of the heading
    yaw = gcs.fresh("ATTITUDE").yaw
    expect = (-2.0 * math.sin(yaw), 2.0 * math.cos(yaw))
    end = time.monotonic() + wall(8)
    while time.monotonic() < end:
        gcs.local_target(M.MAV_FRAME_BODY_NED, IGNORE_POS_ACC_YAW, vy=2.0)
        vx, vy = _speed(gcs)
        if math.dist((vx, vy), expect) < 0.3:
            break
    else:
        raise AssertionError("body-frame velocity target not reached")
    # stop refreshing: it keeps going until GUID_TIMEOUT, then stops and holds (judged on positions,
    # the estimated velocity is GPS-noisy)
    track: list[tuple[float, float, float]] = []
    end = time.monotonic() + wall(guid_timeout + 8)
    while time.monotonic() < end:
        m = gcs.fresh("LOCAL_POSITION_NED")
        track.append((m.time_boot_ms / 1000.0, m.x, m.y))
        if track[-1][0] - track[0][0] > guid_timeout + 7:
            break
    t0 = track[0][0]

    def moved(a: float, b: float) -> float:
        pts = [p for p in track if a <= p[0] - t0 <= b]
        return math.dist(pts[0][1:], pts[-1][1:])

    assert moved(0.0, 0.8 * guid_timeout) > 0.7 * 2.0 * 0.8 * guid_timeout, "stopped before GUID_TIMEOUT"
    assert moved(guid_timeout + 4, guid_timeout + 7) < 1.0, "still moving after GUID_TIMEOUT"


def test_land_then_arm_and_disarm_on_the_ground(gcs: Gcs) -> None:
    assert gcs.command(M.MAV_CMD_NAV_LAND) == M.MAV_RESULT_ACCEPTED
    gcs.wait(lambda: gcs.mode() == LAND, 5, "LAND mode")
    gcs.wait(lambda: gcs.fresh("EXTENDED_SYS_STATE").landed_state == M.MAV_LANDED_STATE_ON_GROUND,
             wall(60), "touchdown")
    gcs.wait(lambda: not gcs.armed(), wall(5), "disarm after landing")
    assert gcs.set_mode(GUIDED) == M.MAV_RESULT_ACCEPTED
    assert gcs.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_ACCEPTED
    assert gcs.armed()
    assert gcs.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 0) == M.MAV_RESULT_ACCEPTED
    assert not gcs.armed()


def test_parameters_persist_across_restart(tmp_path: Path) -> None:
    port = free_port()
    for attempt in range(2):
        sitl = SitlProcess([f"udpin:127.0.0.1:{port}"], tmp_path, speedup=SPEEDUP)
        g = Gcs(port)
        try:
            g.wait(lambda g=g: g.last.get("HEARTBEAT"), 20, "heartbeat")
            if attempt == 0:
                g.conn.param_set_send("RTL_ALT", 2500)
                g.wait(lambda g=g: g.params.get("RTL_ALT", (0,))[0] == 2500, 5, "RTL_ALT set")
            else:
                g.conn.param_fetch_one("RTL_ALT")
                g.wait(lambda g=g: "RTL_ALT" in g.params, 5, "RTL_ALT read")
                assert g.params["RTL_ALT"][0] == 2500
        finally:
            g.conn.close()
            sitl.stop()
