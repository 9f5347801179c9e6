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
RTL          6   climb to RTL_ALT if lower, fly home, descend and land (RTL_ALT_FINAL = 0)
LAND         9   land where it is; stays in LAND after touchdown and disarm, as ArduCopter does
POSHOLD     16   as LOITER without a pilot; with one: lean angles, braking to a hold when sticks centre
BRAKE       17   stop as fast as the envelope allows and hold
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
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from autopilot_model.modules import navigation as navmod
from autopilot_model.modules.shared_params import define_rtl_alt
from taskflight.geo import geodetic_to_ned

if TYPE_CHECKING:
    from autopilot_model.vehicle import Vehicle

log = logging.getLogger(__name__)

STABILIZE = 0
ALT_HOLD = 2
AUTO = 3
GUIDED = 4
LOITER = 5
RTL = 6
LAND = 9
POSHOLD = 16
BRAKE = 17

MODE_NAMES: dict[int, str] = {STABILIZE: "STABILIZE", ALT_HOLD: "ALT_HOLD", AUTO: "AUTO", GUIDED: "GUIDED",
                              LOITER: "LOITER", RTL: "RTL", LAND: "LAND", POSHOLD: "POSHOLD",
                              BRAKE: "BRAKE"}
MODE_NUMBERS: dict[str, int] = {v: k for k, v in MODE_NAMES.items()}
#: Modes ArduCopter lets a ground station arm in (AUTO, RTL, LAND, BRAKE refuse arming).
ARMABLE = frozenset({STABILIZE, ALT_HOLD, GUIDED, LOITER, POSHOLD})
#: Modes in which a take-off command is accepted (ArduCopter: modes with a navigating user take-off).
TAKEOFF_MODES = frozenset({GUIDED, LOITER})
#: Modes in which MAV_CMD_DO_PAUSE_CONTINUE applies.
PAUSABLE = frozenset({AUTO, GUIDED, RTL})

ModeListener = Callable[[int, int, str], None]
Vec3 = tuple[float, float, float]

# GUIDED sub-modes (what the last target asked for)
G_NONE = "none"
G_POS = "pos"
G_VEL = "vel"
G_ACCEL = "accel"
G_POSVEL = "posvel"

# RTL stages
RTL_CLIMB = "climb"
RTL_RETURN = "return"
RTL_LAND = "land"


_home_cache: dict[int, tuple[Any, Vec3]] = {}


def home_ned(vehicle: Any) -> Vec3:
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


def define_mode_params(params: Any) -> None:
    params.define("GUID_TIMEOUT", 3.0, 0.1, 5.0,
                  doc="GUIDED: stop if no new velocity/acceleration target for this long (s)")
    define_rtl_alt(params)
    params.define("RTL_SPEED", 0.0, 0.0, 2000.0, doc="RTL: horizontal speed, 0 = WPNAV_SPEED (cm/s)")


@dataclass
class GuidedTarget:
    """One GUIDED target in the local NED frame of the vehicle (origin = EKF origin)."""

    pos: Vec3 | None = None
    vel: Vec3 | None = None
    acc: Vec3 | None = None
    yaw: float | None = None
    yaw_rate: float | None = None


#: ArduCopter's jerk limit of the position controller's kinematic shaping (PSC_JERK_XY / PSC_JERK_Z
#: default, m/s^3). With the acceleration limit A it sets the shaping gains of ``shape_pos_vel_accel``:
#: ``KPa = jerk / A`` (velocity error -> acceleration) and ``KPv = KPa / 2`` (position error -> velocity,
#: decelerating at ``A / 2``).
PSC_JERK = 5.0
#: Below this speed (m/s) and acceleration (m/s^2) a braking P_d counts as stopped and holds.
_STOPPED_V = 0.02
_STOPPED_A = 0.1


def sqrt_controller(error: float, p: float, second_ord_lim: float, dt: float) -> float:
    """ArduPilot's ``sqrt_controller`` (AP_Math/control.cpp): linear (gain ``p``) near zero, then the
    square root that decelerates at ``second_ord_lim``; never more than ``|error| / dt`` (no overshoot in
    one step)."""
    if second_ord_lim <= 0.0:
        rate = error * p
    elif p == 0.0:
        rate = math.copysign(math.sqrt(2.0 * second_ord_lim * abs(error)), error)
    else:
        linear_dist = second_ord_lim / (p * p)
        if error > linear_dist:
            rate = math.sqrt(2.0 * second_ord_lim * (error - linear_dist / 2.0))
        elif error < -linear_dist:
            rate = -math.sqrt(2.0 * second_ord_lim * (-error - linear_dist / 2.0))
        else:
            rate = error * p
    if dt > 0.0:
        lim = abs(error) / dt
        rate = max(-lim, min(lim, rate))
    return rate


