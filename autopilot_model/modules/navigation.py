"""Navigator: the primitive actions beneath the flight modes (navigation task group).

Arming with pre-arm checks, take-off, landing with a land detector, and the target setters that feed
the setpoint generator (seed 000 Fig. 9: the flight command's target parameters P_t). ArduCopter's
flight modes (:mod:`autopilot_model.modules.flight_modes`) are built on these actions.
Nothing here touches the setpoints directly: every motion goes through the generator, so the envelope
and the continuity of P_d always hold.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from autopilot_model.modules.vehicle_api import VehicleApi

log = logging.getLogger(__name__)

# MAV_LANDED_STATE
LANDED_UNDEFINED = 0
LANDED_ON_GROUND = 1
LANDED_IN_AIR = 2
LANDED_TAKEOFF = 3
LANDED_LANDING = 4

# what the navigator is doing
IDLE = "idle"
TAKEOFF = "takeoff"
FLYING = "flying"
LANDING = "landing"


class Navigator:
    """Arming, take-off, landing and targets, for one vehicle. Owner of ``armed`` and ``landed_state``."""

    def __init__(self, vehicle: VehicleApi) -> None:
        self.v = vehicle
        p = vehicle.params
        p.define("LAND_SPEED", 50.0, 30.0, 200.0, doc="descent speed of the final landing stage (cm/s)")
        p.define("WPNAV_SPEED", 500.0, 20.0, 2000.0, doc="horizontal speed of position targets (cm/s)")
        p.define("WPNAV_SPEED_UP", 250.0, 10.0, 1000.0, doc="climb speed (cm/s)")
        p.define("WPNAV_SPEED_DN", 150.0, 10.0, 500.0, doc="descent speed (cm/s)")
        p.define("DISARM_DELAY", 10.0, 0.0, 127.0, kind="int", doc="auto-disarm on the ground after (s)")
        self.armed = False
        self.spooled = False  # motors under full control (after take-off starts)
        self.landed_state = LANDED_ON_GROUND
        self.action = IDLE
        self.takeoff_alt = 0.0
        self.home_locked = False  # set by MAV_CMD_DO_SET_HOME (``ahrs.lock_home``)
        self._land_timer = 0.0
        self._idle_timer = 0.0
        self._listeners: list[Callable[[str], None]] = []
        self.prearm_checks: list[Callable[[], str | None]] = []
        """More pre-arm checks (each returns its failure text or None), e.g. the fence's."""

    def on_event(self, callback: Callable[[str], None]) -> None:
        """``callback(text)`` on arming, take-off complete, landed, disarmed (the endpoint announces them)."""
        self._listeners.append(callback)

    def _emit(self, text: str) -> None:
        log.info(text)
        for cb in self._listeners:
            cb(text)

    # --- arming ------------------------------------------------------------------------------------
    def prearm_failures(self) -> list[str]:
        v = self.v
        failures = []
        if not v.estimator.healthy:
            failures.append("EKF not ready")
        if v.gps.is_gps and v.gps.fix_type < 3:
            failures.append("GPS: no 3D fix")
        if v.battery.remaining_pct < 5:
            failures.append("Battery below minimum")
        failures += [why for check in self.prearm_checks if (why := check())]
        return failures

    def arm(self, force: bool = False) -> tuple[bool, str]:
        if self.armed:
            return True, "already armed"
        if not force:
            failures = self.prearm_failures()
            if failures:
                return False, "PreArm: " + failures[0]
        self.armed = True
        self.spooled = False
        self._idle_timer = 0.0
        self.v.control.reset()
        self.v.guidance_reset_here()
        # ArduCopter (AP_Arming_Copter::arm): home is set again where the vehicle is armed, unless a
        # ground station locked it (MAV_CMD_DO_SET_HOME sets it locked)
        if self.v.estimator.healthy and not self.home_locked:
            lat, lon, alt = self.v.state.position_geodetic
            self.v.home = (float(lat), float(lon), float(alt))
        self._emit("Arming motors")
        return True, ""

    def disarm(self, force: bool = False) -> tuple[bool, str]:
        if not self.armed:
            return True, "already disarmed"
        if self.landed_state not in (LANDED_ON_GROUND, LANDED_UNDEFINED) and not force:
            return False, "Disarm denied: vehicle is flying"
        self.armed = False
        self.spooled = False
        self.action = IDLE
        # ArduCopter (Copter::update_land_detector): disarmed is landed, wherever it is
        self.landed_state = LANDED_ON_GROUND
        self.v.control.reset()
        self._emit("Disarming motors")
        return True, ""

    # --- actions -------------------------------------------------------------------------------------
    def takeoff(self, alt_m: float) -> tuple[bool, str]:
        """Climb to ``alt_m`` metres above home from the ground (or from the air: a climb)."""
        if not self.armed:
            return False, "Takeoff denied: not armed"
        if not (0.5 <= alt_m <= 1000.0) or not math.isfinite(alt_m):
            return False, f"Takeoff denied: altitude {alt_m:g} m out of range"
        g = self.v.guidance
        if self.landed_state == LANDED_ON_GROUND:
            self.v.guidance_reset_here()
            self.spooled = True
            self.landed_state = LANDED_TAKEOFF
            self.v.control.reset()
        n, e, _ = g.p
        self.takeoff_alt = alt_m
        g.set_position_target((n, e, -alt_m), speed=self.v.params.get("WPNAV_SPEED_UP") / 100.0)
        self.action = TAKEOFF
        return True, ""

    def land(self) -> tuple[bool, str]:
        if not self.armed:
            return False, "Land denied: not armed"
        if self.landed_state == LANDED_ON_GROUND:
            return True, "already landed"
        self.action = LANDING
        self.landed_state = LANDED_LANDING
        self._land_timer = 0.0
        g = self.v.guidance
        g.hold()
        g.set_velocity_target((0.0, 0.0, self._land_speed(-g.p[2])))
        return True, ""

    def _in_air_or_deny(self, what: str) -> tuple[bool, str]:
        if not self.armed:
            return False, f"{what} denied: not armed"
        if self.landed_state in (LANDED_ON_GROUND,):
            return False, f"{what} denied: on the ground (take off first)"
        return True, ""

    def goto(self, p_ned: tuple[float, float, float], speed: float | None = None) -> tuple[bool, str]:
        ok, why = self._in_air_or_deny("Goto")
        if ok:
            s = speed if speed is not None else self.v.params.get("WPNAV_SPEED") / 100.0
            self.v.guidance.set_position_target(tuple(p_ned), speed=s)
            self.action = FLYING
        return ok, why

    def velocity(self, v_ned: tuple[float, float, float]) -> tuple[bool, str]:
        ok, why = self._in_air_or_deny("Velocity")
        if ok:
            self.v.guidance.set_velocity_target(tuple(v_ned))
            self.action = FLYING
        return ok, why

    def acceleration(self, a_ned: tuple[float, float, float]) -> tuple[bool, str]:
        ok, why = self._in_air_or_deny("Acceleration")
        if ok:
            self.v.guidance.set_acceleration_target(tuple(a_ned))
            self.action = FLYING
        return ok, why

    def hold(self) -> tuple[bool, str]:
        ok, why = self._in_air_or_deny("Hold")
        if ok:
            self.v.guidance.hold()
            self.action = FLYING
        return ok, why

    def yaw(self, target_rad: float, rate: float | None = None) -> None:
        self.v.guidance.set_yaw_target(target_rad, rate)

    def yaw_rate(self, rate: float) -> None:
        self.v.guidance.set_yaw_rate_target(rate)

    # --- periodic (navigation group) -------------------------------------------------------------
    def _land_speed(self, alt_m: float) -> float:
        """ArduCopter descends fast high up and at LAND_SPEED in the last 10 m."""
        final = self.v.params.get("LAND_SPEED") / 100.0
        if alt_m > 10.0:
            return max(final, self.v.params.get("WPNAV_SPEED_DN") / 100.0)
        return final

    def periodic(self, dt: float) -> None:
        if not self.armed:
            self.landed_state = LANDED_ON_GROUND  # as ArduCopter's land detector: disarmed is landed
            return
        v = self.v
        g = v.guidance
        if self.action == TAKEOFF and g.at_target:
            self.landed_state = LANDED_IN_AIR
            self.action = FLYING
            self._emit(f"Takeoff complete at {self.takeoff_alt:.1f} m")
        elif self.landed_state == LANDED_TAKEOFF and self.action != TAKEOFF:
            # the take-off was superseded by another target (a GUIDED command, a mode change): as
            # ArduCopter's land detector, report IN_AIR once the vehicle has left the ground
            if -v.state_alt_estimate() > 0.5:
                self.landed_state = LANDED_IN_AIR
        elif self.action == LANDING:
            alt = -v.state_alt_estimate()
            g.set_velocity_target((0.0, 0.0, self._land_speed(alt)))
            # land detector (ArduCopter's): descent is commanded, yet the thrust has fallen far below
            # hover and the estimated descent rate is under 1 m/s, for 1 s. The altitude estimate is
            # not used: outdoors it can be off by a metre or more.
            vz = v.state.vector[5]
            thrust_frac = v.control.out[0] / (v.airframe.mass * 9.80665)
            if abs(vz) < 1.0 and thrust_frac < 0.6:
                self._land_timer += dt
            else:
                self._land_timer = 0.0
            if self._land_timer >= 1.0:
                self.landed_state = LANDED_ON_GROUND
                self.action = IDLE
                self.spooled = False
                self._emit("Landed")
                self.armed = False
                v.control.reset()
                self._emit("Disarming motors")
                v.guidance_reset_here()
        elif self.landed_state == LANDED_ON_GROUND and not self.spooled:
            delay = v.params.get("DISARM_DELAY")
            self._idle_timer += dt
            if delay > 0 and self._idle_timer >= delay:
                self.armed = False
                self._emit("Auto disarmed")
