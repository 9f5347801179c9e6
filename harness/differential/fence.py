"""One ground station's fence-and-status scenario, run against any autopilot.

:func:`observe_fence` drives the autopilot with pymavlink, as QGroundControl or MAVProxy would, and returns
what the ground station sees: the ACK results, the STATUSTEXTs of the refusals, FENCE_STATUS fields, the
mode sequence after a breach, which status messages arrive and how often, AUTOPILOT_VERSION against the
parameter names, the parameters QGroundControl reads, SETUP_SIGNING's effect.
``tests/test_differential_fence.py`` holds it against ArduCopter's answers; ``docs/conformance.md``
tabulates both. No tests here.
"""

from __future__ import annotations

import math
import os
import time
from collections import Counter
from typing import Any

from harness.autopilot import Autopilot
from harness.observer import GUIDED, POS_ONLY, M

#: What QGroundControl's ArduCopter plugin reads on connecting (setup pages: airframe, radio, flight modes,
#: sensors, power, safety) besides the parameters the companion uses.
QGC_PARAMS = (
    "FRAME_CLASS", "FRAME_TYPE", "FLTMODE1", "FLTMODE2", "FLTMODE3", "FLTMODE4", "FLTMODE5", "FLTMODE6",
    "FLTMODE_CH", "SIMPLE", "SUPER_SIMPLE", "RCMAP_ROLL", "RCMAP_PITCH", "RCMAP_THROTTLE", "RCMAP_YAW",
    "RC1_MIN", "RC1_MAX", "RC1_TRIM", "RC1_REVERSED", "RC8_MIN", "RC8_MAX", "RC8_TRIM", "RC8_REVERSED",
    "COMPASS_DEV_ID", "COMPASS_DEV_ID2", "COMPASS_DEV_ID3", "COMPASS_USE", "COMPASS_OFS_X", "COMPASS_OFS_Y",
    "COMPASS_OFS_Z", "INS_ACCOFFS_X", "INS_ACCOFFS_Y", "INS_ACCOFFS_Z", "AHRS_ORIENTATION", "COMPASS_ORIENT",
    "BATT_MONITOR", "BATT_CAPACITY", "BATT_LOW_VOLT", "BATT_CRT_VOLT", "BATT_LOW_MAH", "BATT_CRT_MAH",
    "BATT_FS_LOW_ACT", "BATT_FS_CRT_ACT", "ARMING_CHECK", "FS_GCS_ENABLE", "FS_THR_ENABLE", "FS_THR_VALUE",
    "FS_EKF_ACTION", "FS_EKF_THRESH", "FENCE_ENABLE", "FENCE_TYPE", "FENCE_ACTION", "FENCE_ALT_MAX",
    "FENCE_ALT_MIN", "FENCE_RADIUS", "FENCE_MARGIN", "RTL_ALT", "RTL_ALT_FINAL", "RTL_LOIT_TIME",
    "LAND_SPEED", "WPNAV_SPEED", "WPNAV_SPEED_UP", "WPNAV_SPEED_DN", "WPNAV_RADIUS", "PILOT_SPEED_UP",
    "ANGLE_MAX", "MAV_SYSID", "MAV_GCS_SYSID",
)
STATUS_MESSAGES = ("FENCE_STATUS", "EKF_STATUS_REPORT", "NAV_CONTROLLER_OUTPUT", "GPS_GLOBAL_ORIGIN")
RATE_HZ = 2.0
SYSTEM_TIME_HZ = 5.0
"""SYSTEM_TIME's rate: the clock the other rates are judged by (a lost datagram loses both alike)."""


class Counting:
    """Counts every message type the ground station receives (its background thread records them)."""

    def __init__(self, g: Any) -> None:
        self.counts: Counter[str] = Counter()
        record = g._record

        def counting(m: Any) -> None:
            self.counts[m.get_type()] += 1
            record(m)

        g._record = counting


