"""One ground-station scenario, run against any autopilot, recording what a ground station observes.

The same pymavlink scenario is flown against the bundled model and against ArduPilot's
own copter SITL (:mod:`autopilot_support`), and :func:`observe` returns what a ground station sees:
ACK results, the mode and landed-state sequences, HOME_POSITION, parameter names and values, the
GUID_TIMEOUT stop, the mission protocol's answers. ``tests/test_differential.py`` compares them;
``docs/conformance.md`` tabulates the results. No tests here.
"""

from __future__ import annotations

import math
from typing import Any

from harness.autopilot import Autopilot
from harness.observer import GUIDED, LAND, VEL_ONLY, M
from harness.timing import wait_for

#: Parameters a ground station or the companion uses, by their current ArduCopter names.
PARAMS = ("GUID_TIMEOUT", "FS_GCS_ENABLE", "FS_GCS_TIMEOUT", "MAV_SYSID", "MAV_GCS_SYSID", "DISARM_DELAY",
          "WPNAV_SPEED", "WPNAV_SPEED_UP", "LAND_SPEED", "RTL_ALT", "FENCE_ENABLE", "ANGLE_MAX",
          "ATC_RAT_RLL_P", "PSC_VELXY_P", "PSC_VELXY_FLTE", "PSC_VELXY_FLTD", "PILOT_TKOFF_ALT")
#: Their former names: current ArduCopter answers neither.
OLD_PARAMS = ("SYSID_THISMAV", "SYSID_MYGCS")


def _read_param(ap: Autopilot, name: str) -> float | None:
    g = ap.gcs
    g.conn.mav.param_request_read_send(1, 1, name.encode(), -1)
    try:
        g.wait(lambda: name in g.params, ap.gcs.wall(2), f"PARAM_VALUE {name}")
    except AssertionError:
        return None
    return float(g.params[name][0])


def observe(ap: Autopilot) -> dict[str, Any]:
    """Run the scenario on ``ap`` (on the ground, just started) and return the observations."""
    g = ap.gcs
    obs: dict[str, Any] = {}
    hb = g.last["HEARTBEAT"]
    obs["heartbeat"] = (hb.type, hb.autopilot)
    obs["initial_mode"] = hb.custom_mode
    g.conn.mav.command_long_send(1, 1, M.MAV_CMD_SET_MESSAGE_INTERVAL, 0, M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE,
                                 100_000, 0, 0, 0, 0, 0)
    wait_for(lambda: g.last.get("LOCAL_POSITION_NED") is not None, g.wall(60), "LOCAL_POSITION_NED")
    lpn = g.last["LOCAL_POSITION_NED"]
    obs["local_position_at_start"] = (lpn.x, lpn.y, lpn.z)
    obs["takeoff_disarmed"] = g.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 5)
    obs["unknown_mode"] = g.set_mode(99)
    obs["unknown_command"] = g.command(31999)
    obs["set_guided"] = g.set_mode(GUIDED)
    g.last.pop("HOME_POSITION", None)
    obs["request_home"] = g.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_HOME_POSITION)
    home = g.msg("HOME_POSITION", g.wall(5))
    obs["home_xyz"] = (home.x, home.y, home.z)
    obs["home_q_nan"] = all(math.isnan(q) for q in home.q)
    obs["params"] = {n: _read_param(ap, n) for n in PARAMS + OLD_PARAMS}

    # arm (retried while the pre-arm checks still fail), take off, a second take-off at once
    results: list[int] = []
    wait_for(lambda: results.append(g.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1)) or results[-1] == 0,
             g.wall(60), "arming")
    obs["arm"] = results[-1]
    states: list[int] = []

    def record_state() -> None:
        m = g.last.get("EXTENDED_SYS_STATE")
        if m is not None and (not states or states[-1] != m.landed_state):
            states.append(m.landed_state)

    record_state()
    obs["takeoff"] = g.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 5)
    obs["takeoff_again_on_the_ground"] = g.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 5)
    g.wait(lambda: (record_state(), (m := g.last.get("LOCAL_POSITION_NED")) is not None and m.z < -4.7)[1],
           g.wall(30), "5 m up")
    obs["disarm_in_the_air"] = g.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 0)

    # GUID_TIMEOUT: 2 m/s north for 2 s of autopilot time, then silence
    t = g.last["LOCAL_POSITION_NED"].time_boot_ms
    t_end = t + 2000
    while t < t_end:
        g.local_target(M.MAV_FRAME_LOCAL_NED, VEL_ONLY, vx=2.0)
        wait_for(lambda t=t: (record_state(), g.last["LOCAL_POSITION_NED"].time_boot_ms > t)[1], g.wall(1),
                 "the next position")
        t = g.last["LOCAL_POSITION_NED"].time_boot_ms
    last = g.last["LOCAL_POSITION_NED"]
    track: list[tuple[int, float, float]] = []

    def stopped() -> bool:
        record_state()
        m = g.last["LOCAL_POSITION_NED"]
        track.append((m.time_boot_ms, m.x, m.vx))
        return m.time_boot_ms > last.time_boot_ms + 1000 and abs(m.vx) < 0.1

    g.wait(stopped, g.wall(20), "stopped after GUID_TIMEOUT")
    slow = next(t for t, _, vx in track if t > last.time_boot_ms and vx < 1.0)
    obs["guid_timeout_slowed_s"] = (slow - last.time_boot_ms) / 1000.0
    obs["guid_timeout_travel_m"] = track[-1][1] - last.x

    obs["land"] = g.set_mode(LAND)
    g.wait(lambda: (record_state(), not g.last["HEARTBEAT"].base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)[1],
           g.wall(60), "landed and disarmed")
    g.wait(lambda: (record_state(), states[-1] == M.MAV_LANDED_STATE_ON_GROUND)[1], g.wall(5), "ON_GROUND")
    obs["landed_states"] = states
    obs["modes"] = list(g.modes_seen)

    # mission protocol: upload home + take-off + waypoint, then download the count
    g.conn.mav.mission_count_send(1, 1, 3, 0)
    kinds = ("MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK")
    req = g.next_mission(kinds)
    obs["mission_request_type"] = req.get_type()
    items = ((M.MAV_CMD_NAV_WAYPOINT, 0.0), (M.MAV_CMD_NAV_TAKEOFF, 10.0), (M.MAV_CMD_NAV_WAYPOINT, 10.0))
    lat, lon = int(home.latitude), int(home.longitude)
    seqs: list[int] = []
    while req.get_type() != "MISSION_ACK" and len(seqs) < 10:
        seqs.append(req.seq)
        cmd, alt = items[req.seq]
        g.conn.mav.mission_item_int_send(1, 1, req.seq, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, cmd, 0, 1,
                                         0, 0, 0, 0, lat + 100 * req.seq, lon, alt, 0)
        req = g.next_mission(kinds)
    obs["mission_requested_seqs"] = seqs
    obs["mission_ack"] = req.type
    g.conn.mav.mission_request_list_send(1, 1, 0)
    obs["mission_count"] = g.next_mission(("MISSION_COUNT",)).count
    g.conn.mav.mission_ack_send(1, 1, M.MAV_MISSION_ACCEPTED, 0)
    return obs