def _toward(cur: float, target: float, step: float) -> float:
    return cur + max(-step, min(step, target - cur))


class GuidedTargets:
    """ArduCopter's ``ModeGuided`` target handling: the sub-mode, refresh time and timeout.

    Position + velocity (+ acceleration), ArduCopter's PosVelAccel sub-mode
    (``ModeGuided::set_destination_posvelaccel`` / ``posvelaccel_control_run``):

    * the target is a moving point: every run it is advanced with its feed-forward,
      ``p += v dt + a dt^2 / 2``, ``v += a dt`` (``AC_PosControl::input_pos_vel_accel_NE_cm`` / ``_U_cm``
      take the target by reference and move it in place with ``update_pos_vel_accel``), so a companion
      streaming p + v at 20 Hz gives a smooth target between its messages;
    * P_d follows it as ArduCopter's desired trajectory does (``shape_pos_vel_accel``): velocity = target
      velocity + ``sqrt_controller(position error, KPv, A / 2)`` (the correction capped at WPNAV_SPEED /
      DO_CHANGE_SPEED horizontally, WPNAV_SPEED_UP / _DN vertically), acceleration = target acceleration +
      ``sqrt_controller(velocity error, KPa, jerk)``, reached at most at the jerk limit (``shape_accel``).
      The result is given to the setpoint generator as an acceleration target at each run, so the
      envelope's speed, acceleration and position limits still bound P_d;
    * GUID_TIMEOUT after the last message the velocity and acceleration feed-forward are zeroed (and a yaw
      rate stops): the vehicle brakes, jerk-limited as ``shape_vel_accel`` to zero velocity, and holds
      where it stopped, a braking distance beyond the advanced target (ArduCopter's shaper would then
      settle back onto that frozen target; the model holds the stop point instead). It never flies back
      to the last position *sent*.

    Velocity and acceleration targets (VelAccel / Accel sub-modes) brake the same way after the timeout
    (``velaccel_control_run`` / ``accel_control_run`` zero the targets and shape to a stop).

    POSITION_TARGET_LOCAL_NED echoes the advanced target (``ModeGuided::get_target_pos`` / ``_vel`` /
    ``_accel``), see :meth:`echo`.
    """

    def __init__(self, modes: FlightModes) -> None:
        self.modes = modes
        self.v = modes.v
        self.kind = G_NONE
        self.last_update_s = 0.0
        self.target: GuidedTarget = GuidedTarget()
        self.timed_out = False
        # PosVelAccel: the moving target (advanced in place, as ArduCopter's guided_pos_target_cm)
        self.pva_pos: Vec3 = (0.0, 0.0, 0.0)
        self.pva_vel: Vec3 = (0.0, 0.0, 0.0)
        self.pva_acc: Vec3 = (0.0, 0.0, 0.0)
        self.braking = False  # shaping P_d to a stop after the timeout
        self._pva_t = 0.0  # sim time the moving target was last advanced to
        self._dt = 0.0  # period of the runs (s): the schedule's until measured on the clock
        self._last_run_s: float | None = None
        self._acc: Vec3 = (0.0, 0.0, 0.0)  # the shaped acceleration given to the generator

    def reset(self) -> None:
        self.kind = G_NONE
        self.target = GuidedTarget()
        self.timed_out = False
        self.braking = False

    def set(self, t: GuidedTarget) -> tuple[bool, str]:
        """Apply a target (already converted to local NED). Position with velocity: posvel; etc.

        Re-applying the current position + velocity target object (DO_CHANGE_SPEED does, to pick up a new
        speed) changes nothing: the moving target and its update time stay (ArduCopter's
        ``set_speed_xy`` only changes the limits)."""
        nav = self.v.nav
        now = self.v.clock.now()
        if t.pos is not None and t.vel is not None and t is self.target and self.kind == G_POSVEL:
            return True, ""
        fence = self.modes.fence
        if t.pos is not None and fence is not None and not fence.destination_ok(t.pos):
            return False, "Destination outside fence"  # ArduCopter: DEST_OUTSIDE_FENCE, target ignored
        if t.pos is not None and t.vel is None:
            ok, why = nav.goto(t.pos, self.modes.speed_h())
            kind = G_POS
        elif t.pos is not None and t.vel is not None:
            if self.kind != G_POSVEL or self.timed_out or self.braking:
                self._shaping_start()  # ArduCopter: posvelaccel_control_start()
            ok, why = nav.acceleration(self._acc)  # the in-air check; _shape() below replaces it
            if ok:
                self.pva_pos = (float(t.pos[0]), float(t.pos[1]), float(t.pos[2]))
                self.pva_vel = (float(t.vel[0]), float(t.vel[1]), float(t.vel[2]))
                self.pva_acc = (0.0, 0.0, 0.0) if t.acc is None else (float(t.acc[0]), float(t.acc[1]),
                                                                       float(t.acc[2]))
                self._pva_t = now
            kind = G_POSVEL
        elif t.vel is not None:
            ok, why = nav.velocity(t.vel)
            kind = G_VEL
        elif t.acc is not None:
            ok, why = nav.acceleration(t.acc)
            kind = G_ACCEL
        else:
            return False, "no target"
        if not ok:
            return ok, why
        if t.yaw is not None:
            nav.yaw(t.yaw, None)
        elif t.yaw_rate is not None:
            nav.yaw_rate(t.yaw_rate)
        self.kind = kind
        self.target = t
        self.timed_out = False
        self.braking = False
        self.last_update_s = now
        if kind == G_POSVEL:
            self._shape(self.pva_pos, self.pva_vel, self.pva_acc)
        return True, ""

    def stop(self) -> None:
        """ArduCopter's ``mode_guided.init(true)`` for invalid input: stop and hold here."""
        if self.v.nav.armed and self.v.nav.landed_state != navmod.LANDED_ON_GROUND:
            self.v.nav.hold()
        self.reset()

    def resume(self) -> None:
        """After DO_PAUSE_CONTINUE: ArduCopter's ``ModeGuided::resume`` only clears the pause and the
        sub-mode carries on (its target was not advanced while paused); a position target is flown to
        again. The pause held P_d (``pause_control_run``), so the shaping starts from rest."""
        if self.kind == G_POSVEL:
            self._pva_t = self.v.clock.now()
            self._shaping_start()
            if self.timed_out:
                self.braking = True
        elif self.target.pos is not None:
            self.set(self.target)

    def echo(self) -> tuple[Vec3 | None, Vec3 | None, Vec3 | None]:
        """Position, velocity and acceleration targets as ArduCopter reports them (local NED; None: not
        used by the sub-mode). PosVelAccel: the advanced target, zero feed-forward after the timeout, and
        once the vehicle has stopped after it, the point it holds."""
        t = self.target
        if self.kind != G_POSVEL:
            return t.pos, t.vel, t.acc
        pos = self.pva_pos
        if self.timed_out and not self.braking:
            held = self.v.guidance.target
            if held is not None:
                pos = held
        return pos, self.pva_vel, None if t.acc is None else self.pva_acc

    # --- ArduCopter's kinematic shaping (AC_PosControl, AP_Math/control.cpp) ------------------------
    def _shaping_start(self) -> None:
        """``init_NE_controller`` / ``init_U_controller``: the shaping continues from P_d's acceleration."""
        self._acc = tuple(float(x) for x in self.v.guidance.a)  # type: ignore[assignment]

    def _shape(self, pos: Vec3 | None, vel: Vec3, acc: Vec3) -> None:
        """One step of ``shape_pos_vel_accel`` (``pos`` None: ``shape_vel_accel``, no position
        correction): the acceleration P_d should have until the next run, jerk-limited, given to the
        setpoint generator as its acceleration target."""
        g = self.v.guidance
        env = g.envelope
        dt = self._dt
        jdt = PSC_JERK * dt
        pn, pe, pd = g.p
        vn, ve, vd = g.v
        an, ae, ad = self._acc
        ah, av = env.max_accel_h, env.max_accel_v
        tvn, tve, tvd = vel
        # horizontal (2-D, along the errors, as the _xy versions)
        if pos is not None:
            en, ee = pos[0] - pn, pos[1] - pe
            eh = math.hypot(en, ee)
            if eh > 0.0:
                c = min(sqrt_controller(eh, 0.5 * PSC_JERK / ah, 0.5 * ah, dt), self.modes.speed_h())
                tvn += en / eh * c
                tve += ee / eh * c
        en, ee = tvn - vn, tve - ve
        eh = math.hypot(en, ee)
        cn = ce = 0.0
        if eh > 0.0:
            c = min(sqrt_controller(eh, PSC_JERK / ah, PSC_JERK, dt), ah)
            cn, ce = en / eh * c, ee / eh * c
        cn += acc[0]
        ce += acc[1]
        dn, de = cn - an, ce - ae  # shape_accel_xy: at most jerk * dt
        dh = math.hypot(dn, de)
        k = jdt / dh if dh > jdt else 1.0
        an, ae = an + dn * k, ae + de * k
        # vertical (1-D; down positive)
        if pos is not None:
            params = self.v.params
            c = sqrt_controller(pos[2] - pd, 0.5 * PSC_JERK / av, 0.5 * av, dt)
            tvd += max(-params.get("WPNAV_SPEED_UP") / 100.0, min(params.get("WPNAV_SPEED_DN") / 100.0, c))
        c = max(-av, min(av, sqrt_controller(tvd - vd, PSC_JERK / av, PSC_JERK, dt)))
        ad = _toward(ad, c + acc[2], jdt)
        self._acc = (an, ae, ad)
        g.set_acceleration_target(self._acc)

    def _brake(self) -> None:
        """After the timeout: shape the velocity to zero, then hold where P_d stopped."""
        g = self.v.guidance
        if not self.modes.in_air():
            self.braking = False
            return
        vn, ve, vd = g.v
        an, ae, ad = self._acc
        if (vn * vn + ve * ve + vd * vd < _STOPPED_V ** 2
                and an * an + ae * ae + ad * ad < _STOPPED_A ** 2):
            self.braking = False
            self.v.nav.hold()
            return
        self._shape(None, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))

    def _pva_run(self) -> None:
        """One run of ``posvelaccel_control_run``: advance the moving target, shape P_d after it."""
        now = self.v.clock.now()
        dt = now - self._pva_t
        self._pva_t = now
        if dt > 0.0:
            (pn, pe, pd), (vn, ve, vd), (an, ae, ad) = self.pva_pos, self.pva_vel, self.pva_acc
            h = 0.5 * dt * dt
            self.pva_pos = (pn + vn * dt + an * h, pe + ve * dt + ae * h, pd + vd * dt + ad * h)
            self.pva_vel = (vn + an * dt, ve + ae * dt, vd + ad * dt)
        if self.modes.in_air():
            self._shape(self.pva_pos, self.pva_vel, self.pva_acc)

    def update(self) -> None:
        now = self.v.clock.now()
        if self._last_run_s is not None and 0.0 < now - self._last_run_s <= 0.1:
            self._dt = now - self._last_run_s
        elif self._dt <= 0.0:
            self._dt = self.v.step_of("flight_modes.update")
        self._last_run_s = now
        if self.braking:
            self._brake()
            return
        if self.kind not in (G_VEL, G_ACCEL, G_POSVEL) or self.timed_out:
            return
        if now - self.last_update_s <= self.v.params.get("GUID_TIMEOUT"):
            if self.kind == G_POSVEL:
                self._pva_run()
            return
        self.timed_out = True
        if self.kind == G_POSVEL:
            # zero the feed-forward; the target stops where it had been advanced to
            self.pva_vel = (0.0, 0.0, 0.0)
            self.pva_acc = (0.0, 0.0, 0.0)
        else:
            self._shaping_start()
        if self.target.yaw_rate is not None:
            self.v.nav.yaw_rate(0.0)
        log.info("GUIDED: target timed out, stopping")
        if self.modes.in_air():
            self.braking = True
            self._brake()


