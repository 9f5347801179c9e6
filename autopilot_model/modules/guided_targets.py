"""GUIDED targets of the flight modes: ArduCopter's ``ModeGuided`` target handling (:class:`GuidedTargets`)
and the kinematic shaping of ``AC_PosControl`` it uses (:func:`sqrt_controller`). Split from
:mod:`.flight_modes`, which re-exports these names.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from autopilot_model.modules import navigation as navmod

if TYPE_CHECKING:
    from autopilot_model.modules.flight_modes import FlightModes

log = logging.getLogger("autopilot_model.modules.flight_modes")

Vec3 = tuple[float, float, float]

# GUIDED sub-modes (what the last target asked for)
G_NONE = "none"
G_POS = "pos"
G_VEL = "vel"
G_ACCEL = "accel"
G_POSVEL = "posvel"


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
