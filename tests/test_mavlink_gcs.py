"""pymavlink as a ground station against the model over loopback UDP (lockstep, 10x).

One SITL process for the module; the tests run in file order and each leaves the vehicle in a known
state (on the ground, disarmed) or says what it expects. Deadlines are wall time derived from the
simulated durations; nothing sleeps and hopes.
"""

from __future__ import annotations

import math
import socket
import time
from pathlib import Path

import pytest

from harness.model import SitlProcess
from harness.observer import ALT_HOLD, GUIDED, LAND, LOITER, STABILIZE, Gcs, M
from harness.timing import SPEEDUP, wall
from taskflight_common.ports import free_ports

pytestmark = pytest.mark.integration

IGNORE_VEL_ACC_YAW = 0b110111111000
IGNORE_POS_ACC_YAW = 0b110111000111
IGNORE_ACC_YAW = 0b110111000000


GCS_WAIT_PREARM = True  # the gcs fixture: the tests start from a vehicle ready to arm


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
    assert gcs.set_mode(77) == M.MAV_RESULT_FAILED  # as ArduCopter
    assert gcs.set_mode(LAND) == M.MAV_RESULT_ACCEPTED
    gcs.texts.clear()
    assert gcs.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_FAILED
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
    _go(gcs, M.MAV_FRAME_LOCAL_NED, 10, 0, -10, (10, 0, -10))  # from the EKF origin (see below)
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


def _set_interval(gcs: Gcs, msg_id: int, hz: float) -> None:
    """SET_MESSAGE_INTERVAL on our link (0 Hz: back to the default rate)."""
    interval_us = 1e6 / hz if hz > 0 else 0
    assert gcs.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, interval_us) == M.MAV_RESULT_ACCEPTED


def test_guided_posvel_stream_then_timeout_brakes_and_holds(gcs: Gcs) -> None:
    """A companion streams position + velocity targets at 20 Hz (simulated), moving north at 3 m/s, then
    stops sending. ArduCopter (``ModeGuided::posvelaccel_control_run``): the position target is advanced
    with the velocity feed-forward between updates (``AC_PosControl::input_pos_vel_accel_NE_cm`` moves it
    in place), so the vehicle keeps going smoothly; after GUID_TIMEOUT the velocity and acceleration are
    zeroed and it brakes and holds, a braking distance beyond last target + v * GUID_TIMEOUT. It never
    flies back to the last position sent, and does not oscillate."""
    guid_timeout, speed, accel = 3.0, 3.0, 1.5
    # ArduCopter's braking (shape_vel_accel: jerk 5 m/s^3, acceleration 2.5 m/s^2, then the sqrt
    # controller's linear tail) from 3 m/s: about 3 m and 3 s
    braking_m, braking_s = 3.5, 4.0
    _set_interval(gcs, M.MAVLINK_MSG_ID_LOCAL_POSITION_NED, 50.0)  # simulated time at 20 ms resolution
    try:
        gcs.fresh("LOCAL_POSITION_NED")
        n0, e0, d0 = gcs.ned()
        t0 = gcs.last["LOCAL_POSITION_NED"].time_boot_ms / 1000.0
        t_acc = speed / accel

        def ref(t: float) -> tuple[float, float]:  # north position and speed of the companion's reference
            if t < t_acc:
                return n0 + 0.5 * accel * t * t, accel * t
            return n0 + 0.5 * accel * t_acc * t_acc + speed * (t - t_acc), speed

        t_stream = t_acc + 3.0
        track: list[tuple[float, float, float, float]] = []  # (sim t, n, e, d)
        last_sent = (n0, 0.0, t0)
        next_send = t0
        end = time.monotonic() + wall(t_stream + guid_timeout + 12)
        streaming = True
        while time.monotonic() < end:
            gcs.pump()
            m = gcs.last["LOCAL_POSITION_NED"]
            t = m.time_boot_ms / 1000.0
            if not track or t > track[-1][0]:
                track.append((t, m.x, m.y, m.z))
            if streaming and t >= next_send:
                n, vn = ref(min(t - t0, t_stream))
                gcs.local_target(M.MAV_FRAME_LOCAL_NED, IGNORE_ACC_YAW, n, e0, d0, vn, 0.0, 0.0)
                last_sent = (n, vn, t)
                next_send = max(next_send + 0.05, t)
                streaming = t - t0 < t_stream
            if t - last_sent[2] > guid_timeout + 8.0:
                break
            time.sleep(0.001)
        else:
            raise AssertionError("track not recorded in time")
        gcs.fresh("LOCAL_POSITION_NED")
        echo = gcs.fresh("POSITION_TARGET_LOCAL_NED")
    finally:
        _set_interval(gcs, M.MAVLINK_MSG_ID_LOCAL_POSITION_NED, 0)
    n_last, v_last, t_last = last_sent
    assert v_last == speed
    # the estimate carries GPS noise (a few decimetres): judge 0.5 s averages
    half = 0.25
    avg = [tuple(sum(q[k] for q in w) / len(w) for k in range(4))
           for w in ([q for q in track if abs(q[0] - p[0]) <= half] for p in track)
           if w[0][0] >= track[0][0] + half - 0.03 and w[-1][0] <= track[-1][0] - half + 0.03]

    # streaming: a smooth 3 m/s during the cruise (least-squares line through the last 2 s)
    cruise = [p for p in avg if t_last - 2.0 <= p[0] <= t_last]
    tm = sum(p[0] for p in cruise) / len(cruise)
    nm = sum(p[1] for p in cruise) / len(cruise)
    slope = (sum((p[0] - tm) * (p[1] - nm) for p in cruise) / sum((p[0] - tm) ** 2 for p in cruise))
    resid = math.sqrt(sum((p[1] - nm - slope * (p[0] - tm)) ** 2 for p in cruise) / len(cruise))
    assert slope == pytest.approx(speed, abs=0.4) and resid < 0.3, f"not a smooth 3 m/s: {slope}, {resid}"
    # after the last target: on at v until GUID_TIMEOUT, then a stop within the braking distance
    after = [p for p in avg if p[0] >= t_last]
    t_stop = t_last + guid_timeout + braking_s  # braked by then
    t_peak, peak = max(((p[0], p[1]) for p in after if p[0] <= t_stop), key=lambda q: q[1])
    ahead = n_last + v_last * guid_timeout
    assert ahead - 1.0 < peak < ahead + braking_m, (peak, ahead)
    back = peak - min(p[1] for p in after if p[0] >= t_peak)
    assert back < 0.8, f"flew back {back:.2f} m towards the last position sent"
    held = [p for p in after if p[0] >= t_stop]
    assert len(held) > 50
    assert max(p[1] for p in held) - min(p[1] for p in held) < 0.8, "still moving (oscillating)"
    assert all(abs(p[2] - e0) < 1.0 and abs(p[3] - d0) < 1.0 for p in after), "left the line"
    # the echo is the target held: no feed-forward left
    assert echo.type_mask & 0b111 == 0 and (echo.vx, echo.vy, echo.vz) == (0.0, 0.0, 0.0)