class FlightModes:
    """The ArduCopter mode machine of one vehicle; the only writer of ``mode``."""

    def __init__(self, vehicle: Vehicle) -> None:
        self.v = vehicle
        define_mode_params(vehicle.params)
        self.mode = STABILIZE
        self.mission_runner: Any = None  # set by the Sitl wiring (issue 3, missions)
        self.guided = GuidedTargets(self)
        self.paused = False
        self.speed_override_h: float | None = None  # DO_CHANGE_SPEED (m/s), until the next mode change
        self._rtl_stage = RTL_CLIMB
        self._listeners: list[ModeListener] = []
        self.pilot: Any = None  # the pilot-driven modes (pilot_modes.PilotModes), set by the Sitl wiring
        self.fence: Any = None  # the geofence (fence.Fence): GUIDED destinations outside it are refused

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
        result = runner.start()
        if isinstance(result, tuple):
            ok, why = result
            if not ok:
                return False, why
        elif result is False:
            return False, "Auto: mission cannot start"
        return True, ""

    # --- pause / continue (MAV_CMD_DO_PAUSE_CONTINUE) -----------------------------------------
    def pause(self) -> tuple[bool, str]:
        if self.mode not in PAUSABLE or not self.in_air():
            return False, f"Pause denied in {self.name}"
        self.paused = True
        self.v.nav.hold()
        return True, ""

    def resume(self) -> tuple[bool, str]:
        if not self.paused:
            return True, ""
        self.paused = False
        if self.mode == RTL:
            self._rtl_start()
        elif self.mode == AUTO and self.mission_runner is not None and hasattr(self.mission_runner, "resume"):
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
        if self._rtl_stage == RTL_CLIMB and alt_above_home < self._rtl_alt() - 0.5:
            nav.goto((n, e, hd - target_alt), self._rtl_speed())
        else:
            self._rtl_stage = RTL_RETURN
            nav.goto((hn, he, hd - target_alt), self._rtl_speed())

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
        if self.pilot is not None:
            self.pilot.update(self.v.step_of("flight_modes.update"))
        if mode == GUIDED:
            if not self.paused:
                self.guided.update()
        elif mode == RTL:
            self._rtl_update()
        elif mode == AUTO and not self.paused and self.mission_runner is not None:
            self.mission_runner.update()
