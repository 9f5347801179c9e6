"""Missions of the autopilot model: the stored plans (:class:`MissionStore`), what the model accepts in
them (:func:`validate_item`, :func:`validate_plan`) and AUTO-mode execution (:class:`MissionRunner`).

Items keep the fields of MAVLink's MISSION_ITEM_INT so that a download returns exactly what was
uploaded. As in ArduPilot, item 0 of the flight plan (mission type MISSION) is home: it is stored
and returned but never flown; AUTO starts at item 1. Fence and rally plans are stored the same way
(fence polygons and circles are read by :mod:`autopilot_model.modules.safety`).

Files: this one holds the execution; :mod:`.mission_items` the items, what is accepted and their geodesy;
:mod:`.mission_store` the storage. Their public names are importable from here as before.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from taskflight_common.ardupilot import CopterMode

from .circle_nav import CircleNav, define_circle_params
from .mission_do import DoCommands, next_cmd
from .mission_items import (
    ACCEPTED,
    CONDITION_YAW,
    DO_CHANGE_SPEED,
    FENCE,
    FENCE_CIRCLE_EXCLUSION,
    FENCE_CIRCLE_INCLUSION,
    FENCE_POLYGON_EXCLUSION,
    FENCE_POLYGON_INCLUSION,
    FENCE_RETURN_POINT,
    FRAME_GLOBAL,
    FRAME_GLOBAL_INT,
    FRAME_RELATIVE,
    FRAME_RELATIVE_INT,
    GLOBAL_FRAMES,
    MAX_ITEMS,
    MISSION,
    MISSION_TYPES,
    NAV_COMMANDS,
    NAV_LAND,
    NAV_LOITER_TIME,
    NAV_LOITER_TURNS,
    NAV_LOITER_UNLIM,
    NAV_RETURN_TO_LAUNCH,
    NAV_TAKEOFF,
    NAV_WAYPOINT,
    POSITIONLESS,
    RALLY,
    RALLY_POINT,
    RELATIVE_FRAMES,
    SUPPORTED,
    MissionItem,
    item_to_ned,
    validate_item,
    validate_plan,
    vehicle_frames,
)
from .mission_store import MissionStore
from .shared_params import define_rtl_alt

if TYPE_CHECKING:
    from autopilot_model.params import ParamStore

    from .auto_yaw import AutoYaw
    from .vehicle_api import GroundLink, VehicleApi

__all__ = [
    "ACCEPTED",
    "COMPLETE",
    "DO_CHANGE_SPEED",
    "FENCE",
    "FENCE_CIRCLE_EXCLUSION",
    "FENCE_CIRCLE_INCLUSION",
    "FENCE_POLYGON_EXCLUSION",
    "FENCE_POLYGON_INCLUSION",
    "FENCE_RETURN_POINT",
    "FRAME_GLOBAL",
    "FRAME_GLOBAL_INT",
    "FRAME_RELATIVE",
    "FRAME_RELATIVE_INT",
    "GLOBAL_FRAMES",
    "IDLE",
    "MAX_ITEMS",
    "MISSION",
    "MISSION_TYPES",
    "NAV_COMMANDS",
    "NAV_LAND",
    "NAV_LOITER_TIME",
    "NAV_RETURN_TO_LAUNCH",
    "NAV_TAKEOFF",
    "NAV_WAYPOINT",
    "POSITIONLESS",
    "RALLY",
    "RALLY_POINT",
    "RELATIVE_FRAMES",
    "RUNNING",
    "SUPPORTED",
    "WAITING",
    "MissionItem",
    "MissionRunner",
    "MissionStore",
    "define_mission_params",
    "item_to_ned",
    "validate_item",
    "validate_plan",
    "vehicle_frames",
]

log = logging.getLogger(__name__)


def _finite(value: float, default: float = 0.0) -> float:
    return value if math.isfinite(value) else default


# --- execution --------------------------------------------------------------------------------------
IDLE = "idle"
"""Not in AUTO."""
WAITING = "waiting"
"""In AUTO on the ground: waiting for MAV_CMD_MISSION_START (and arming), as ArduCopter does."""
RUNNING = "running"
COMPLETE = "complete"
"""Past the last item: holding position in the air, or landed."""

# MISSION_STATE / MISSION_CURRENT.mission_mode values
_STATE_NO_MISSION, _STATE_NOT_STARTED, _STATE_ACTIVE, _STATE_PAUSED, _STATE_COMPLETE = 1, 2, 3, 4, 5
_LANDED_ON_GROUND = 1
_LANDED_TAKEOFF = 3
_SETTLE_S = 2.0
"""A target the generator has reached counts as reached after this long even if the vehicle sits
just outside a (very small) acceptance radius."""


def define_mission_params(params: ParamStore) -> None:
    """ArduCopter parameters the mission runner reads (units as ArduCopter: cm, cm/s)."""
    params.define("WPNAV_RADIUS", 200.0, 5.0, 1000.0, doc="waypoint acceptance radius (cm) when an item's "
                  "param2 is 0")
    define_rtl_alt(params)
    define_circle_params(params)


class AutoModeHost(Protocol):
    """What the runner follows of the mode machine (:class:`.flight_modes.FlightModes`)."""

    mode: int
    speed_override_h: float | None
    auto_yaw: AutoYaw

    def on_mode_change(self, callback: Callable[[int, int, str], None]) -> None: ...


class MissionRunner:
    """Flies the stored flight plan in AUTO, item by item, through the navigator (goto, takeoff, land,
    hold), so the envelope and the continuity of the setpoints hold as in every other mode.

    Lifecycle, as ArduCopter: :meth:`start` on entering AUTO (in the air it resumes the current item at
    once; on the ground it waits), :meth:`mission_start` for MAV_CMD_MISSION_START (takes off once
    armed), :meth:`update` every navigation step while in AUTO, :meth:`stop` on leaving AUTO. At the end
    of the plan the vehicle holds position in AUTO, or stays landed if the plan ended with a landing.

    Supported: NAV_TAKEOFF, NAV_WAYPOINT (param1 hold time s; param2 acceptance radius m, 0 =
    WPNAV_RADIUS), NAV_LOITER_TIME (param1 s), NAV_LOITER_UNLIM (never completes), NAV_LOITER_TURNS
    (param1 turns, param3 radius m, negative counter-clockwise; 0 = CIRCLE_RADIUS), NAV_LAND (at lat/lon
    if given), NAV_RETURN_TO_LAUNCH (climb to RTL_ALT, return, land); beside them (:mod:`.mission_do`)
    DO_CHANGE_SPEED (param2 m/s), CONDITION_DELAY, CONDITION_YAW, DO_SET_ROI(_LOCATION, _NONE), and
    DO_JUMP. Heading: towards the next waypoint (ArduCopter's WP_YAW_BEHAVIOR 2), unless a
    CONDITION_YAW or an ROI holds it.
    """

    def __init__(self, vehicle: VehicleApi, store: MissionStore, endpoint: GroundLink | None = None,
                 modes: AutoModeHost | None = None) -> None:
        self.vehicle = vehicle
        self.store = store
        self.endpoint = endpoint
        self.params = vehicle.params
        define_mission_params(self.params)
        self.state = IDLE
        self.finished = False
        """True once the last item has completed (reset by the next start)."""
        self.start_requested = False
        self.speed: float | None = None
        """Horizontal speed set by DO_CHANGE_SPEED (m/s); None = WPNAV_SPEED."""
        self._item: MissionItem | None = None
        self._phase = ""
        self._target: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self._radius = 0.0
        self._t_phase = 0.0
        self._t_settled: float | None = None
        self._hold_s = 0.0
        self._jumping = False
        self._modes: AutoModeHost | None = None
        self.do = DoCommands(self)
        self.jumps: dict[int, int] = {}
        """Jumps taken per DO_JUMP item (AP_Mission's jump tracking)."""
        self.circle = CircleNav(vehicle)
        self._turns = 0.0
        self._reached_pending: int | None = None
        self.reached: list[int] = []
        """Sequence numbers reached so far (also sent as MISSION_ITEM_REACHED)."""
        store.on_current(self._on_current)
        store.on_change(self._on_change)
        if modes is not None:
            self.attach_modes(modes)

    # --- MissionStatus (for MISSION_CURRENT) ------------------------------------------------------
    @property
    def mission_state(self) -> int:
        if self.store.count(MISSION) <= 1:
            return _STATE_NO_MISSION
        return {IDLE: _STATE_PAUSED if self._item is not None else _STATE_NOT_STARTED,
                WAITING: _STATE_NOT_STARTED, RUNNING: _STATE_ACTIVE,
                COMPLETE: _STATE_COMPLETE}[self.state]

    @property
    def mission_mode(self) -> int:
        return 1 if self.state != IDLE else 2

    # --- lifecycle ----------------------------------------------------------------------------------
    def attach_modes(self, modes: AutoModeHost, auto_mode: int = CopterMode.AUTO) -> None:
        """Follow a FlightModes object: :meth:`stop` whenever the mode leaves AUTO; honour its
        DO_CHANGE_SPEED override (a MAV_CMD_DO_CHANGE_SPEED command while in AUTO)."""
        self._modes = modes

        def on_change(*args: Any) -> None:
            if modes.mode != auto_mode:
                self.stop()
        modes.on_mode_change(on_change)

    def start(self) -> tuple[bool, str]:
        """Entering AUTO (refused without a plan, as ArduCopter). In the air: fly the current item now
        (from item 1 if the plan had been completed). On the ground: wait for MISSION_START; an armed
        copter on the ground needs a take-off as its first navigation item."""
        nav = self.vehicle.nav
        if self.store.count(MISSION) <= 1:
            return False, "Auto: no mission"
        if nav.armed and nav.landed_state == _LANDED_ON_GROUND and not self._starts_with_takeoff():
            return False, "Auto: Missing Takeoff Cmd"
        self.start_requested = False
        if self._on_ground():
            self.state = WAITING
            return True, ""
        self._run_from(1 if self.finished else self.store.current)
        return True, ""

    def mission_start(self, first: int = 0) -> tuple[bool, str]:
        """MAV_CMD_MISSION_START (in AUTO): start at ``first`` (0 = the current item; from the ground,
        or after the plan was completed, item 1). A disarmed vehicle starts once it is armed."""
        if self.store.count(MISSION) <= 1:
            return False, "Mission: no items"
        if first > 0 and not self.store.set_current(first):
            return False, f"Mission: invalid item {first}"
        if self.state == RUNNING:
            return True, ""
        if not self.vehicle.nav.armed:
            self.state = WAITING
            self.start_requested = True  # take off as soon as the vehicle is armed
            return True, ""
        on_ground = self._on_ground()
        if on_ground and not self._starts_with_takeoff():
            return False, "Auto: Missing Takeoff Cmd"
        first_seq = self.store.current
        if on_ground or self.finished or first_seq < 1:
            first_seq = 1
        if first_seq == 1:
            self.speed = None  # a fresh start flies at WPNAV_SPEED
        self._run_from(first_seq)
        return True, ""

    def resume(self) -> None:
        """MAV_CMD_DO_PAUSE_CONTINUE(continue): fly on to the target the pause stopped short of."""
        if self.state == RUNNING and self._item is not None and self._phase == "goto":
            self._goto(self._target)

    def stop(self) -> None:
        """Leaving AUTO: stop commanding; the current item stays current (resumed by the next start)."""
        if self.state != IDLE:
            log.debug("mission runner stopped at item %d", self.store.current)
        self.state = IDLE
        self.store.running = False
        self.start_requested = False

    # --- periodic (navigation group, called by the AUTO flight mode) -------------------------------
    def update(self) -> None:
        nav = self.vehicle.nav
        if self.state == WAITING:
            if self.start_requested and nav.armed:
                self.start_requested = False
                self.mission_start()
            return
        if self.state != RUNNING or self._item is None:
            return
        if not nav.armed and self._phase not in ("landing",):
            self.state = WAITING  # disarmed under us: wait for a new start
            self.store.running = False
            return
        self._reached_pending = None
        if self._check_done():
            self._complete_item()
        # AP_Mission::update: the do command beside the navigation command
        if self.state == RUNNING:
            if self.do.item is None:
                self.do.advance(self.store, self.jumps)
            elif self.do.verified():
                self._reached(self.do.item)
                self.do.item = None
        if self._reached_pending is not None and self.endpoint is not None:
            self.endpoint.send(self.endpoint.mav.mission_item_reached_encode(self._reached_pending))
        self._reached_pending = None

    # --- what the do commands use --------------------------------------------------------------------
    @property
    def nav_item(self) -> MissionItem:
        assert self._item is not None
        return self._item

    def now(self) -> float:
        return self._now()

    def home_alt(self) -> float:
        return self._geo()[1]

    def auto_yaw(self) -> AutoYaw | None:
        return self._modes.auto_yaw if self._modes is not None else None

    def change_speed(self, item: MissionItem) -> None:
        """DO_CHANGE_SPEED: also the leg being flown (ArduCopter's set_speed_NE changes it at once)."""
        self._change_speed(item)
        if self._phase in ("goto", "approach", "climb", "return"):
            self._goto(self._target)

    def change_speed_now(self) -> None:
        """MAV_CMD_DO_CHANGE_SPEED in AUTO: the leg being flown takes the new speed."""
        if self.state == RUNNING and self._phase in ("goto", "approach", "climb", "return"):
            self._goto(self._target)

    def can_pause(self) -> bool:
        """``ModeAuto::pause``: only while flying to a waypoint not yet reached."""
        return self.state == RUNNING and self._phase == "goto" and not self._arrived()

    # --- internals ----------------------------------------------------------------------------------
    def _on_ground(self) -> bool:
        nav = self.vehicle.nav
        return not nav.armed or nav.landed_state == _LANDED_ON_GROUND

    def _starts_with_takeoff(self) -> bool:
        items = self.store.items
        first = next((it for it in items[1:] if it.command in NAV_COMMANDS), None)
        return first is not None and first.command == NAV_TAKEOFF

    def _run_from(self, seq: int) -> None:
        """``advance_current_nav_cmd`` from ``seq``: start the first do command passed on the way (following
        DO_JUMPs) and the navigation command found; past the end, the mission is complete."""
        seq = max(1, seq)
        if seq <= 1:
            self.jumps.clear()
        self.do.reset()
        say = None
        ep = self.endpoint
        if ep is not None:
            def say(text: str) -> None:
                ep.statustext(mavlink.MAV_SEVERITY_INFO, text)
        first_do: MissionItem | None = None
        idx = seq
        while True:
            it = next_cmd(self.store, idx, self.jumps, increment=True, say=say)
            if it is None:
                if first_do is not None:
                    self.do.start(first_do)
                self._finish()
                return
            if it.command in NAV_COMMANDS:
                break
            if first_do is None:
                first_do = it
            idx = it.seq + 1
        self.state = RUNNING
        self.finished = False
        self.store.running = True
        self._set_current(it.seq)
        if first_do is not None:
            self.do.start(first_do)
        else:
            self.do.all_done = True
        self._begin(it)

    def _set_current(self, seq: int) -> None:
        self._jumping = True
        try:
            self.store.set_current(seq)
        finally:
            self._jumping = False

    def _on_current(self, seq: int) -> None:
        if self._jumping or self.state != RUNNING:
            return
        self._run_from(seq)  # MISSION_SET_CURRENT while flying the plan: go there now

    def _on_change(self, mission_type: int) -> None:
        if mission_type != MISSION:
            return
        if self.state != RUNNING:
            self._item = None  # a new plan: nothing paused any more
            return
        if self.store.current >= 1 and self.store.current < self.store.count(MISSION):
            self._run_from(self.store.current)  # plan replaced in flight: restart the current item
        else:
            self._finish()

    def _pos(self) -> tuple[float, float, float]:
        p = self.vehicle.state.position_ned
        return (float(p[0]), float(p[1]), float(p[2]))

    def _now(self) -> float:
        return float(self.vehicle.clock.now())

    def _geo(self) -> tuple[tuple[float, float, float], float, tuple[float, float, float]]:
        """(origin, home altitude AMSL, home NED)."""
        return vehicle_frames(self.vehicle)

    def _goto(self, target: tuple[float, float, float], face: bool = False) -> None:
        self._target = target
        self._t_settled = None
        speed = self.speed
        override = self._modes.speed_override_h if self._modes is not None else None
        if override is not None:
            speed = override
        nav = self.vehicle.nav
        nav.goto(target, speed=speed)
        yaw = self.auto_yaw()
        if face and yaw is not None and yaw.mode == "none":
            n, e, _ = self._pos()
            if math.hypot(target[0] - n, target[1] - e) > 2.0:  # WP_YAW_BEHAVIOR 2: face the next WP
                nav.yaw(math.atan2(target[1] - e, target[0] - n), None)

    def _phase_to(self, phase: str) -> None:
        self._phase = phase
        self._t_phase = self._now()
        self._t_settled = None

    def _begin(self, item: MissionItem) -> None:
        self._item = item
        nav = self.vehicle.nav
        origin, home_alt, home_ned = self._geo()
        pos = self._pos()
        c = item.command
        log.info("mission: item %d, command %d", item.seq, c)
        yaw = self.auto_yaw()
        if yaw is not None and yaw.mode == "fixed" and not (
                self.do.item is not None and self.do.item.command == CONDITION_YAW):
            yaw.reset()  # wp_start: auto yaw back to the default (an ROI stays)
        if c == NAV_TAKEOFF:
            alt_home = item.z if item.frame in RELATIVE_FRAMES else item.z - home_alt
            target_d = -(alt_home + home_alt - origin[2])
            self._target = (pos[0], pos[1], target_d)
            self._radius = min(1.0, self.params.get("WPNAV_RADIUS") / 100.0)
            self._phase_to("takeoff")
            if pos[2] <= target_d + 0.1:
                self._phase_to("done")  # already at or above the take-off altitude
            elif nav.landed_state == _LANDED_ON_GROUND:
                nav.takeoff(-target_d)
            else:
                self._goto(self._target)
        elif c in (NAV_WAYPOINT, NAV_LOITER_TIME, NAV_LOITER_UNLIM):
            self._phase_to("goto")
            self._goto(item_to_ned(item, origin, home_alt, pos), face=True)
            r = _finite(item.param2) if c == NAV_WAYPOINT else 0.0
            self._radius = r if r > 0 else self.params.get("WPNAV_RADIUS") / 100.0
            self._hold_s = math.inf if c == NAV_LOITER_UNLIM else max(0.0, _finite(item.param1))
        elif c == NAV_LOITER_TURNS:
            centre = item_to_ned(item, origin, home_alt, pos)
            r = abs(_finite(item.param3))
            self._circle_r = r if r > 0 else self.params.get("CIRCLE_RADIUS") / 100.0
            rate = math.radians(abs(self.params.get("CIRCLE_RATE")))
            self._circle_rate = -rate if _finite(item.param3) < 0 else rate
            self._circle_centre = centre
            self._turns = max(_finite(item.param1), 0.0)
            self._radius = 1.0
            self._phase_to("edge")
            self._goto(self.circle.edge_point(centre, self._circle_r), face=True)
        elif c == NAV_LAND:
            if item.x == 0 and item.y == 0:
                self._phase_to("landing")
                nav.land()
            else:
                n, e, _ = item_to_ned(item, origin, home_alt, pos)
                self._phase_to("approach")
                self._radius = self.params.get("WPNAV_RADIUS") / 100.0
                self._goto((n, e, pos[2]))
        elif c == NAV_RETURN_TO_LAUNCH:
            rtl_alt = self.params.get("RTL_ALT") / 100.0
            d = min(pos[2], -(rtl_alt + home_alt - origin[2])) if rtl_alt > 0 else pos[2]
            self._radius = self.params.get("WPNAV_RADIUS") / 100.0
            if pos[2] - d > 0.5:
                self._phase_to("climb")
                self._goto((pos[0], pos[1], d))
            else:
                self._phase_to("return")
                self._goto((home_ned[0], home_ned[1], d))
        else:  # validated at upload: cannot happen
            log.warning("mission: item %d: command %d not flown", item.seq, c)
            self._phase_to("done")

    def _change_speed(self, item: MissionItem) -> None:
        speed = _finite(item.param2, -1.0)
        if item.param1 in (2, 3):  # climb / descent speed: the navigator's own limits apply
            return
        if speed > 0:
            self.speed = speed
        elif speed == -2:
            self.speed = None

    def _arrived(self) -> bool:
        pos = self._pos()
        dist = math.dist(pos, self._target)
        if dist <= self._radius:
            return True
        # the generator has arrived and the vehicle has settled near the target (tiny radius)
        if self.vehicle.guidance.at_target and dist <= max(1.0, self._radius):
            if self._t_settled is None:
                self._t_settled = self._now()
            return self._now() - self._t_settled >= _SETTLE_S
        self._t_settled = None
        return False

    def _check_done(self) -> bool:
        nav = self.vehicle.nav
        phase = self._phase
        if phase == "done":
            return True
        if phase == "takeoff":
            if nav.landed_state == _LANDED_TAKEOFF:  # the navigator's take-off: wait for it to finish
                return False
            return self._arrived()
        if phase == "goto":
            if self._arrived():
                self._phase_to("hold")
            return False
        if phase == "hold":
            return self._now() - self._t_phase >= self._hold_s
        if phase == "edge":
            if self._arrived():
                self._phase_to("circle")
                self.circle.start_at(self._circle_centre, self._circle_r, self._circle_rate)
            return False
        if phase == "circle":
            self.circle.update(self.vehicle.step_of("flight_modes.update"))
            if self.circle.turns >= self._turns:
                self.vehicle.nav.hold()
                return True
            return False
        if phase == "approach" and self._arrived():
            self._phase_to("landing")
            nav.land()
            return False
        if phase == "climb" and self._arrived():
            _, _, home_ned = self._geo()
            self._phase_to("return")
            self._goto((home_ned[0], home_ned[1], self._target[2]))
            return False
        if phase == "return" and self._arrived():
            self._phase_to("landing")
            nav.land()
            return False
        if phase == "landing":
            return nav.landed_state == _LANDED_ON_GROUND or not nav.armed
        return False

    def _reached(self, item: MissionItem) -> None:
        """``verify_command`` succeeded (every command, as ArduCopter): MISSION_ITEM_REACHED at the end of
        the cycle. ArduCopter queues one such message per cycle (``send_mission_item_reached_message``
        keeps the last index), so a navigation item verified in the same cycle as the do command started
        with the next one is overtaken by it; the model reports the same way."""
        self.reached.append(item.seq)
        self._reached_pending = item.seq
        if self.endpoint is not None and item.command in (NAV_WAYPOINT, NAV_LOITER_TIME):
            self.endpoint.statustext(mavlink.MAV_SEVERITY_INFO, f"Reached command #{item.seq}")

    def _complete_item(self) -> None:
        item = self._item
        assert item is not None
        self._reached(item)
        self._run_from(item.seq + 1)

    def _finish(self) -> None:
        """End of the plan: hold in the air (ArduCopter loiters in AUTO), or stay landed."""
        self.state = COMPLETE
        self.finished = True
        self.store.running = False
        nav = self.vehicle.nav
        if nav.armed and nav.landed_state != _LANDED_ON_GROUND:
            nav.hold()
        if self.endpoint is not None:
            self.endpoint.statustext(mavlink.MAV_SEVERITY_INFO, "Mission complete")
