"""Modes, commands and missions, run against any autopilot, recording what a ground
station observes. No tests here: ``tests/test_differential_modes.py`` compares the observations of the
model and of ArduPilot's copter SITL; ``docs/conformance.md`` tabulates them.

:func:`observe_commands`: GUIDED take-off; CONDITION_YAW, DO_CHANGE_SPEED, DO_REPOSITION (QGroundControl's
"go to location", as COMMAND_INT), DO_PAUSE_CONTINUE, DO_SET_ROI_LOCATION, DO_SET_HOME, CIRCLE, SMART_RTL,
PREFLIGHT_REBOOT_SHUTDOWN. :func:`observe_mission`: a plan with DO_CHANGE_SPEED, CONDITION_DELAY,
CONDITION_YAW, LOITER_TIME, DO_JUMP, DO_SET_ROI_LOCATION, LOITER_TURNS and LOITER_UNLIM, edited with
MISSION_WRITE_PARTIAL_LIST, flown in AUTO; then RTL to a rally point.

Positions are local NED (LOCAL_POSITION_NED, from the EKF origin, which both autopilots put at the place
they were armed first); headings in degrees from ATTITUDE.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from harness.autopilot import Autopilot
from harness.differential.pilot import Sticks
from harness.observer import GUIDED, M
from harness.timing import wait_for
from taskflight_common.ardupilot import CopterMode
from taskflight_common.geo import ned_to_geodetic

AUTO, LOITER, RTL, CIRCLE, SMART_RTL, STABILIZE = (
    CopterMode.AUTO, CopterMode.LOITER, CopterMode.RTL, CopterMode.CIRCLE, CopterMode.SMART_RTL,
    CopterMode.STABILIZE)
ACCEPTED = M.MAV_RESULT_ACCEPTED
REL_INT = M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT


class Flight:
    """Helpers on one autopilot's ground station, with deadlines in simulated seconds."""

    def __init__(self, ap: Autopilot) -> None:
        self.ap = ap
        self.g = ap.gcs
        self.states: list[int] = []
        self.home = (0.0, 0.0, 0.0)

    def pos(self) -> tuple[float, float, float]:
        m = self.g.last["LOCAL_POSITION_NED"]
        return m.x, m.y, m.z

    def speed(self) -> float:
        m = self.g.last["LOCAL_POSITION_NED"]
        return math.hypot(m.vx, m.vy)

    def heading(self) -> float:
        return math.degrees(self.g.last["ATTITUDE"].yaw) % 360.0

    def sim_s(self) -> float:
        return self.g.last["LOCAL_POSITION_NED"].time_boot_ms / 1000.0

    def record_state(self) -> None:
        m = self.g.last.get("EXTENDED_SYS_STATE")
        if m is not None and (not self.states or self.states[-1] != m.landed_state):
            self.states.append(m.landed_state)

    def until(self, pred: Callable[[], Any], sim_s: float, what: str,
              each: Callable[[], None] | None = None) -> Any:
        def test() -> Any:
            self.record_state()
            if each is not None:
                each()
            return pred()
        return self.g.wait(test, self.g.wall(sim_s), what)

    def during(self, sim_s: float, each: Callable[[], None] | None = None) -> None:
        """Let ``sim_s`` simulated seconds pass (by the autopilot's own clock), calling ``each``."""
        t_end = self.sim_s() + sim_s
        self.until(lambda: self.sim_s() >= t_end, sim_s * 2 + 10, f"{sim_s} s to pass", each)

    def command_int(self, cmd: int, frame: int, p: tuple[float, float, float, float], lat: float,
                    lon: float, alt: float) -> int:
        g = self.g
        g.acks.clear()
        g.conn.mav.command_int_send(1, 1, frame, cmd, 0, 0, *p, round(lat * 1e7), round(lon * 1e7), alt)
        ack = g.wait(lambda: next((a for a in g.acks if a.command == cmd), None), 10, f"ACK of {cmd}")
        return ack.result

    def geo(self, n: float, e: float) -> tuple[float, float]:
        """Latitude, longitude of the local point ``n``, ``e`` (m from the EKF origin = the first home)."""
        lat, lon, _ = ned_to_geodetic(self.home, n, e, 0.0)
        return lat, lon

    def start(self) -> None:
        """Stream requests, wait for a position and home."""
        g = self.g
        for msg_id in (M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE, M.MAVLINK_MSG_ID_HOME_POSITION,
                       M.MAVLINK_MSG_ID_MISSION_CURRENT):
            g.conn.mav.command_long_send(1, 1, M.MAV_CMD_SET_MESSAGE_INTERVAL, 0, msg_id, 200_000,
                                         0, 0, 0, 0, 0)
        wait_for(lambda: g.last.get("LOCAL_POSITION_NED") is not None and g.last.get("ATTITUDE") is not None,
                 g.wall(60), "LOCAL_POSITION_NED and ATTITUDE")
        self.home = g.home()

    def arm(self) -> int:
        results: list[int] = []
        arm = M.MAV_CMD_COMPONENT_ARM_DISARM
        wait_for(lambda: results.append(self.g.command(arm, 1)) or results[-1] == 0, self.g.wall(60),
                 "arming")
        return results[-1]

    def takeoff(self, alt: float) -> int:
        result = self.g.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, alt)
        self.until(lambda: -self.pos()[2] > alt - 0.5, 40, f"{alt} m up")
        return result

    def landed_and_disarmed(self, sim_s: float, each: Callable[[], None] | None = None) -> None:
        self.until(lambda: not self.g.last["HEARTBEAT"].base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, sim_s,
                   "landed and disarmed", each)
        self.until(lambda: self.states[-1:] == [M.MAV_LANDED_STATE_ON_GROUND], 5, "ON_GROUND")


