"""Setpoint generation: from the channel targets P_t to a continuous, bounded reference P_d.

Seed 000 Sec. IV-D, Fig. 9. Every tick the running command turns its channels into targets
(:class:`ChannelTargets`); :class:`ReferenceGenerator.step` plans, from the *current reference* state
(p, v, a, yaw, yaw rate), jerk-limited trajectories to those targets with ruckig and samples them
one tick ahead. Because every plan starts from the current reference, switching targets (next
command, pause, break-in, reset, stop) never makes the reference jump.

How the channels are planned
    * Horizontal position (H_Pos, H_ExtPos, H_KeepDistance; 3-D with V_WithHor): in the *path
      frame*: a 1-D ruckig problem along the straight line from the reference to the target (speed,
      acceleration, jerk of the line; end speed at arrival) and a k-D problem across it that brings
      any sideways velocity back to the line. Starting at rest (or moving along the line) the path
      is exactly straight and the commanded speed is reached exactly; otherwise the reference bends
      smoothly onto the line. The along part is stretched (ruckig ``minimum_duration``) so that it
      never arrives before the across part.
    * Velocity channels (ExtVel, RCVel, DNU = come to rest and hold): ruckig's velocity interface;
      the two horizontal axes are time-synchronised (straight change of velocity) and each gets
      ``1/sqrt(2)`` of the acceleration and jerk, so the horizontal norm stays within the limits
      (braking to a hover along an axis therefore uses 71 % of the horizontal acceleration).
    * Vertical and heading: 1-D each. Yaw is planned unwrapped.
    * Speed modifiers (Fig. 7): a channel modified by another is given that channel's remaining
      duration as ruckig ``minimum_duration``: it slows down so that both arrive together.

A plan is kept and sampled tick after tick while its target is unchanged and the reference is still
on it (what ruckig's own ``update()`` does); it is recalculated when the target changes or the
reference left it (a channel switch, the guard below).

End flags are the generator's *arrival* flags: the tick whose planned trajectory ends within the
tick lands exactly on the target (position and end velocity), so "the setpoints arrive exactly at
the desired values" (Sec. IV-A1).

Bounds, guaranteed by a final guard on every step whatever the planner did (it only acts in rare
corner cases, e.g. curving while braking): with ``dt`` the tick interval, ``|v_h| <= v_h,max``,
``|dv_h| <= a_h,max*dt``, ``|dp_h| <= v_h,max*dt`` (horizontal norms) and the same for the vertical
axis and the yaw (``|dyaw| <= yaw_rate*dt``). The envelope (p_env) bounds the targets: position
targets outside are moved to the nearest point inside (``target_unreachable``), velocity targets are
slowed so that the reference can stop before the boundary (``limit_reached``), and a reference that
would still cross the boundary is held on it.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, replace

import numpy as np

from .limits import Envelope, Limits
from .planner import (
    Array,
    PathFrame,
    Planner,
    clamp_norm,
    close_to,
    perp_basis,
    plan_key,
    stopping_speed,
    unit,
)
from .setpoint import Vec3

log = logging.getLogger(__name__)

_EPS = 1e-9
_SQRT1_2 = math.sqrt(0.5)


def wrap_pi(angle: float) -> float:
    """Wrap an angle to (-pi, pi]."""
    a = math.fmod(angle + math.pi, 2.0 * math.pi)
    if a <= 0.0:
        a += 2.0 * math.pi
    return a - math.pi


@dataclass(frozen=True)
class Reference:
    """The reference state P_d at time ``t_s``. ``yaw`` is unwrapped (continuous), radians."""

    t_s: float
    p: Vec3
    v: Vec3
    a: Vec3
    yaw: float
    yaw_rate: float = 0.0
    yaw_acc: float = 0.0

    @property
    def altitude(self) -> float:
        return -self.p[2]


# --- targets P_t ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class PathTarget:
    """Fly the straight line to ``position`` (NE, or NED with V_WithHor) and arrive with ``end_velocity``.

    ``speed`` is the horizontal speed along the line (the vertical part follows; with a 3-D target
    the line slows down when the vertical limit binds).
    """

    position: tuple[float, ...]
    speed: float
    end_velocity: tuple[float, ...] | None = None


@dataclass(frozen=True)
class VelocityTarget:
    """Track ``velocity`` (NE for the horizontal channel, (down,) for the vertical one)."""

    velocity: tuple[float, ...]


@dataclass(frozen=True)
class AxisTarget:
    """Vertical position target: ``down`` (m), ``speed`` (m/s), ``end_velocity`` (down, m/s)."""

    down: float
    speed: float
    end_velocity: float = 0.0


@dataclass(frozen=True)
class YawTarget:
    """Heading target ``yaw`` (unwrapped radians: the side it is on decides the direction), ``rate`` > 0."""

    yaw: float
    rate: float


@dataclass(frozen=True)
class YawRateTarget:
    """Yaw with ``rate`` (rad/s, signed)."""

    rate: float


@dataclass(frozen=True)
class ChannelTargets:
    """P_t of one tick. ``vertical`` is None when ``horizontal`` is a 3-D :class:`PathTarget`."""

    horizontal: PathTarget | VelocityTarget
    vertical: AxisTarget | VelocityTarget | None
    heading: YawTarget | YawRateTarget
    h_sync_vertical: bool = False
    h_sync_heading: bool = False
    v_sync_heading: bool = False
    floor_exempt: bool = False


HOLD = ChannelTargets(VelocityTarget((0.0, 0.0)), VelocityTarget((0.0,)), YawRateTarget(0.0))


@dataclass(frozen=True)
class StepResult:
    """One step: the new reference, the channels' arrival flags and the envelope flags."""

    reference: Reference
    h_arrived: bool = False
    v_arrived: bool = False
    hd_arrived: bool = False
    limit_reached: bool = False
    target_unreachable: bool = False


