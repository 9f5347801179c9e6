"""ArduCopter flight modes on top of the Navigator (navigation task group).

Modes are ArduCopter's ``custom_mode`` numbers. The pilot-driven modes (STABILIZE, ALT_HOLD, LOITER,
POSHOLD) fly the RC sticks once RC has been seen (RC_CHANNELS_OVERRIDE, MANUAL_CONTROL:
:mod:`.pilot_modes`); before that they hold still:

==========  ===  ===========================================================================
STABILIZE    0   level, zero velocity demand (no position hold: it drifts with estimator error)
ALT_HOLD     2   as STABILIZE (the altitude is held by the velocity demand)
AUTO         3   delegates to the mission runner (``modes.mission_runner``: ``start()``, ``update()``)
GUIDED       4   targets from the ground station / companion (:class:`GuidedTargets`); GUID_TIMEOUT
LOITER       5   hold position
RTL          6   climb to RTL_ALT if lower, fly home or to the nearest rally point (:mod:`.rally`), land
LAND         9   land where it is; stays in LAND after touchdown and disarm, as ArduCopter does
CIRCLE       7   circle a centre CIRCLE_RADIUS ahead at CIRCLE_RATE, nose in (:mod:`.circle_nav`)
POSHOLD     16   as LOITER without a pilot; with one: lean angles, braking to a hold when sticks centre
BRAKE       17   stop as fast as the envelope allows and hold
SMART_RTL   21   fly the recorded path back, land where armed (:mod:`.smart_rtl`); refused without a path
==========  ===  ===========================================================================

Every change of mode goes through :meth:`FlightModes.set_mode`, which may refuse with a reason;
listeners registered with :meth:`FlightModes.on_mode_change` are told of each change (the MAVLink
endpoint announces it by STATUSTEXT, the failsafes use ``set_mode`` with a reason).

GUIDED semantics follow ArduCopter's ``ModeGuided``: a position target is flown to and held; a
velocity or acceleration target (alone or as feed-forward of a position target) must be refreshed
within ``GUID_TIMEOUT`` seconds, otherwise the vehicle stops (velocity and acceleration demand set
to zero) and holds; entering GUIDED in the air holds the current position. A position + velocity
(+ acceleration) target is a *moving* target, as in ``ModeGuided::posvelaccel_control_run``: see
:class:`GuidedTargets`. All GUIDED positions are local NED from the EKF origin (the state's
``origin``), never from home.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol

from autopilot_model.modules import navigation as navmod
from autopilot_model.modules import rally
from autopilot_model.modules.auto_yaw import AutoYaw
from autopilot_model.modules.circle_nav import CircleNav, define_circle_params
from autopilot_model.modules.guided_targets import (  # noqa: F401 - re-exported
    G_ACCEL,
    G_NONE,
    G_POS,
    G_POSVEL,
    G_VEL,
    PSC_JERK,
    GuidedTarget,
    GuidedTargets,
    sqrt_controller,
)
from autopilot_model.modules.shared_params import define_rtl_alt
from autopilot_model.modules.smart_rtl import SmartRtl
from taskflight_common.ardupilot import CopterMode
from taskflight_common.geo import geodetic_to_ned

if TYPE_CHECKING:
    from autopilot_model.modules.fence import Fence
    from autopilot_model.modules.mission_store import MissionStore
    from autopilot_model.modules.pilot_modes import PilotModes
    from autopilot_model.modules.vehicle_api import VehicleApi
    from autopilot_model.params import ParamStore

log = logging.getLogger(__name__)

STABILIZE = CopterMode.STABILIZE
ALT_HOLD = CopterMode.ALT_HOLD
AUTO = CopterMode.AUTO
GUIDED = CopterMode.GUIDED
LOITER = CopterMode.LOITER
RTL = CopterMode.RTL
CIRCLE = CopterMode.CIRCLE
LAND = CopterMode.LAND
POSHOLD = CopterMode.POSHOLD
BRAKE = CopterMode.BRAKE
SMART_RTL = CopterMode.SMART_RTL

#: The ArduCopter modes the model flies: number -> name.
MODE_NAMES: dict[int, str] = {m.value: m.name for m in (
    STABILIZE, ALT_HOLD, AUTO, GUIDED, LOITER, RTL, CIRCLE, LAND, POSHOLD, BRAKE, SMART_RTL)}
MODE_NUMBERS: dict[str, int] = {v: k for k, v in MODE_NAMES.items()}
#: Modes ArduCopter lets a ground station arm in (AUTO, RTL, LAND, BRAKE refuse arming).
ARMABLE = frozenset({STABILIZE, ALT_HOLD, GUIDED, LOITER, POSHOLD})
#: Modes in which a take-off command is accepted (ArduCopter: modes with a navigating user take-off).
TAKEOFF_MODES = frozenset({GUIDED, LOITER})
#: Modes in which MAV_CMD_DO_PAUSE_CONTINUE applies (ArduCopter: ``pause()`` of ModeAuto, ModeGuided).
PAUSABLE = frozenset({AUTO, GUIDED})
#: Modes whose speed DO_CHANGE_SPEED sets (ArduCopter: ``set_speed_xy_cms`` of Auto, Guided, RTL).
SPEED_MODES = frozenset({AUTO, GUIDED, RTL})
#: Modes that fly the auto yaw (CONDITION_YAW, ROI).
AUTO_YAW_MODES = frozenset({AUTO, GUIDED, RTL, SMART_RTL})

ModeListener = Callable[[int, int, str], None]
Vec3 = tuple[float, float, float]

# RTL stages
RTL_CLIMB = "climb"
RTL_RETURN = "return"
RTL_LAND = "land"


_home_cache: dict[int, tuple[Any, Vec3]] = {}


def home_ned(vehicle: VehicleApi) -> Vec3:
    """Home (``vehicle.home``: lat, lon, alt AMSL) in the local NED frame of the state's origin."""
    key = (tuple(vehicle.home[:3]), tuple(vehicle.state.origin))
    cached = _home_cache.get(id(vehicle))
    if cached is None or cached[0] != key:
        h = vehicle.home
        cached = (key, geodetic_to_ned(vehicle.state.origin, h[0], h[1], h[2]))
        _home_cache[id(vehicle)] = cached
    return cached[1]