def _param(g: Any, name: str) -> float | None:
    g.params.pop(name, None)
    g.conn.mav.param_request_read_send(1, 1, name.encode(), -1)
    try:
        g.wait(lambda: name in g.params, g.wall(2), f"PARAM_VALUE {name}")
    except AssertionError:
        return None
    return float(g.params[name][0])


def _sim_ms(g: Any) -> int:
    return int(g.last["SYSTEM_TIME"].time_boot_ms)


def _counts_over(g: Any, counter: Counting, sim_s: float) -> tuple[dict[str, int], float]:
    """Messages received during ``sim_s`` seconds of the autopilot's time, and the time measured."""
    g.msg("SYSTEM_TIME")
    t0 = _sim_ms(g)
    before = dict(counter.counts)
    g.wait(lambda: _sim_ms(g) >= t0 + sim_s * 1000, g.wall(sim_s + 3), f"{sim_s} s of autopilot time")
    dt = (_sim_ms(g) - t0) / 1000.0
    return {t: counter.counts[t] - before.get(t, 0) for t in (*STATUS_MESSAGES, "SYSTEM_TIME")}, dt


def _arm_refusal(g: Any) -> tuple[int, str | None]:
    """Arm (expecting a refusal): its result and the STATUSTEXT naming the fence."""
    n = len(g.texts)
    result = g.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    if result == M.MAV_RESULT_ACCEPTED:
        g.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 0)
        return result, None
    try:
        g.wait(lambda: any("FENCE" in t or "fence" in t.lower() for t in g.texts[n:]), g.wall(2), "text")
    except AssertionError:
        return result, None
    return result, next(t for t in g.texts[n:] if "FENCE" in t or "fence" in t.lower())


def _command_int(g: Any, cmd: int, frame: int, p: tuple[float, ...], x: int, y: int, z: float) -> int:
    """COMMAND_INT (ArduCopter takes DO_REPOSITION only so); the ACK's result."""
    with g._lock:
        g.acks.clear()
    g.conn.mav.command_int_send(1, 1, frame, cmd, 0, 0, *p, x, y, z)
    ack = g.wait(lambda: next((a for a in g.acks if a.command == cmd), None), g.wall(5), f"ACK of {cmd}")
    return ack.result


def _still(g: Any, sim_s: float) -> float:
    """Horizontal distance travelled over ``sim_s`` seconds of the autopilot's time."""
    start = g.last["LOCAL_POSITION_NED"]
    g.wait(lambda: g.last["LOCAL_POSITION_NED"].time_boot_ms >= start.time_boot_ms + sim_s * 1000,
           g.wall(sim_s + 3), "time passing")
    end = g.last["LOCAL_POSITION_NED"]
    return math.hypot(end.x - start.x, end.y - start.y)