class ReferenceGenerator:
    """Turns :class:`ChannelTargets` into the next :class:`Reference` (see module docstring)."""

    def __init__(self, limits: Limits, envelope: Envelope | None = None) -> None:
        self.limits = limits
        self.envelope = envelope or Envelope()
        self._along = Planner(1)
        self._cross2 = Planner(1)
        self._cross3 = Planner(2)
        self._hvel = Planner(2)
        self._vert = Planner(1)
        self._yaw = Planner(1)
        self._frame: PathFrame | None = None
        #: How often the final guard had to correct the planned step (diagnostics).
        self.guard_interventions = 0

    # --- public ------------------------------------------------------------------------------------
    def initial(self, t_s: float, p: Vec3, v: Vec3, yaw: float) -> Reference:
        """A reference at a measured state (start, or after an override): velocity within limits."""
        # plain floats, not numpy: an idle companion's queue calls this at every tick (the reference
        # follows the vehicle), and numpy on 2-vectors costs ~10x the arithmetic
        L = self.limits
        vn, ve = float(v[0]), float(v[1])
        speed = math.hypot(vn, ve)
        if speed > L.horizontal_speed:
            scale = L.horizontal_speed / speed
            vn, ve = vn * scale, ve * scale
        vd = min(max(float(v[2]), -L.vertical_speed), L.vertical_speed)
        return Reference(t_s, (float(p[0]), float(p[1]), float(p[2])), (vn, ve, vd),
                         (0.0, 0.0, 0.0), float(yaw), 0.0, 0.0)

    def step(self, ref: Reference, targets: ChannelTargets, dt: float) -> StepResult:
        """Advance the reference by ``dt`` seconds towards ``targets``."""
        if dt <= 0:
            return StepResult(ref)
        targets, limit_reached, unreachable = self._apply_envelope(ref, targets)
        p0, v0, a0 = np.array(ref.p), np.array(ref.v), np.array(ref.a)

        # heading first: its duration may slow the others (Hd_sm)
        yaw, yaw_rate, yaw_acc, t_hd, hd_arrived = self._step_heading(ref, targets.heading, dt)
        # vertical (unless part of a 3-D path)
        t_v = 0.0
        v_arrived = False
        pd = vd = ad = 0.0
        if targets.vertical is not None:
            v_goal = t_hd if (targets.v_sync_heading and isinstance(targets.heading, YawTarget)) else 0.0
            pd, vd, ad, t_v, v_arrived = self._step_vertical(p0[2], v0[2], a0[2], targets.vertical, dt,
                                                             v_goal)
        # horizontal
        t_mod = 0.0
        if targets.h_sync_vertical and isinstance(targets.vertical, AxisTarget):
            t_mod = max(t_mod, t_v)
        if targets.h_sync_heading and isinstance(targets.heading, YawTarget):
            t_mod = max(t_mod, t_hd)
        h = targets.horizontal
        if isinstance(h, PathTarget):
            k = len(h.position)
            ph, vh, ah, h_arrived = self._step_path(p0[:k], v0[:k], a0[:k], h, dt, t_mod)
            if k == 3:
                pd, vd, ad = ph[2], vh[2], ah[2]
                v_arrived = h_arrived
                ph, vh, ah = ph[:2], vh[:2], ah[:2]
        else:
            ph, vh, ah = self._step_hvel(p0[:2], v0[:2], a0[:2], np.array(h.velocity, dtype=float), dt)
            h_arrived = False
        p1 = np.array([ph[0], ph[1], pd])
        v1 = np.array([vh[0], vh[1], vd])
        a1 = np.array([ah[0], ah[1], ad])
        p1, held = self._hold_inside(p0, p1, targets.floor_exempt)
        pg, vg, ag, yaw, yaw_rate, moved, turned = self._guard(ref, p1, v1, a1, yaw, yaw_rate, dt)
        if moved or held:  # not where the plan arrived: let the next tick replan and arrive
            h_arrived = v_arrived = False
        if turned:
            hd_arrived = False
        new = Reference(ref.t_s + dt, pg, vg, ag, yaw, yaw_rate, yaw_acc)
        return StepResult(new, h_arrived, v_arrived, hd_arrived, limit_reached or held, unreachable)

    # --- envelope -------------------------------------------------------------------------------------
    def _apply_envelope(self, ref: Reference, t: ChannelTargets) -> tuple[ChannelTargets, bool, bool]:
        env, L = self.envelope, self.limits
        limited = unreachable = False
        h, vert = t.horizontal, t.vertical
        if isinstance(h, PathTarget):
            pos = np.array(h.position, dtype=float)
            ne, moved = env.clamp_ne(pos[:2])
            if len(pos) == 3:
                alt, moved_v = env.clamp_altitude(-pos[2], floor_exempt=t.floor_exempt)
                moved = moved or moved_v
                new_pos: tuple[float, ...] = (float(ne[0]), float(ne[1]), -alt)
            else:
                new_pos = (float(ne[0]), float(ne[1]))
            if moved:
                limited = unreachable = True
                h = PathTarget(new_pos, h.speed, None)  # arrive at rest on the boundary
        elif env.bounded_horizontally:
            v = np.array(h.velocity, dtype=float)
            reach = L.horizontal_speed ** 2 / L.horizontal_acceleration + 2.0
            for normal, dist in env.boundary_constraints(np.array(ref.p[:2]), reach):
                allow = stopping_speed(dist, L.horizontal_acceleration, L.horizontal_jerk)
                comp = float(v @ normal)
                if comp > allow:
                    v = v - (comp - allow) * normal
                    limited = True
            h = VelocityTarget((float(v[0]), float(v[1])))
        if isinstance(vert, AxisTarget):
            alt, moved = env.clamp_altitude(-vert.down, floor_exempt=t.floor_exempt)
            if moved:
                limited = unreachable = True
                vert = AxisTarget(-alt, vert.speed, 0.0)
        elif isinstance(vert, VelocityTarget):
            vdown = vert.velocity[0]
            alt = ref.altitude
            floor = None if t.floor_exempt else env.altitude_floor
            if env.altitude_ceiling is not None and vdown < 0 and alt <= env.altitude_ceiling:
                allow = stopping_speed(env.altitude_ceiling - alt, L.vertical_acceleration, L.vertical_jerk)
                if -vdown > allow:
                    vdown, limited = -allow, True
            if floor is not None and vdown > 0 and alt >= floor:
                allow = stopping_speed(alt - floor, L.vertical_acceleration, L.vertical_jerk)
                if vdown > allow:
                    vdown, limited = allow, True
            vert = VelocityTarget((vdown,))
        if h is not t.horizontal or vert is not t.vertical:
            t = replace(t, horizontal=h, vertical=vert)
        return t, limited, unreachable

    def _hold_inside(self, p0: np.ndarray, p1: np.ndarray, floor_exempt: bool) -> tuple[np.ndarray, bool]:
        """Keep a reference that was inside from crossing the boundary (last resort)."""
        env = self.envelope
        held = False
        if env.bounded_horizontally and env.contains_ne(p0[:2]) and not env.contains_ne(p1[:2]):
            ne, _ = env.clamp_ne(p1[:2])
            p1 = np.array([ne[0], ne[1], p1[2]])
            held = True
        alt0, alt1 = -p0[2], -p1[2]
        ceiling = env.altitude_ceiling
        floor = None if floor_exempt else env.altitude_floor
        if ceiling is not None and alt1 > ceiling and alt1 > alt0:
            p1[2] = -max(ceiling, alt0)
            held = True
        if floor is not None and alt1 < floor and alt1 < alt0:
            p1[2] = -min(floor, alt0)
            held = True
        return p1, held

    # --- channels -------------------------------------------------------------------------------------
    def _step_heading(self, ref: Reference, t: YawTarget | YawRateTarget, dt: float
                      ) -> tuple[float, float, float, float, bool]:
        """Returns yaw, rate, acceleration, remaining duration (before this step), arrived."""
        L = self.limits
        pl = self._yaw
        cur = (np.array([ref.yaw]), np.array([ref.yaw_rate]), np.array([ref.yaw_acc]))
        lim_a = np.array([L.yaw_acceleration_rad])
        lim_j = np.array([L.yaw_jerk_rad])
        if isinstance(t, YawTarget):
            rate = min(abs(t.rate), L.yaw_rate_rad)
            key = plan_key(0, t.yaw, rate)
            if pl.reusable(key, *cur, key_tol=1e-6) or pl.plan(*cur, np.array([t.yaw]), np.zeros(1),
                                                                np.array([rate]), lim_a, lim_j, key=key):
                remaining = pl.remaining
                if remaining <= dt:
                    pl.advance(dt)
                    return t.yaw, 0.0, 0.0, remaining, True
                y, r, acc = pl.advance(dt)
                return float(y[0]), float(r[0]), float(acc[0]), remaining, False
        else:
            rate = float(np.clip(t.rate, -L.yaw_rate_rad, L.yaw_rate_rad))
            key = plan_key(1, rate)
            if pl.reusable(key, *cur) or pl.plan(*cur, None, np.array([rate]), np.array([L.yaw_rate_rad]),
                                                 lim_a, lim_j, key=key):
                y, r, acc = pl.advance(dt)
                return float(y[0]), float(r[0]), float(acc[0]), 0.0, False
        pl.invalidate()
        rate0 = ref.yaw_rate  # no plan: brake the yaw rate
        dr = -math.copysign(min(abs(rate0), L.yaw_acceleration_rad * dt), rate0)
        return ref.yaw + (rate0 + 0.5 * dr) * dt, rate0 + dr, dr / dt, 0.0, False

    def _step_vertical(self, p: float, v: float, a: float, t: AxisTarget | VelocityTarget, dt: float,
                       goal: float) -> tuple[float, float, float, float, bool]:
        """Returns down, velocity, acceleration, remaining duration (before this step), arrived."""
        L = self.limits
        pl = self._vert
        lim_a = np.array([L.vertical_acceleration])
        lim_j = np.array([L.vertical_jerk])
        cur = (np.array([p]), np.array([v]), np.array([a]))
        if isinstance(t, AxisTarget):
            speed = min(t.speed, L.vertical_speed)
            end_v = float(np.clip(t.end_velocity, -speed, speed))
            key = plan_key(0, t.down, end_v, speed)
            if pl.reusable(key, *cur, goal=goal) or pl.plan(*cur, np.array([t.down]), np.array([end_v]),
                                                            np.array([speed]), lim_a, lim_j, goal, key):
                remaining = pl.remaining
                if remaining <= dt:
                    pl.advance(dt)
                    return t.down, end_v, 0.0, remaining, True
                pp, vv, aa = pl.advance(dt)
                return float(pp[0]), float(vv[0]), float(aa[0]), remaining, False
        else:
            target_v = float(np.clip(t.velocity[0], -L.vertical_speed, L.vertical_speed))
            key = plan_key(1, target_v)
            if pl.reusable(key, *cur) or pl.plan(*cur, None, np.array([target_v]),
                                                 np.array([L.vertical_speed]), lim_a, lim_j, key=key):
                pp, vv, aa = pl.advance(dt)
                return float(pp[0]), float(vv[0]), float(aa[0]), 0.0, False
        pl.invalidate()
        dv = -math.copysign(min(abs(v), L.vertical_acceleration * dt), v)
        return p + (v + 0.5 * dv) * dt, v + dv, dv / dt, 0.0, False

    def _step_hvel(self, p: Array, v: Array, a: Array, target_v: Array, dt: float
                   ) -> tuple[Array, Array, Array]:
        """Horizontal velocity target: both axes time-synchronised (a straight change of velocity),
        each with ``1/sqrt(2)`` of the acceleration and jerk, so that their norm never exceeds the
        limits whatever the direction of the previous change was (a joystick changes it every tick)."""
        L = self.limits
        pl = self._hvel
        target_v, _ = clamp_norm(target_v, L.horizontal_speed)
        key = plan_key(target_v)
        if pl.reusable(key, p, v, a) or pl.plan(p, v, a, None, target_v, np.full(2, L.horizontal_speed),
                                                np.full(2, L.horizontal_acceleration * _SQRT1_2),
                                                np.full(2, L.horizontal_jerk * _SQRT1_2), key=key):
            return pl.advance(dt)
        return self._brake_path(p, v, dt)

    def _step_path(self, p: Array, v: Array, a: Array, t: PathTarget, dt: float,
                   goal: float) -> tuple[Array, Array, Array, bool]:
        """Along-the-line plus across-the-line planning (see module docstring)."""
        L = self.limits
        k = p.shape[0]
        m = k - 1
        along, cross = self._along, (self._cross2 if k == 2 else self._cross3)
        target = np.array(t.position, dtype=float)
        end_v = np.array(t.end_velocity, dtype=float) if t.end_velocity is not None else np.zeros(k)
        speed = min(t.speed, L.horizontal_speed)
        key = plan_key(k, target, end_v, speed)
        frame = self._frame
        reuse = (frame is not None and frame.dims == k and frame.key.shape == key.shape
                 and close_to(frame.key, key, 1e-9) and along.ok
                 and along.reusable(key, *frame.along_state(p, v, a),
                                  goal=max(goal, cross.remaining if frame.cross_active else 0.0))
                 and (not frame.cross_active or cross.on_track(*frame.cross_state(p, v, a))))
        if frame is None or not reuse:
            frame = self._plan_path(p, v, a, target, end_v, speed, goal, key)
            if frame is None:
                self._frame = None
                return (*self._brake_path(p, v, dt), False)
            self._frame = frame
        remaining = max(along.remaining, cross.remaining if frame.cross_active else 0.0)
        if remaining <= dt:
            along.advance(dt)
            if frame.cross_active:
                cross.advance(dt)
            return target, end_v, np.zeros(k), True
        s, vs, as_ = along.advance(dt)
        c, vc, ac = cross.advance(dt) if frame.cross_active else (np.zeros(m), np.zeros(m), np.zeros(m))
        p1 = target + s[0] * frame.u + sum(c[i] * frame.basis[i] for i in range(m))
        v1 = vs[0] * frame.u + sum(vc[i] * frame.basis[i] for i in range(m))
        a1 = as_[0] * frame.u + sum(ac[i] * frame.basis[i] for i in range(m))
        return p1, v1, a1, False

    def _plan_path(self, p: Array, v: Array, a: Array, target: Array, end_v: Array, speed: float, goal: float,
                   key: Array) -> PathFrame | None:
        L = self.limits
        k = p.shape[0]
        m = k - 1
        along, cross = self._along, (self._cross2 if k == 2 else self._cross3)
        u, dist = unit(target - p)
        if dist <= _EPS:
            u, n = unit(end_v)
            if n <= _EPS:
                u, n = unit(v)
            if n <= _EPS:
                u = np.eye(k)[0]
        frame = PathFrame(k, u, perp_basis(u), target, key)
        uh = float(np.linalg.norm(u[:2]))
        uv = abs(float(u[2])) if k == 3 else 0.0

        def along_limit(h_lim: float, v_lim: float) -> float:
            lim = math.inf
            if uh > 1e-6:
                lim = min(lim, h_lim / uh)
            if uv > 1e-6:
                lim = min(lim, v_lim / uv)
            return lim if math.isfinite(lim) else h_lim

        s_vmax = along_limit(speed, L.vertical_speed)
        s_amax = along_limit(L.horizontal_acceleration, L.vertical_acceleration)
        s_jmax = along_limit(L.horizontal_jerk, L.vertical_jerk)
        ha, va = L.horizontal_acceleration, L.vertical_acceleration
        c_amax = ha if k == 2 else min(ha, va)
        c_jmax = L.horizontal_jerk if k == 2 else min(L.horizontal_jerk, L.vertical_jerk)
        c_vmax = 0.5 * (min(speed, L.vertical_speed) if k == 3 else speed)
        s0, vs0, as0 = frame.along_state(p, v, a)
        c0, vc0, ac0 = frame.cross_state(p, v, a)
        end_s = float(np.clip(end_v @ u, -s_vmax, s_vmax))
        end_c = np.array([end_v @ n for n in frame.basis])
        frame.cross_active = bool(np.any(np.abs(vc0) > 1e-6) or np.any(np.abs(ac0) > 1e-6)
                                  or np.any(np.abs(end_c) > 1e-6))
        alpha, beta = (0.8, 0.6) if frame.cross_active else (1.0, 0.6)
        if frame.cross_active:  # the cross part is never stretched; the along part waits for it instead
            c_vmax = max(c_vmax, float(np.max(np.abs(end_c))) + 1e-6)
            if not cross.plan(c0, vc0, ac0, np.zeros(m), end_c, np.full(m, c_vmax), np.full(m, beta * c_amax),
                              np.full(m, beta * c_jmax), key=key):
                return None
            frame.t_cross = cross.duration
        if not along.plan(s0, vs0, as0, np.zeros(1), np.array([end_s]), np.array([s_vmax]),
                          np.array([alpha * s_amax]), np.array([alpha * s_jmax]), max(goal, frame.t_cross),
                          key):
            return None
        return frame

    def _brake_path(self, p: Array, v: Array, dt: float) -> tuple[Array, Array, Array]:
        log.warning("planning failed; braking")
        L = self.limits
        dv, _ = clamp_norm(-v, min(L.horizontal_acceleration, L.vertical_acceleration) * dt)
        return p + (v + 0.5 * dv) * dt, v + dv, dv / dt

    # --- the guard --------------------------------------------------------------------------------------
    def _guard(self, ref: Reference, p1: Array, v1: Array, a1: Array, yaw: float,
               yaw_rate: float, dt: float) -> tuple[Vec3, Vec3, Vec3, float, float, bool, bool]:
        """Enforce the step bounds of the module docstring, whatever the planner proposed."""
        L = self.limits
        (p0n, p0e, p0d), (v0n, v0e, v0d) = ref.p, ref.v
        pn, pe, pd = (float(x) for x in p1)
        vn, ve, vd = (float(x) for x in v1)
        an, ae, ad = (float(x) for x in a1)
        # velocities: within the speed limits, and within a_max*dt of the previous ones
        vn2, ve2 = _clamp2(vn, ve, L.horizontal_speed)
        dvn, dve = _clamp2(vn2 - v0n, ve2 - v0e, L.horizontal_acceleration * dt)
        vd2 = _clip(vd, L.vertical_speed)
        dvd = _clip(vd2 - v0d, L.vertical_acceleration * dt)
        v_new = (v0n + dvn, v0e + dve, v0d + dvd)
        # positions: within v_max*dt of the previous ones
        dpn, dpe = _clamp2(pn - p0n, pe - p0e, L.horizontal_speed * dt)
        dpd = _clip(pd - p0d, L.vertical_speed * dt)
        p_new = (p0n + dpn, p0e + dpe, p0d + dpd)
        # accelerations: within the limits
        an2, ae2 = _clamp2(an, ae, L.horizontal_acceleration)
        a_new = (an2, ae2, _clip(ad, L.vertical_acceleration))
        # yaw
        yaw_new = ref.yaw + _clip(yaw - ref.yaw, L.yaw_rate_rad * dt)
        rate_new = _clip(yaw_rate, L.yaw_rate_rad)
        moved = max(max(abs(x - y) for x, y in zip(v_new, (vn, ve, vd), strict=True)),
                    max(abs(x - y) for x, y in zip(p_new, (pn, pe, pd), strict=True)),
                    max(abs(x - y) for x, y in zip(a_new, (an, ae, ad), strict=True)))
        turned = max(abs(yaw_new - yaw), abs(rate_new - yaw_rate))
        if max(moved, turned) > 1e-9:
            self.guard_interventions += 1
            log.debug("guard corrected a step by %.3g (position) %.3g (yaw)", moved, turned)
        return p_new, v_new, a_new, yaw_new, rate_new, moved > 1e-9, turned > 1e-9


def _clamp2(x: float, y: float, limit: float) -> tuple[float, float]:
    n = math.hypot(x, y)
    if n > limit:
        k = limit / n
        return x * k, y * k
    return x, y


def _clip(x: float, limit: float) -> float:
    return limit if x > limit else (-limit if x < -limit else x)