def mode_name(mode: int) -> str:
    return MODE_NAMES.get(mode, f"MODE{mode}")


def define_mode_params(params: ParamStore) -> None:
    params.define("GUID_TIMEOUT", 3.0, 0.1, 5.0,
                  doc="GUIDED: stop if no new velocity/acceleration target for this long (s)")
    define_rtl_alt(params)
    params.define("RTL_SPEED", 0.0, 0.0, 2000.0, doc="RTL: horizontal speed, 0 = WPNAV_SPEED (cm/s)")
    define_circle_params(params)
    rally.define_rally_params(params)


class AutoRunner(Protocol):
    """What AUTO and the mission's MAV_CMDs ask of the mission runner (:class:`.mission.MissionRunner`)."""

    speed: float | None

    def start(self) -> tuple[bool, str]: ...
    def mission_start(self, first: int = 0) -> tuple[bool, str]: ...
    def stop(self) -> None: ...
    def change_speed_now(self) -> None: ...
    def update(self) -> None: ...
    def resume(self) -> None: ...
    def can_pause(self) -> bool: ...


class FlightModes:
    """The ArduCopter mode machine of one vehicle; the only writer of ``mode``."""

    def __init__(self, vehicle: VehicleApi) -> None:
        self.v = vehicle
        define_mode_params(vehicle.params)
        self.mode: int = STABILIZE
        self.mission_runner: AutoRunner | None = None  # the mission runner (AUTO), set by the wiring
        self.guided = GuidedTargets(self)
        self.paused = False
        self.speed_override_h: float | None = None  # DO_CHANGE_SPEED (m/s), until the next mode change
        self._rtl_stage = RTL_CLIMB
        self._listeners: list[ModeListener] = []
        self.pilot: PilotModes | None = None  # the pilot-driven modes, set by the wiring
        self.fence: Fence | None = None  # the geofence: GUIDED destinations outside it are refused
        self.auto_yaw = AutoYaw(vehicle)
        self.circle = CircleNav(vehicle)
        self.smart_rtl = SmartRtl(vehicle)
        self.missions: MissionStore | None = None  # rally points for RTL, set by the wiring

    # --- listeners -----------------------------------------------------------------------------
    def on_mode_change(self, callback: ModeListener) -> None:
        """``callback(old_mode, new_mode, reason)`` after every accepted change."""
        self._listeners.append(callback)

    @property
    def name(self) -> str:
        return mode_name(self.mode)

    def in_air(self) -> bool:
        nav = self.v.nav
        return nav.armed and nav.landed_state != navmod.LANDED_ON_GROUND

    def speed_h(self) -> float:
        """Horizontal speed of position targets: DO_CHANGE_SPEED if given, else WPNAV_SPEED (m/s)."""
        if self.speed_override_h is not None:
            return self.speed_override_h
        return self.v.params.get("WPNAV_SPEED") / 100.0

    def allows_arming(self) -> bool:
        return self.mode in ARMABLE

    # --- changing mode -------------------------------------------------------------------------
    def set_mode(self, mode: int, reason: str = "") -> tuple[bool, str]:
        """Enter ``mode`` (ArduCopter number); returns ``(ok, why_not)``. Re-entering a mode is a no-op."""
        if mode not in MODE_NAMES:
            return False, f"Mode change denied: unknown mode {mode}"
        if mode == self.mode:
            return True, ""
        enter = getattr(self, f"_enter_{MODE_NAMES[mode].lower()}")
        ok, why = enter()
        if not ok:
            log.info("mode %s refused: %s", mode_name(mode), why)
            return False, why
        old = self.mode
        self.mode = mode
        self.paused = False
        self.speed_override_h = None
        self.auto_yaw.reset()
        if mode != GUIDED:
            self.guided.reset()
        if self.pilot is not None:
            self.pilot.enter(mode)
        log.info("mode %s -> %s %s", mode_name(old), mode_name(mode), reason)
        for cb in list(self._listeners):
            cb(old, mode, reason)
        return True, ""

    def _enter_stabilize(self) -> tuple[bool, str]:
        if self.in_air():
            self.v.nav.velocity((0.0, 0.0, 0.0))
        return True, ""

    _enter_alt_hold = _enter_stabilize

    def _enter_guided(self) -> tuple[bool, str]:
        self.guided.reset()
        if self.in_air() and self.v.nav.action != navmod.TAKEOFF:
            self.v.nav.hold()
        return True, ""

    def _enter_loiter(self) -> tuple[bool, str]:
        if self.in_air():
            self.v.nav.hold()
        return True, ""

    _enter_brake = _enter_loiter
    _enter_poshold = _enter_loiter

    def _enter_circle(self) -> tuple[bool, str]:
        if self.in_air():
            p = self.v.params
            self.circle.start_here(p.get("CIRCLE_RADIUS") / 100.0, math.radians(p.get("CIRCLE_RATE")))
        return True, ""

    def _enter_smart_rtl(self) -> tuple[bool, str]:
        return self.smart_rtl.start()

    def _enter_land(self) -> tuple[bool, str]:
        if self.in_air():
            self.v.nav.land()
        return True, ""

    def _enter_rtl(self) -> tuple[bool, str]:
        if self.in_air():
            self._rtl_stage = RTL_CLIMB
            self._rtl_start()
        return True, ""

    def _enter_auto(self) -> tuple[bool, str]:
        runner = self.mission_runner
        if runner is None:
            return False, "Auto: no mission runner"
        ok, why = runner.start()
        return (True, "") if ok else (False, why)

    # --- pause / continue (MAV_CMD_DO_PAUSE_CONTINUE) -----------------------------------------
    def pause(self) -> tuple[bool, str]:
        """``Mode::pause``: GUIDED always; AUTO while flying to a waypoint not yet reached."""
        runner = self.mission_runner
        if self.mode == AUTO and not (runner is not None and runner.can_pause()):
            return False, "Failed to pause"
        if self.mode not in PAUSABLE:
            return False, "Failed to pause"
        self.paused = True
        if self.in_air():
            self.v.nav.hold()
        return True, ""

    def resume(self) -> tuple[bool, str]:
        if self.mode not in PAUSABLE:
            return False, "Failed to resume"
        if not self.paused:
            return True, ""
        self.paused = False
        if not self.in_air():
            return True, ""
        if self.mode == AUTO and self.mission_runner is not None:
            self.mission_runner.resume()
        elif self.mode == GUIDED:
            self.guided.resume()
        return True, ""

    # --- RTL -----------------------------------------------------------------------------------
    def _rtl_alt(self) -> float:
        return self.v.params.get("RTL_ALT") / 100.0

    def _rtl_speed(self) -> float:
        s = self.v.params.get("RTL_SPEED") / 100.0
        return s if s > 0 else self.speed_h()

    def _home_ned(self) -> Vec3:
        return home_ned(self.v)

    def _rtl_start(self) -> None:
        nav = self.v.nav
        n, e, d = self.v.state.position_ned
        hn, he, hd = self._home_ned()
        alt_above_home = hd - d
        target_alt = max(self._rtl_alt(), alt_above_home)
        best = rally.return_target(self.v, self.missions)  # the nearest rally point, else home
        if best is not None:
            (hn, he, _), rally_alt = best
            target_alt = max(target_alt, rally_alt)
        if self._rtl_stage == RTL_CLIMB and alt_above_home < self._rtl_alt() - 0.5:
            nav.goto((n, e, hd - target_alt), self._rtl_speed())
        else:
            self._rtl_stage = RTL_RETURN
            nav.goto((hn, he, hd - target_alt), self._rtl_speed())

    def rtl_speed_changed(self) -> None:
        """DO_CHANGE_SPEED in RTL: the climb or the return goes on at the new speed."""
        if self.mode == RTL and self.in_air() and self._rtl_stage in (RTL_CLIMB, RTL_RETURN):
            self._rtl_start()

    def _rtl_update(self) -> None:
        nav = self.v.nav
        if not self.in_air() or self.paused:
            return
        g = self.v.guidance
        if self._rtl_stage == RTL_CLIMB and g.at_target:
            self._rtl_stage = RTL_RETURN
            self._rtl_start()
        elif self._rtl_stage == RTL_RETURN and g.at_target:
            self._rtl_stage = RTL_LAND
            nav.land()

    # --- periodic (navigation group) -----------------------------------------------------------
    def update(self) -> None:
        mode = self.mode
        dt = self.v.step_of("flight_modes.update")
        if self.pilot is not None:
            self.pilot.update(dt)
        self.smart_rtl.record(mode != SMART_RTL)
        if mode in AUTO_YAW_MODES:
            self.auto_yaw.update()
        if mode == CIRCLE:
            if self.in_air():
                self.circle.update(dt)
        elif mode == SMART_RTL:
            self.smart_rtl.update()
        elif mode == GUIDED:
            if not self.paused:
                self.guided.update()
        elif mode == RTL:
            self._rtl_update()
        elif mode == AUTO and not self.paused and self.mission_runner is not None:
            self.mission_runner.update()