def test_local_ned_is_relative_to_the_origin_not_home(gcs: Gcs) -> None:
    """ArduCopter (``handle_message_set_position_target_local_ned``): MAV_FRAME_LOCAL_NED x, y, z are
    metres from the EKF origin; moving home (MAV_CMD_DO_SET_HOME) changes nothing."""
    home = gcs.fresh("HOME_POSITION")

    def set_home(lat_e7: int, lon_e7: int, alt_m: float) -> None:
        gcs.acks.clear()
        gcs.conn.mav.command_int_send(1, 1, M.MAV_FRAME_GLOBAL, M.MAV_CMD_DO_SET_HOME, 0, 0, 0, 0, 0, 0,
                                      lat_e7, lon_e7, alt_m)
        ack = gcs.wait(lambda: next((a for a in gcs.acks if a.command == M.MAV_CMD_DO_SET_HOME), None), 10,
                       "DO_SET_HOME ack")
        assert ack.result == M.MAV_RESULT_ACCEPTED

    # 30 m north of where it was, 7 m higher
    set_home(home.latitude + int(30 / 111_320 * 1e7), home.longitude, home.altitude / 1000 + 7.0)
    try:
        # HOME_POSITION carries the new home in lat/lon/alt only (x, y, z stay 0, as ArduCopter sends them)
        new_alt = home.altitude + 7000
        gcs.wait(lambda: abs(gcs.fresh("HOME_POSITION").altitude - new_alt) <= 1, 10, "new home")
        moved = gcs.last["HOME_POSITION"]
        assert (moved.x, moved.y, moved.z) == (0.0, 0.0, 0.0)
        assert moved.latitude == home.latitude + int(30 / 111_320 * 1e7)
        _go(gcs, M.MAV_FRAME_LOCAL_NED, 5, -5, -12, (5, -5, -12))
        tgt = gcs.fresh("POSITION_TARGET_LOCAL_NED")
        assert (tgt.x, tgt.y, tgt.z) == pytest.approx((5, -5, -12), abs=0.01)
        n, e, d = gcs.ned()
        assert (n, e, d) == pytest.approx((5, -5, -12), abs=0.8)
        # the offset frames stay relative to the vehicle
        _go(gcs, M.MAV_FRAME_LOCAL_OFFSET_NED, 0, 0, 2, (n, e, d + 2))
    finally:
        set_home(home.latitude, home.longitude, home.altitude / 1000)


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
    port = free_ports(1, socket.SOCK_DGRAM)[0]
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