def _angle_diff(a: float, b: float) -> float:
    return abs((a - b + 180.0) % 360.0 - 180.0)


def observe_commands(ap: Autopilot) -> dict[str, Any]:
    """The command scenario (see the module docstring); returns the observations."""
    f = Flight(ap)
    g = f.g
    obs: dict[str, Any] = {}
    f.start()
    g.wait_prearm(g.wall(60))  # a good position: SmartRTL's path has started
    obs["smart_rtl_disarmed"] = g.set_mode(SMART_RTL)
    obs["reboot_bad_param"] = g.command(M.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 0)
    # DO_SET_HOME to a location (20 m east) on the ground: HOME_POSITION moves, locked: arming keeps it
    lat, lon = f.geo(0.0, 20.0)
    obs["set_home_location"] = g.command(M.MAV_CMD_DO_SET_HOME, 0, 0, 0, 0, lat, lon, f.home[2])
    h = g.home()
    obs["home_moved_east_m"] = (h[1] - f.home[1]) * 111_195.0 * math.cos(math.radians(h[0]))
    obs["set_guided"] = g.set_mode(GUIDED)
    obs["arm"] = f.arm()
    obs["takeoff"] = f.takeoff(10.0)  # at once: DISARM_DELAY
    obs["home_after_arming_east_m"] = (g.home()[1] - f.home[1]) * 111_195.0 * math.cos(math.radians(h[0]))
    obs["reboot_armed"] = g.command(M.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 1)

    # CONDITION_YAW: 90 deg absolute, then a bad angle
    obs["condition_yaw"] = g.command(M.MAV_CMD_CONDITION_YAW, 90, 0, 1, 0)
    t0 = f.sim_s()
    f.until(lambda: _angle_diff(f.heading(), 90.0) < 3.0, 30, "heading 90")
    obs["condition_yaw_s"] = f.sim_s() - t0
    obs["condition_yaw_bad"] = g.command(M.MAV_CMD_CONDITION_YAW, 400, 0, 1, 0)
    obs["condition_yaw_relative"] = g.command(M.MAV_CMD_CONDITION_YAW, 45, 0, -1, 1)
    f.until(lambda: _angle_diff(f.heading(), 45.0) < 3.0, 30, "heading 45 (90 - 45)")

    # DO_REPOSITION 60 m north at 15 m (after a DO_CHANGE_SPEED, which the new destination drops:
    # WPNAV_SPEED); DO_CHANGE_SPEED 3 m/s on the way; paused, continued
    obs["change_speed_zero"] = g.command(M.MAV_CMD_DO_CHANGE_SPEED, 1, 0, -1)
    obs["change_speed_before"] = g.command(M.MAV_CMD_DO_CHANGE_SPEED, 1, 2, -1)
    lat, lon = f.geo(60.0, 0.0)
    obs["reposition"] = f.command_int(M.MAV_CMD_DO_REPOSITION, REL_INT, (-1, 0, 0, math.nan), lat, lon, 15.0)
    speeds: list[float] = []
    f.until(lambda: f.pos()[0] > 12.0, 40, "12 m north", lambda: speeds.append(f.speed()))
    obs["reposition_speed"] = max(speeds)
    obs["change_speed"] = g.command(M.MAV_CMD_DO_CHANGE_SPEED, 1, 3, -1)
    f.during(5.0)
    obs["changed_speed"] = f.speed()
    obs["pause"] = g.command(M.MAV_CMD_DO_PAUSE_CONTINUE, 0)
    t0 = f.sim_s()
    f.until(lambda: f.speed() < 0.2, 20, "stopped by the pause")
    obs["pause_stop_s"] = f.sim_s() - t0
    f.during(2.0)
    obs["pause_held_north"] = f.pos()[0]
    obs["continue"] = g.command(M.MAV_CMD_DO_PAUSE_CONTINUE, 1)
    f.until(lambda: math.dist(f.pos(), (60.0, 0.0, -15.0)) < 1.5, 90, "at the reposition target")
    obs["reposition_reached"] = True

    # DO_SET_ROI_LOCATION 40 m east of the origin: the nose turns to it
    lat, lon = f.geo(0.0, 40.0)
    obs["roi"] = f.command_int(M.MAV_CMD_DO_SET_ROI_LOCATION, REL_INT, (0, 0, 0, 0), lat, lon, 0.0)
    bearing = math.degrees(math.atan2(40.0 - f.pos()[1], 0.0 - f.pos()[0])) % 360.0
    f.until(lambda: _angle_diff(f.heading(), bearing) < 5.0, 30, "nose to the ROI")
    obs["roi_heading_error"] = _angle_diff(f.heading(), bearing)

    # DO_SET_HOME here (param1 1): HOME_POSITION moves 60 m north (and SmartRTL's path restarts here)
    obs["set_home_here"] = g.command(M.MAV_CMD_DO_SET_HOME, 1)
    h = g.home()
    obs["home_moved_north_m"] = (h[0] - f.home[0]) * 111_195.0

    # CIRCLE: the centre 10 m ahead (CIRCLE_RADIUS 1000), 20 deg/s. The sticks are centred by RC override
    # (ArduCopter's SITL receiver holds the throttle low: CIRCLE would descend)
    sticks = Sticks(ap)
    sticks.set(1500, 1500, 1500, 1500)
    yaw = math.radians(f.heading())
    p0 = f.pos()
    centre = (p0[0] + 10.0 * math.cos(yaw), p0[1] + 10.0 * math.sin(yaw))
    obs["circle"] = g.set_mode(CIRCLE)
    radii: list[float] = []
    circle_speeds: list[float] = []

    def on_circle() -> None:
        p = f.pos()
        radii.append(math.hypot(p[0] - centre[0], p[1] - centre[1]))
        circle_speeds.append(f.speed())

    f.during(20.0, on_circle)
    obs["circle_radius"] = (min(radii[len(radii) // 2:]), max(radii[len(radii) // 2:]))
    obs["circle_speed"] = f.speed()
    obs["circle_alt"] = -f.pos()[2]
    obs["circle_pause"] = g.command(M.MAV_CMD_DO_PAUSE_CONTINUE, 0)
    obs["circle_change_speed"] = g.command(M.MAV_CMD_DO_CHANGE_SPEED, 1, 3, -1)

    # SMART_RTL: back along the circle to where home was set, lands there
    obs["smart_rtl"] = g.set_mode(SMART_RTL)
    try:
        f.landed_and_disarmed(240)
    finally:
        sticks.close()
    obs["smart_rtl_land_m"] = math.dist(f.pos()[:2], (60.0, 0.0))
    obs["modes"] = list(g.modes_seen)
    obs["landed_states"] = list(f.states)

    # PREFLIGHT_REBOOT_SHUTDOWN on the ground: ACCEPTED, then heartbeats again
    obs["reboot"] = g.command(M.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 1)
    g.last.pop("HEARTBEAT", None)
    try:
        g.wait(lambda: g.last.get("HEARTBEAT") is not None, 60, "a heartbeat after the reboot")
        obs["heartbeat_after_reboot"] = g.last["HEARTBEAT"].custom_mode
    except AssertionError:
        obs["heartbeat_after_reboot"] = None
    return obs


def _item(f: Flight, seq: int, cmd: int, n: float | None = None, e: float = 0.0, z: float = 0.0,
          p: tuple[float, float, float, float] = (0, 0, 0, 0), mission_type: int = 0) -> tuple[Any, ...]:
    """MISSION_ITEM_INT fields (after target system and component) for one item; ``n`` None: no position."""
    if n is None:
        lat = lon = 0
        frame = M.MAV_FRAME_MISSION
    else:
        la, lo = f.geo(n, e)
        lat, lon = round(la * 1e7), round(lo * 1e7)
        frame = REL_INT
    return (seq, frame, cmd, 0, 1, *p, lat, lon, z, mission_type)


def _upload(f: Flight, items: list[tuple[Any, ...]], mission_type: int = 0,
            partial: tuple[int, int] | None = None) -> tuple[list[int], int]:
    """Upload (with ``partial`` start, end: MISSION_WRITE_PARTIAL_LIST); returns requested seqs, ACK type."""
    g = f.g
    by_seq = {it[0]: it for it in items}
    _quiet(f)
    if partial is None:
        g.conn.mav.mission_count_send(1, 1, len(items), mission_type)
    else:
        g.conn.mav.mission_write_partial_list_send(1, 1, partial[0], partial[1], mission_type)
    kinds = ("MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK")
    req = g.next_mission(kinds)
    seqs: list[int] = []
    while req.get_type() != "MISSION_ACK" and len(seqs) < 40:
        seqs.append(req.seq)
        g.conn.mav.mission_item_int_send(1, 1, *by_seq[req.seq])
        req = g.next_mission(kinds)
    return seqs, req.type


def _quiet(f: Flight) -> None:
    """Drop what is left of the last exchange (a request repeated after 1 s of simulated time, answered
    twice, is acknowledged twice): each exchange starts from the vehicle's next answer."""
    f.during(0.5)
    with f.g._lock:
        f.g.mission.clear()


def _download_item(f: Flight, seq: int) -> Any:
    g = f.g
    _quiet(f)
    g.conn.mav.mission_request_list_send(1, 1, 0)
    count = g.next_mission(("MISSION_COUNT",)).count
    g.conn.mav.mission_request_int_send(1, 1, seq, 0)
    item = g.next_mission(("MISSION_ITEM_INT",))
    g.conn.mav.mission_ack_send(1, 1, M.MAV_MISSION_ACCEPTED, 0)
    return count, item


def observe_mission(ap: Autopilot) -> dict[str, Any]:
    """The mission scenario (see the module docstring); returns the observations."""
    f = Flight(ap)
    g = f.g
    obs: dict[str, Any] = {}
    f.start()
    c = M
    plan = [
        _item(f, 0, c.MAV_CMD_NAV_WAYPOINT, 0, 0, 0),
        _item(f, 1, c.MAV_CMD_NAV_TAKEOFF, 0, 0, 10),
        _item(f, 2, c.MAV_CMD_DO_CHANGE_SPEED, p=(1, 3, -1, 0)),
        _item(f, 3, c.MAV_CMD_NAV_WAYPOINT, 25, 0, 10),
        _item(f, 4, c.MAV_CMD_CONDITION_DELAY, p=(3, 0, 0, 0)),
        _item(f, 5, c.MAV_CMD_CONDITION_YAW, p=(270, 0, 0, 0)),
        _item(f, 6, c.MAV_CMD_NAV_LOITER_TIME, 30, 30, 10, p=(3, 0, 0, 0)),
        _item(f, 7, c.MAV_CMD_DO_JUMP, p=(3, 1, 0, 0)),
        _item(f, 8, c.MAV_CMD_DO_SET_ROI_LOCATION, 60, 30, 0),
        _item(f, 9, c.MAV_CMD_NAV_WAYPOINT, 0, 30, 10),
        _item(f, 10, c.MAV_CMD_NAV_LOITER_TURNS, 0, 45, 10, p=(1, 0, 8, 0)),
        _item(f, 11, c.MAV_CMD_NAV_LOITER_UNLIM, 30, -10, 10),
    ]
    obs["upload"] = _upload(f, plan)
    # a partial edit: item 3 moves to 30 m north, 12 m up; then one item appended (end = count)
    edited = _item(f, 3, c.MAV_CMD_NAV_WAYPOINT, 30, 0, 12)
    obs["partial"] = _upload(f, [edited], partial=(3, 3))
    count, item3 = _download_item(f, 3)
    obs["partial_download"] = (count, item3.command, item3.x == edited[9], item3.y == edited[10], item3.z)
    appended = _item(f, 12, c.MAV_CMD_NAV_WAYPOINT, 0, 0, 10)
    obs["partial_append"] = _upload(f, [appended], partial=(12, 12))
    obs["partial_append_count"] = _download_item(f, 12)[0]
    obs["partial_bad_range"] = _upload(f, [], partial=(5, 3))
    obs["partial_past_end"] = _upload(f, [], partial=(20, 20))
    # put the plan back to 12 items (the appended waypoint would be flown after LOITER_UNLIM: never)
    rally = _item(f, 0, c.MAV_CMD_NAV_RALLY_POINT, 30, -30, 20, mission_type=M.MAV_MISSION_TYPE_RALLY)
    obs["rally_upload"] = _upload(f, [rally], mission_type=M.MAV_MISSION_TYPE_RALLY)

    obs["set_guided"] = g.set_mode(GUIDED)
    obs["arm"] = f.arm()
    g.reached.clear()
    obs["mission_start"] = g.command(M.MAV_CMD_MISSION_START, 0, 0)
    current: list[int] = []
    t_reached: dict[int, float] = {}
    heading_at: dict[Any, float] = {}
    speeds: list[float] = []
    circle_r: list[float] = []

    def each() -> None:
        m = g.last.get("MISSION_CURRENT")
        if m is not None and (not current or current[-1] != m.seq):
            current.append(m.seq)
        for seq in g.reached:
            if seq not in t_reached:
                t_reached[seq] = f.sim_s()
                heading_at[seq] = f.heading()
        if 5 in t_reached and "yaw_held" not in heading_at and f.sim_s() > t_reached[5] + 1.0:
            heading_at["yaw_held"] = f.heading()  # a second after CONDITION_YAW was verified
        if current[-1:] == [3] and len(current) <= 3:
            speeds.append(f.speed())
        if current[-1:] == [10] and 10 not in t_reached:
            p = f.pos()
            circle_r.append(math.hypot(p[0], p[1] - 45.0))

    f.until(lambda: current[-1:] == [11] and math.dist(f.pos()[:2], (30.0, -10.0)) < 2.0, 400,
            "at the LOITER_UNLIM", each)
    f.until(lambda: f.speed() < 0.3, 20, "holding at the LOITER_UNLIM", each)
    f.during(3.0, each)
    obs["mission_current"] = current
    obs["reached"] = list(g.reached)
    obs["speed_leg_3"] = max(speeds) if speeds else None
    obs["delay_s"] = t_reached.get(4, math.nan) - t_reached.get(3, math.nan)
    obs["heading_after_condition_yaw"] = heading_at.get("yaw_held")
    obs["heading_at_wp9"] = heading_at.get(9)
    obs["circle_radius"] = (min(circle_r[len(circle_r) // 2:]), max(circle_r[len(circle_r) // 2:])) \
        if circle_r else None
    obs["still_loitering"] = (current[-1], math.dist(f.pos()[:2], (30.0, -10.0)), f.speed())

    # RTL: to the rally point (nearer than home), lands there
    obs["rtl"] = g.set_mode(RTL)
    alts: list[float] = []
    f.landed_and_disarmed(300, lambda: alts.append(-f.pos()[2]))
    obs["rtl_max_alt"] = max(alts)
    obs["rtl_land_ne"] = f.pos()[:2]
    obs["modes"] = list(g.modes_seen)
    obs["landed_states"] = list(f.states)
    return obs
