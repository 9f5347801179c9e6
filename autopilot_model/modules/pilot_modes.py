"""The pilot-driven modes: STABILIZE, ALT_HOLD, LOITER and POSHOLD flown from the RC sticks.

The sticks come from :class:`~autopilot_model.modules.rc_input.RcInput` (RC_CHANNELS_OVERRIDE,
MANUAL_CONTROL); each mode follows its ArduCopter counterpart (``mode_stabilize.cpp``,
``mode_althold.cpp``, ``mode_loiter.cpp`` with ``AC_Loiter``, ``mode_poshold.cpp``):

* lean angles (STABILIZE, ALT_HOLD, POSHOLD while a stick is out): roll and pitch sticks times
  ANGLE_MAX (LOITER: two thirds of it, ``AC_Loiter::get_angle_max_cd``). The model's cascade flies
  accelerations, so a lean angle is given to it as the horizontal acceleration ``g tan(angle)`` in
  the heading's frame, with no horizontal position or velocity feedback (:attr:`Vehicle.lean`);
* the yaw stick is a yaw rate, PILOT_Y_RATE at full stick;
* STABILIZE: the throttle stick is the collective through ArduCopter's throttle curve
  (``get_pilot_desired_throttle``: mid-stick is the hover throttle);
* ALT_HOLD, LOITER, POSHOLD: the throttle stick is a climb rate (``get_pilot_desired_climb_rate``):
  zero within THR_DZ of mid-stick, PILOT_SPEED_UP at full, PILOT_SPEED_DN (0: PILOT_SPEED_UP) at
  zero; on the ground, throttle above the dead band takes off (ArduCopter's pilot take-off);
* LOITER: the sticks are an acceleration request (``AC_Loiter::calc_desired_velocity``): the desired
  velocity integrates it against a drag that makes full stick LOIT_SPEED, and with the sticks centred
  it brakes at up to LOIT_BRK_ACCEL after LOIT_BRK_DELAY, then holds the position;
* POSHOLD: lean angles while a stick is out; sticks centred, it brakes (the setpoint generator's
  deceleration) and holds the position, as LOITER;
* a land detector for the pilot's descent (thrust far below hover, descent rate under 1 m/s, 1 s):
  landed, motors at ground idle, disarmed after DISARM_DELAY.

Until RC has been seen these modes keep the model's behavior without a pilot (level, holding still:
what centred sticks and mid throttle give in LOITER), so the companion's flights are unchanged.

The RC failsafe's action (``Copter::failsafe_radio_on_event``) is :meth:`PilotModes.radio_failsafe`.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from typing import TYPE_CHECKING

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from autopilot_model.modules import navigation as navmod
from autopilot_model.modules.guided_targets import sqrt_controller
from autopilot_model.modules.rc_input import PITCH, ROLL, YAW, RcInput
from taskflight_common.ardupilot import CopterMode

if TYPE_CHECKING:
    from autopilot_model.modules.flight_modes import FlightModes
    from autopilot_model.params import ParamStore

log = logging.getLogger(__name__)

GRAVITY = 9.80665
STABILIZE, ALT_HOLD, AUTO, GUIDED, LOITER, RTL, LAND, POSHOLD, BRAKE, SMART_RTL = (
    CopterMode.STABILIZE, CopterMode.ALT_HOLD, CopterMode.AUTO, CopterMode.GUIDED, CopterMode.LOITER,
    CopterMode.RTL, CopterMode.LAND, CopterMode.POSHOLD, CopterMode.BRAKE, CopterMode.SMART_RTL)
PILOT_MODES = frozenset({STABILIZE, ALT_HOLD, LOITER, POSHOLD})
#: FS_THR_ENABLE -> failsafe mode (4, 5: SmartRTL first, then this one; the model has no DO_LAND_START: 6 RTL)
_FS_THR_MODES = {1: RTL, 2: RTL, 3: LAND, 4: RTL, 5: LAND, 6: RTL, 7: BRAKE}
# FS_OPTIONS bits (Copter::FailsafeOption)
RC_CONTINUE_IF_AUTO = 1
RC_CONTINUE_IF_GUIDED = 4
CONTINUE_IF_LANDING = 8
LAND_DETECT_S = 1.0


def define_pilot_params(params: ParamStore) -> None:
    params.define("PILOT_SPEED_UP", 250.0, 50.0, 500.0, doc="pilot's maximum climb rate (cm/s)")
    params.define("PILOT_SPEED_DN", 0.0, 0.0, 500.0,
                  doc="pilot's maximum descent rate (cm/s), 0: PILOT_SPEED_UP")
    params.define("PILOT_Y_RATE", 202.5, 1.0, 500.0, doc="pilot's yaw rate at full stick (deg/s)")
    params.define("PILOT_TKOFF_ALT", 0.0, 0.0, 1000.0,
                  doc="pilot take-off altitude (cm), 0: climb on throttle")
    params.define("THR_DZ", 100, 0, 300, "int", "throttle dead band around mid-stick in ALT_HOLD, LOITER, "
                  "POSHOLD (0..1000 stick units)")
    params.define("LOIT_SPEED", 1250.0, 20.0, 3500.0, doc="LOITER: horizontal speed at full stick (cm/s)")
    params.define("LOIT_ACC_MAX", 500.0, 100.0, 981.0, doc="LOITER: maximum correction acceleration (cm/s^2)")
    params.define("LOIT_BRK_ACCEL", 250.0, 25.0, 250.0, doc="LOITER: braking acceleration (cm/s^2)")
    params.define("LOIT_BRK_JERK", 500.0, 500.0, 5000.0, doc="LOITER: braking jerk (cm/s^3)")
    params.define("LOIT_BRK_DELAY", 1.0, 0.0, 2.0, doc="LOITER: delay before braking when sticks centre (s)")
    params.define("LOIT_ANG_MAX", 0.0, 0.0, 45.0, doc="LOITER: maximum lean (deg), 0 = 2/3 of ANGLE_MAX")




class PilotModes:
    """Runs the pilot-driven modes of one vehicle (called from ``FlightModes.update``, 50 Hz)."""

    def __init__(self, modes: FlightModes, rc: RcInput) -> None:
        self.modes = modes
        self.v = modes.v
        self.rc = rc
        define_pilot_params(self.v.params)
        self._dt = 0.0  # the step of flight_modes.update in the schedule, given by update()
        self._land_timer = 0.0
        self._loiter_vel = (0.0, 0.0)
        self._brake_timer = 0.0
        self._brake_accel = 0.0
        self._poshold_braking = False
        self.announce: Callable[[int, str], None] | None = None  # STATUSTEXT, set by the wiring
        rc.on_failsafe.append(self.radio_failsafe)

    # --- stick read-outs ---------------------------------------------------------------------------
    def angle_max(self) -> float:
        return math.radians(self.v.params.get("ANGLE_MAX") / 100.0)

    def lean_angles(self, angle_max: float) -> tuple[float, float]:
        """(roll, pitch) in rad from the sticks, limited together to ``angle_max`` (a circle)."""
        r, p = self.rc.stick(ROLL), self.rc.stick(PITCH)
        n = math.hypot(r, p)
        if n > 1.0:
            r, p = r / n, p / n
        return r * angle_max, p * angle_max

    def climb_rate(self) -> float:
        """``get_pilot_desired_climb_rate``: m/s, positive up."""
        p = self.v.params
        thr = self.rc.throttle()
        dz = min(max(p.get("THR_DZ"), 0.0), 400.0)
        mid = 500.0
        up = p.get("PILOT_SPEED_UP") / 100.0
        dn = p.get("PILOT_SPEED_DN") / 100.0 or up
        if thr < mid - dz:
            return dn * (thr - (mid - dz)) / (mid - dz)
        if thr > mid + dz:
            return up * (thr - (mid + dz)) / (1000.0 - (mid + dz))
        return 0.0

    def hover_fraction(self) -> float:
        af = self.v.airframe
        return af.mass * GRAVITY / (4.0 * af.thrust_max)

    def throttle_out(self) -> float:
        """``get_pilot_desired_throttle``: the collective (fraction of full thrust) from the stick."""
        t = min(max(self.rc.throttle() / 1000.0, 0.0), 1.0)
        mid = self.hover_fraction()
        expo = min(max(-(mid - 0.5) / 0.375, -0.5), 1.0)
        return t * (1.0 - expo) + expo * t * t * t

    def yaw_rate(self) -> float:
        return self.rc.stick(YAW) * math.radians(self.v.params.get("PILOT_Y_RATE"))

    def _heading(self) -> float:
        return self.v.guidance.yaw

    def _lean_accel(self, angle_max: float) -> tuple[float, float]:
        """Horizontal acceleration (north, east; m/s^2) of the sticks' lean angles."""
        roll, pitch = self.lean_angles(angle_max)
        fwd = -GRAVITY * math.tan(pitch)
        right = GRAVITY * math.tan(roll) / max(math.cos(pitch), 0.1)
        c, s = math.cos(self._heading()), math.sin(self._heading())
        return fwd * c - right * s, fwd * s + right * c

    def sticks_centred(self) -> bool:
        return self.rc.stick(ROLL) == 0.0 and self.rc.stick(PITCH) == 0.0

    # --- arming checks (AP_Arming_Copter::arm_checks, RC part) ------------------------------------
    def arm_refusal(self, mode: int) -> str | None:
        """Why ArduCopter would refuse arming for the sticks (None: fine). Only once RC has been seen."""
        rc = self.rc
        if not rc.seen or (int(self.v.params.get("FS_THR_ENABLE")) == 0 and mode == GUIDED):
            return None
        if int(self.v.params.get("FS_THR_ENABLE")) and rc.radio_in[2] < self.v.params.get("FS_THR_VALUE"):
            return "PreArm: Throttle below failsafe"
        if rc.failsafe:
            return "PreArm: Radio failsafe on"
        if mode in (GUIDED, AUTO):
            return None  # GCS arming in GUIDED / AUTO skips the throttle checks
        if self.climb_rate() > 0.0 or (mode == STABILIZE and rc.throttle() > 0.0):
            return "Arm: Throttle too high"
        return None

    # --- entering modes ----------------------------------------------------------------------------
    def enter(self, mode: int) -> None:
        """Called on every mode change (after it happened)."""
        v = self.v
        self.v.lean = None
        self._loiter_vel = (float(v.guidance.v[0]), float(v.guidance.v[1]))
        self._brake_accel = 0.0
        self._brake_timer = 0.0
        self._poshold_braking = False
        self._land_timer = 0.0
        if mode in (STABILIZE, ALT_HOLD, POSHOLD):
            ctl = v.control
            ctl.integ[0] = ctl.integ[1] = 0.0
            if mode == STABILIZE:
                ctl.integ[2] = 0.0

    # --- the periodic step -------------------------------------------------------------------------
    def update(self, dt: float) -> None:
        self._dt = dt
        self.rc.periodic()
        mode = self.modes.mode
        v = self.v
        nav = v.nav
        if mode not in PILOT_MODES or not nav.armed or nav.action in (navmod.TAKEOFF, navmod.LANDING):
            v.lean = None
            return
        if not self.rc.seen:
            v.lean = None
            return  # no pilot: the model's hold (see the module docstring)
        if nav.landed_state == navmod.LANDED_ON_GROUND:
            self._on_ground(mode)
            return
        if mode == STABILIZE:
            self._stabilize()
        elif mode == ALT_HOLD:
            self._alt_hold()
        elif mode == LOITER:
            self._loiter()
        else:
            self._poshold()
        self._land_detector(mode)

    def _sync_guidance(self, vertical: bool) -> None:
        """While the sticks fly the vehicle, P_d follows the estimate horizontally (and vertically in
        STABILIZE), so that the next mode starts from where the vehicle is."""
        g = self.v.guidance
        e = self.v.state.vector
        if vertical:
            g.p = (float(e[0]), float(e[1]), float(e[2]))
            g.v = (float(e[3]), float(e[4]), float(e[5]))
            g.a = (0.0, 0.0, 0.0)
        else:
            g.p = (float(e[0]), float(e[1]), g.p[2])
            g.v = (float(e[3]), float(e[4]), g.v[2])
            g.a = (0.0, 0.0, g.a[2])

    def _vertical(self, climb: float, vn: float = 0.0, ve: float = 0.0) -> None:
        g = self.v.guidance
        if climb == 0.0 and vn == 0.0 and ve == 0.0:
            g.hold()
        else:
            g.set_velocity_target((vn, ve, -climb))
        g.set_yaw_rate_target(self.yaw_rate())

    def _stabilize(self) -> None:
        an, ae = self._lean_accel(self.angle_max())
        thrust = self.throttle_out() * 4.0 * self.v.airframe.thrust_max
        self.v.lean = (an, ae, GRAVITY - thrust / self.v.airframe.mass)
        self.v.guidance.set_yaw_rate_target(self.yaw_rate())
        self._sync_guidance(vertical=True)

    def _alt_hold(self) -> None:
        an, ae = self._lean_accel(self.angle_max())
        self._vertical(self.climb_rate())
        self.v.lean = (an, ae, None)
        self._sync_guidance(vertical=False)

    def _loiter_angle_max(self) -> float:
        a = self.v.params.get("LOIT_ANG_MAX")
        return math.radians(a) if a > 0 else self.angle_max() * 2.0 / 3.0

    def _loiter(self) -> None:
        """``AC_Loiter::calc_desired_velocity``, then the setpoint generator flies the velocity."""
        p = self.v.params
        dt = self._dt
        amax = self._loiter_angle_max()
        an, ae = self._lean_accel(amax)
        acc_max = p.get("LOIT_ACC_MAX") / 100.0
        a = math.hypot(an, ae)
        if a > acc_max:
            an, ae = an * acc_max / a, ae * acc_max / a
        vmax = max(p.get("LOIT_SPEED") / 100.0, 0.2)
        pilot_acc_max = GRAVITY * math.tan(amax)
        vn, ve = self._loiter_vel
        vn += an * dt
        ve += ae * dt
        speed = math.hypot(vn, ve)
        centred = an == 0.0 and ae == 0.0
        if speed > 0.0:
            drag = pilot_acc_max * speed / vmax
            brake = 0.0
            if centred:
                self._brake_timer += dt
                if self._brake_timer > p.get("LOIT_BRK_DELAY"):
                    brake = min(max(sqrt_controller(speed, 1.0, p.get("LOIT_BRK_JERK") / 100.0, dt), 0.0),
                                p.get("LOIT_BRK_ACCEL") / 100.0)
            else:
                self._brake_timer = 0.0
            jerk = p.get("LOIT_BRK_JERK") / 100.0 * dt
            self._brake_accel += min(max(brake - self._brake_accel, -jerk), jerk)
            new = max(speed - (drag + self._brake_accel) * dt, 0.0)
            vn, ve = vn / speed * new, ve / speed * new
            if new > vmax:
                vn, ve = vn * vmax / new, ve * vmax / new
        else:
            self._brake_accel = 0.0
        if centred and math.hypot(vn, ve) < 0.05:
            vn = ve = 0.0
        self._loiter_vel = (vn, ve)
        self._vertical(self.climb_rate(), vn, ve)
        self.v.lean = None

    def _poshold(self) -> None:
        climb = self.climb_rate()
        if not self.sticks_centred():
            self._poshold_braking = False
            an, ae = self._lean_accel(self.angle_max())
            self._vertical(climb)
            self.v.lean = (an, ae, None)
            self._sync_guidance(vertical=False)
            return
        if not self._poshold_braking:  # sticks just centred: P_d is at the vehicle, brake and hold
            self._poshold_braking = True
            self.v.lean = None
            self.v.guidance.hold()
        g = self.v.guidance
        if climb != 0.0:
            g.set_velocity_target((0.0, 0.0, -climb))
        else:
            g.hold()
        g.set_yaw_rate_target(self.yaw_rate())
        self.v.lean = None

    # --- take-off and landing ----------------------------------------------------------------------
    def _on_ground(self, mode: int) -> None:
        v = self.v
        nav = v.nav
        v.lean = None
        if mode == STABILIZE:
            out = self.throttle_out()
            if out > 0.0 and not nav.spooled:
                nav.spooled = True
                v.control.reset()
                v.guidance_reset_here()
            elif out <= 0.0 and nav.spooled:
                nav.spooled = False
            if nav.spooled:
                thrust = out * 4.0 * v.airframe.thrust_max
                v.lean = (0.0, 0.0, GRAVITY - thrust / v.airframe.mass)
                self._sync_guidance(vertical=True)
                if out > 0.5 * self.hover_fraction():
                    nav.landed_state = navmod.LANDED_IN_AIR  # ArduCopter: above the non-take-off throttle
                    nav.action = navmod.FLYING
            return
        climb = self.climb_rate()
        if climb > 0.0:  # the pilot's take-off (ArduCopter: throttle above the dead band)
            v.guidance_reset_here()
            nav.spooled = True
            nav.landed_state = navmod.LANDED_TAKEOFF
            nav.action = navmod.FLYING
            v.control.reset()
            self._loiter_vel = (0.0, 0.0)
            v.guidance.set_velocity_target((0.0, 0.0, -climb))
            self._land_timer = 0.0

    def _land_detector(self, mode: int) -> None:
        v = self.v
        nav = v.nav
        if mode == STABILIZE:
            descending = self.throttle_out() < self.hover_fraction()
        else:
            descending = self.climb_rate() < 0
        thrust_frac = v.control.out[0] / (v.airframe.mass * GRAVITY)
        if descending and thrust_frac < 0.5 and abs(v.state.vector[5]) < 1.0:
            self._land_timer += self._dt
        else:
            self._land_timer = 0.0
        if self._land_timer < LAND_DETECT_S:
            return
        self._land_timer = 0.0
        nav.landed_state = navmod.LANDED_ON_GROUND
        nav.action = navmod.IDLE
        nav.spooled = False
        nav._idle_timer = 0.0
        v.lean = None
        v.control.reset()
        v.guidance_reset_here()
        nav._emit("Landed")

    # --- RC failsafe action --------------------------------------------------------------------------
    def _say(self, severity: int, text: str) -> None:
        log.warning(text)
        if self.announce is not None:
            self.announce(severity, text)

    def should_disarm(self) -> bool:
        """``Copter::should_disarm_on_failsafe``."""
        nav = self.v.nav
        landed = nav.landed_state == navmod.LANDED_ON_GROUND
        if self.modes.mode == STABILIZE:
            return landed or self.rc.throttle() <= 0.0
        return landed

    def radio_failsafe(self, on: bool) -> None:
        """``Copter::failsafe_radio_on_event`` / ``_off_event``."""
        if not on:
            self._say(mavlink.MAV_SEVERITY_CRITICAL, "Radio Failsafe Cleared")
            return
        nav = self.v.nav
        if not nav.armed:
            self._say(mavlink.MAV_SEVERITY_CRITICAL, "Radio Failsafe")
            return
        params = self.v.params
        options = int(params.get("FS_OPTIONS"))
        mode = self.modes.mode
        action = _FS_THR_MODES.get(int(params.get("FS_THR_ENABLE")), LAND)
        if self.should_disarm():
            self._say(mavlink.MAV_SEVERITY_CRITICAL, "Radio Failsafe - Disarming")
            nav.disarm(force=True)
            return
        if mode == LAND and options & CONTINUE_IF_LANDING:
            self._say(mavlink.MAV_SEVERITY_CRITICAL, "Radio Failsafe - Continuing Landing")
            return
        if mode == AUTO and options & RC_CONTINUE_IF_AUTO:
            self._say(mavlink.MAV_SEVERITY_CRITICAL, "Radio Failsafe - Continuing Auto")
            return
        if mode == GUIDED and options & RC_CONTINUE_IF_GUIDED:
            self._say(mavlink.MAV_SEVERITY_CRITICAL, "Radio Failsafe - Continuing Guided Mode")
            return
        self._say(mavlink.MAV_SEVERITY_CRITICAL, "Radio Failsafe")
        if int(params.get("FS_THR_ENABLE")) in (4, 5) and self.modes.set_mode(SMART_RTL, "Radio Failsafe")[0]:
            return
        ok, _why = self.modes.set_mode(action, "Radio Failsafe")
        if not ok and action != LAND:
            self.modes.set_mode(LAND, "Radio Failsafe")