def observe_fence(ap: Autopilot) -> dict[str, Any]:
    """Run the scenario on ``ap`` (on the ground, just started) and return the observations."""
    g = ap.gcs
    counter = Counting(g)
    obs: dict[str, Any] = {}
    # only what the scenario reads (a 10 Hz firehose of every group can overflow a loaded machine's socket)
    g.conn.mav.request_data_stream_send(1, 1, M.MAV_DATA_STREAM_ALL, 0, 0)
    for msg_id, hz in ((M.MAVLINK_MSG_ID_LOCAL_POSITION_NED, 10), (M.MAVLINK_MSG_ID_SYS_STATUS, 2)):
        g.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 1e6 / hz)
    ids = [M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE, M.MAVLINK_MSG_ID_SYSTEM_TIME] + [
        getattr(M, f"MAVLINK_MSG_ID_{name}") for name in STATUS_MESSAGES]
    obs["intervals"] = [g.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, i,
                                  1e6 / (SYSTEM_TIME_HZ if i == ids[1] else RATE_HZ)) for i in ids]

    # version and parameter names
    g.last.pop("AUTOPILOT_VERSION", None)
    obs["request_version"] = g.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    v = g.msg("AUTOPILOT_VERSION", g.wall(5)).flight_sw_version
    obs["version"] = (v >> 24 & 0xFF, v >> 16 & 0xFF, v >> 8 & 0xFF, v & 0xFF)
    obs["params"] = {n: _param(g, n) for n in (*QGC_PARAMS, "SYSID_THISMAV")}

    # the EKF and its origin, before anything flies
    g.wait(lambda: (m := g.last.get("EKF_STATUS_REPORT")) is not None
           and m.flags & 0x33F == 0x33F and not m.flags & M.EKF_UNINITIALIZED, g.wall(90), "EKF ready")
    ekf = g.last["EKF_STATUS_REPORT"]
    obs["ekf"] = (ekf.flags, ekf.velocity_variance, ekf.pos_horiz_variance, ekf.pos_vert_variance)
    origin = g.msg("GPS_GLOBAL_ORIGIN", g.wall(10))
    obs["origin"] = (origin.latitude * 1e-7, origin.longitude * 1e-7, origin.altitude * 1e-3)
    obs["rates_fence_off"], obs["rates_dt"] = _counts_over(g, counter, 5.0)

    # ready to arm: arm and disarm at once (ArduCopter needs about 40 s of its time)
    results: list[int] = []
    g.wait(lambda: results.append(g.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1)) or results[-1] == 0,
           g.wall(90), "arming")
    obs["disarm_on_ground"] = g.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 0)

    # DO_FENCE_ENABLE, FENCE_STATUS, SYS_STATUS's fence bits
    obs["fence_enable_bad_action"] = g.command(M.MAV_CMD_DO_FENCE_ENABLE, 5)
    obs["fence_enable_floor_unconfigured"] = g.command(M.MAV_CMD_DO_FENCE_ENABLE, 1, 8)
    obs["fence_enable"] = g.command(M.MAV_CMD_DO_FENCE_ENABLE, 1)
    fs = g.msg("FENCE_STATUS", g.wall(3))
    obs["fence_status_enabled"] = (fs.breach_status, fs.breach_count, fs.breach_type)
    g.fresh("SYS_STATUS", g.wall(3))
    ss = g.fresh("SYS_STATUS", g.wall(3))
    bit = M.MAV_SYS_STATUS_GEOFENCE
    obs["sys_status_fence"] = tuple(bool(x & bit) for x in (ss.onboard_control_sensors_present,
                                                            ss.onboard_control_sensors_enabled,
                                                            ss.onboard_control_sensors_health))

    # pre-arm fence checks
    g.set_param("FENCE_ALT_MAX", 20)
    g.set_param("FENCE_ALT_MIN", 50)
    obs["prearm_alt_order"] = _arm_refusal(g)
    g.set_param("FENCE_ALT_MAX", 100)
    g.set_param("FENCE_ALT_MIN", 99)
    obs["prearm_margin"] = _arm_refusal(g)
    g.set_param("FENCE_ALT_MIN", -10)

    # fly, fenced: 100 m up, 300 m around home
    obs["set_guided"] = g.set_mode(GUIDED)
    obs["arm"] = g.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    obs["takeoff"] = g.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 10)
    g.wait_alt(10, 40, tol=0.6)
    n = len(g.texts)
    g.conn.mav.setup_signing_send(1, 1, list(os.urandom(32)), 0)
    g.wait(lambda: any("signing" in t for t in g.texts[n:]), g.wall(3), "the refusal to set up signing")
    obs["setup_signing_armed"] = next(t for t in g.texts[n:] if "signing" in t)
    obs["rates_flying"], _ = _counts_over(g, counter, 5.0)
    g.local_target(M.MAV_FRAME_LOCAL_NED, POS_ONLY, 400, 0, -10)  # beyond FENCE_RADIUS
    obs["target_outside_circle_moved_m"] = _still(g, 3.0)
    g.local_target(M.MAV_FRAME_LOCAL_NED, POS_ONLY, 0, 0, -120)  # above FENCE_ALT_MAX
    z0 = g.last["LOCAL_POSITION_NED"].z
    _still(g, 3.0)
    obs["target_above_ceiling_climbed_m"] = z0 - g.last["LOCAL_POSITION_NED"].z
    g.last.pop("HOME_POSITION", None)
    g.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_HOME_POSITION)
    home = g.msg("HOME_POSITION", g.wall(5))
    obs["reposition_outside"] = _command_int(g, M.MAV_CMD_DO_REPOSITION, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                                             (-1, 0, 0, math.nan),
                                             home.latitude + round(400 / 111_320 * 1e7), home.longitude, 10)
    g.local_target(M.MAV_FRAME_LOCAL_NED, POS_ONLY, 40, 0, -10)
    g.wait(lambda: 10 < g.last["LOCAL_POSITION_NED"].x < 20, g.wall(30), "on the way north")
    nco = g.fresh("NAV_CONTROLLER_OUTPUT", g.wall(3))
    obs["nav_controller_en_route"] = (nco.target_bearing, nco.wp_dist, g.last["LOCAL_POSITION_NED"].x)
    g.wait(lambda: g.last["LOCAL_POSITION_NED"].x > 38, g.wall(30), "40 m north")

    # breach: the circle pulled in to 30 m
    modes_before = len(g.modes_seen)
    g.set_param("FENCE_RADIUS", 30)
    g.wait(lambda: (m := g.last.get("FENCE_STATUS")) is not None and m.breach_status == 1, g.wall(5),
           "the breach")
    fs = g.last["FENCE_STATUS"]
    obs["fence_status_breached"] = (fs.breach_status, fs.breach_count, fs.breach_type,
                                    0 < fs.breach_time <= g.last["SYSTEM_TIME"].time_boot_ms + 1000)
    g.wait(lambda: g.last["FENCE_STATUS"].breach_status == 0, g.wall(60), "breach cleared")
    fs = g.last["FENCE_STATUS"]
    obs["fence_status_cleared"] = (fs.breach_status, fs.breach_count, fs.breach_type)
    obs["breach_texts"] = [t for t in g.texts if "ence" in t]
    g.wait(lambda: not g.last["HEARTBEAT"].base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, g.wall(120), "landed")
    obs["modes_after_breach"] = list(g.modes_seen[modes_before - 1:])
    obs["modes"] = list(g.modes_seen)
    g.set_param("FENCE_RADIUS", 300)
    obs["fence_disable"] = g.command(M.MAV_CMD_DO_FENCE_ENABLE, 0)
    obs["rates_fence_disabled"], _ = _counts_over(g, counter, 3.0)

    # SETUP_SIGNING on the ground
    key = os.urandom(32)
    # signing time: 10 us since 2015, the later of the wall clock and the vehicle's Unix time (a SITL's GPS
    # clock runs at its speed-up, and ArduPilot raises its signing time to it)
    unix_s = max(time.time(), g.fresh("SYSTEM_TIME", g.wall(3)).time_unix_usec * 1e-6) + 1.0
    now = int((unix_s - 1420070400) * 1e5)
    g.conn.mav.setup_signing_send(1, 1, list(key), now)
    try:
        obs["unsigned_after_setup"] = g.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION,
                                                timeout_s=g.wall(2))
    except AssertionError:
        obs["unsigned_after_setup"] = None
    g.conn.setup_signing(key, sign_outgoing=True, initial_timestamp=now)
    # ArduPilot starts its signing time a minute after the key's: send once a signed packet from the vehicle
    # has moved ours up to its time (a new stream more than a minute behind is refused)
    g.wait(lambda: g.conn.mav.signing.stream_timestamps, g.wall(5), "a signed packet from the vehicle")
    obs["signed"] = g.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    g.conn.mav.setup_signing_send(1, 1, [0] * 32, 0)  # all zero: signing off
    g.conn.disable_signing()
    obs["unsigned_after_off"] = g.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION,
                                          timeout_s=g.wall(3))
    return obs
