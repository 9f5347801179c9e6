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
      smoothly onto the line. Both parts arrive at the same time (ruckig ``minimum_duration``).
    * Velocity channels (ExtVel, RCVel, DNU = come to rest and hold): ruckig's velocity interface;
      the two horizontal axes are time-synchronised (straight change of velocity) and each gets
      ``1/sqrt(2)`` of the acceleration and jerk, so the horizontal norm stays within the limits.
    * Vertical and heading: 1-D each. Yaw is planned unwrapped.
    * Speed modifiers (Fig. 7): a channel modified by another is given that channel's remaining
      duration as ruckig ``minimum_duration``: it slows down so that both arrive together.

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
from ruckig import ControlInterface, InputParameter, Result, Ruckig, Synchronization, Trajectory

from .limits import Envelope, Limits
from .setpoint import Vec3

log = logging.getLogger(__name__)

_SQRT1_2 = math.sqrt(0.5)
_EPS = 1e-9


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


# --- ruckig wrapper ---------------------------------------------------------------------------------
class _Planner:
    """One ruckig problem of ``dofs`` degrees of freedom, planned from scratch each call (online)."""

    def __init__(self, dofs: int) -> None:
        self.dofs = dofs
        self._otg = Ruckig(dofs)
        self._inp = InputParameter(dofs)
        self._traj = Trajectory(dofs)
        self.duration = 0.0
        self.ok = False

    def plan(self, p: np.ndarray, v: np.ndarray, a: np.ndarray, target_p: np.ndarray | None,
             target_v: np.ndarray, vmax: np.ndarray, amax: np.ndarray, jmax: np.ndarray,
             min_duration: float | None = None) -> bool:
        """Plan to (target_p, target_v) or, with ``target_p`` None, to velocity ``target_v``."""
        inp = self._inp
        inp.control_interface = ControlInterface.Velocity if target_p is None else ControlInterface.Position
        inp.synchronization = Synchronization.Time
        inp.current_position = [float(x) for x in p]
        inp.current_velocity = [float(x) for x in v]
        inp.current_acceleration = [float(x) for x in a]
        inp.target_position = [float(x) for x in (target_p if target_p is not None else p)]
        inp.target_velocity = [float(x) for x in target_v]
        inp.target_acceleration = [0.0] * self.dofs
        inp.max_velocity = [max(float(x), 1e-6) for x in vmax]
        inp.max_acceleration = [max(float(x), 1e-6) for x in amax]
        inp.max_jerk = [max(float(x), 1e-6) for x in jmax]
        inp.minimum_duration = min_duration if min_duration and min_duration > 0 else None
        try:
            result = self._otg.calculate(inp, self._traj)
        except Exception as exc:  # ruckig raises on invalid input or unmapped error codes
            log.debug("ruckig failed (%s) for p=%s v=%s a=%s tp=%s tv=%s", exc, p, v, a, target_p, target_v)
            self.ok = False
            return False
        self.ok = result in (Result.Working, Result.Finished)
        self.duration = float(self._traj.duration) if self.ok else 0.0
        return self.ok

    def sample(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        p, v, a = self._traj.at_time(min(t, self.duration))
        p_arr, v_arr, a_arr = np.array(p), np.array(v), np.array(a)
        if t > self.duration:  # after the end the trajectory continues with its final velocity
            p_arr = p_arr + v_arr * (t - self.duration)
            a_arr = np.zeros(self.dofs)
        return p_arr, v_arr, a_arr


def _unit(x: np.ndarray) -> tuple[np.ndarray, float]:
    n = float(np.linalg.norm(x))
    return (x / n if n > _EPS else np.zeros_like(x)), n


def _clamp_norm(x: np.ndarray, limit: float) -> tuple[np.ndarray, bool]:
    n = float(np.linalg.norm(x))
    if n > limit:
        return x * (limit / n), True
    return x, False


def _perp_basis(u: np.ndarray) -> list[np.ndarray]:
    """Orthonormal vectors spanning the space perpendicular to unit vector ``u`` (2-D or 3-D)."""
    if u.shape[0] == 2:
        return [np.array([-u[1], u[0]])]
    helper = np.array([0.0, 0.0, 1.0]) if abs(u[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    n1, _ = _unit(np.cross(u, helper))
    n2 = np.cross(u, n1)
    return [n1, n2]


def stopping_speed(distance: float, accel: float, jerk: float) -> float:
    """Largest speed from which a jerk-limited stop (using half of ``accel``) fits in ``distance``."""
    a = 0.5 * accel
    d = max(0.0, distance - 0.1)
    k = a * a / jerk
    return -k + math.sqrt(k * k + 2.0 * a * d)


class ReferenceGenerator:
    """Turns :class:`ChannelTargets` into the next :class:`Reference` (see module docstring)."""

    def __init__(self, limits: Limits, envelope: Envelope | None = None) -> None:
        self.limits = limits
        self.envelope = envelope or Envelope()
        self._along = _Planner(1)
        self._cross2 = _Planner(1)
        self._cross3 = _Planner(2)
        self._hvel = _Planner(2)
        self._vert = _Planner(1)
        self._yaw = _Planner(1)
        self._brake3 = _Planner(3)
        #: How often the final guard had to correct the planned step (diagnostics).
        self.guard_interventions = 0

    # --- public ------------------------------------------------------------------------------------
    def initial(self, t_s: float, p: Vec3, v: Vec3, yaw: float) -> Reference:
        """A reference at a measured state (start, or after an override): velocity within limits."""
        L = self.limits
        vh, _ = _clamp_norm(np.array(v[:2], dtype=float), L.horizontal_speed)
        vd = float(np.clip(v[2], -L.vertical_speed, L.vertical_speed))
        return Reference(t_s, tuple(float(x) for x in p), (float(vh[0]), float(vh[1]), vd),  # type: ignore[arg-type]
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
            min_dur = t_hd if (targets.v_sync_heading and isinstance(targets.heading, YawTarget)) else None
            pd, vd, ad, t_v, v_arrived = self._step_vertical(p0[2], v0[2], a0[2], targets.vertical, dt, min_dur)
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
        p1, v1, a1, yaw, yaw_rate = self._guard(ref, p1, v1, a1, yaw, yaw_rate, dt)
        new = Reference(ref.t_s + dt, _t3(p1), _t3(v1), _t3(a1), yaw, yaw_rate, yaw_acc)
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
        L = self.limits
        pl = self._yaw
        y0 = np.array([ref.yaw])
        r0 = np.array([ref.yaw_rate])
        ya0 = np.array([ref.yaw_acc])
        lim_a = np.array([L.yaw_acceleration_rad])
        lim_j = np.array([L.yaw_jerk_rad])
        if isinstance(t, YawTarget):
            rate = min(abs(t.rate), L.yaw_rate_rad)
            if pl.plan(y0, r0, ya0, np.array([t.yaw]), np.zeros(1), np.array([rate]), lim_a, lim_j):
                if pl.duration <= dt:
                    return t.yaw, 0.0, 0.0, pl.duration, True
                y, r, acc = pl.sample(dt)
                return float(y[0]), float(r[0]), float(acc[0]), pl.duration, False
        else:
            rate = float(np.clip(t.rate, -L.yaw_rate_rad, L.yaw_rate_rad))
            if pl.plan(y0, r0, ya0, None, np.array([rate]), np.array([L.yaw_rate_rad]), lim_a, lim_j):
                y, r, acc = pl.sample(dt)
                return float(y[0]), float(r[0]), float(acc[0]), 0.0, False
        return self._brake_yaw(ref, dt)

    def _brake_yaw(self, ref: Reference, dt: float) -> tuple[float, float, float, float, bool]:
        r = ref.yaw_rate
        dr = -math.copysign(min(abs(r), self.limits.yaw_acceleration_rad * dt), r)
        r1 = r + dr
        return ref.yaw + 0.5 * (r + r1) * dt, r1, dr / dt, 0.0, False

    def _step_vertical(self, p: float, v: float, a: float, t: AxisTarget | VelocityTarget, dt: float,
                       min_duration: float | None) -> tuple[float, float, float, float, bool]:
        L = self.limits
        pl = self._vert
        lim_a = np.array([L.vertical_acceleration])
        lim_j = np.array([L.vertical_jerk])
        cur = (np.array([p]), np.array([v]), np.array([a]))
        if isinstance(t, AxisTarget):
            speed = min(t.speed, L.vertical_speed)
            end_v = float(np.clip(t.end_velocity, -speed, speed))
            trivial = abs(t.down - p) < 1e-6 and abs(v) < 1e-6 and abs(a) < 1e-6 and abs(end_v) < 1e-6
            if pl.plan(*cur, np.array([t.down]), np.array([end_v]), np.array([speed]), lim_a, lim_j,
                       None if trivial else min_duration):
                if pl.duration <= dt:
                    return t.down, end_v, 0.0, pl.duration, True
                pp, vv, aa = pl.sample(dt)
                return float(pp[0]), float(vv[0]), float(aa[0]), pl.duration, False
        else:
            target_v = float(np.clip(t.velocity[0], -L.vertical_speed, L.vertical_speed))
            if pl.plan(*cur, None, np.array([target_v]), np.array([L.vertical_speed]), lim_a, lim_j):
                pp, vv, aa = pl.sample(dt)
                return float(pp[0]), float(vv[0]), float(aa[0]), 0.0, False
        # fallback: brake at constant deceleration
        dv = -math.copysign(min(abs(v), L.vertical_acceleration * dt), v)
        return p + (v + 0.5 * dv) * dt, v + dv, dv / dt, 0.0, False

    def _step_hvel(self, p: np.ndarray, v: np.ndarray, a: np.ndarray, target_v: np.ndarray, dt: float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        L = self.limits
        target_v, _ = _clamp_norm(target_v, L.horizontal_speed)
        lim_v = np.full(2, L.horizontal_speed)
        lim_a = np.full(2, L.horizontal_acceleration * _SQRT1_2)
        lim_j = np.full(2, L.horizontal_jerk * _SQRT1_2)
        if self._hvel.plan(p, v, a, None, target_v, lim_v, lim_a, lim_j):
            return self._hvel.sample(dt)
        dv, _ = _clamp_norm(-v, L.horizontal_acceleration * dt)
        return p + (v + 0.5 * dv) * dt, v + dv, dv / dt

    def _step_path(self, p: np.ndarray, v: np.ndarray, a: np.ndarray, t: PathTarget, dt: float,
                   t_mod: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
        """Along-the-line plus across-the-line planning (see module docstring)."""
        L = self.limits
        k = p.shape[0]
        target = np.array(t.position, dtype=float)
        end_v = np.array(t.end_velocity, dtype=float) if t.end_velocity is not None else np.zeros(k)
        u, dist = _unit(target - p)
        if dist <= _EPS:
            u, n = _unit(end_v)
            if n <= _EPS:
                u, n = _unit(v)
            if n <= _EPS:
                u = np.eye(k)[0]
        basis = _perp_basis(u)
        # limits of the line
        uh = float(np.linalg.norm(u[:2]))
        uv = abs(float(u[2])) if k == 3 else 0.0
        speed = min(t.speed, L.horizontal_speed)

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
        c_amax = min(L.horizontal_acceleration, L.vertical_acceleration) if k == 3 else L.horizontal_acceleration
        c_jmax = min(L.horizontal_jerk, L.vertical_jerk) if k == 3 else L.horizontal_jerk
        c_vmax = 0.5 * (min(speed, L.vertical_speed) if k == 3 else speed)

        vc = np.array([v @ n for n in basis])
        ac = np.array([a @ n for n in basis])
        end_s = float(end_v @ u)
        end_c = np.array([end_v @ n for n in basis])
        cross_active = bool(np.any(np.abs(vc) > 1e-3) or np.any(np.abs(ac) > 1e-3) or np.any(np.abs(end_c) > 1e-3))
        alpha, beta = (0.8, 0.6) if cross_active else (1.0, 0.6)
        end_s = float(np.clip(end_s, -s_vmax, s_vmax))
        c_vmax = max(c_vmax, float(np.max(np.abs(end_c))) + 1e-6)

        along, cross = self._along, (self._cross2 if k == 2 else self._cross3)
        m = k - 1
        s_args = (np.array([-dist]), np.array([float(v @ u)]), np.array([float(a @ u)]), np.zeros(1),
                  np.array([end_s]), np.array([s_vmax]), np.array([alpha * s_amax]),
                  np.array([alpha * s_jmax]))
        if not along.plan(*s_args):
            return (*self._brake_path(p, v, dt), False)
        t_cross = 0.0
        if cross_active:  # the cross part is never stretched; the along part waits for it instead
            if not cross.plan(np.zeros(m), vc, ac, np.zeros(m), end_c, np.full(m, c_vmax),
                              np.full(m, beta * c_amax), np.full(m, beta * c_jmax)):
                return (*self._brake_path(p, v, dt), False)
            t_cross = cross.duration
        goal = max(t_cross, t_mod)
        trivial = dist < 1e-6 and abs(float(v @ u)) < 1e-6 and abs(float(a @ u)) < 1e-6 and abs(end_s) < 1e-6
        if along.duration < goal - 1e-9 and not trivial and not along.plan(*s_args, min_duration=goal):
            return (*self._brake_path(p, v, dt), False)
        if max(along.duration, t_cross) <= dt:
            return target, end_v, np.zeros(k), True
        s, vs, as_ = along.sample(dt)
        c, vcs, acs = cross.sample(dt) if cross_active else (np.zeros(m), np.zeros(m), np.zeros(m))
        p1 = target + s[0] * u + sum(c[i] * basis[i] for i in range(m))
        v1 = vs[0] * u + sum(vcs[i] * basis[i] for i in range(m))
        a1 = as_[0] * u + sum(acs[i] * basis[i] for i in range(m))
        return p1, v1, a1, False

    def _brake_path(self, p: np.ndarray, v: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        log.warning("path planning failed; braking")
        dv, _ = _clamp_norm(-v, min(self.limits.horizontal_acceleration, self.limits.vertical_acceleration) * dt)
        return p + (v + 0.5 * dv) * dt, v + dv, dv / dt

    # --- the guard --------------------------------------------------------------------------------------
    def _guard(self, ref: Reference, p1: np.ndarray, v1: np.ndarray, a1: np.ndarray, yaw: float,
               yaw_rate: float, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
        """Enforce the step bounds of the module docstring, whatever the planner proposed."""
        L = self.limits
        p0, v0 = np.array(ref.p), np.array(ref.v)
        # velocities: within the speed limits, and within a_max*dt of the previous ones
        vh, _ = _clamp_norm(v1[:2], L.horizontal_speed)
        dvh, _ = _clamp_norm(vh - v0[:2], L.horizontal_acceleration * dt)
        vv = float(np.clip(v1[2], -L.vertical_speed, L.vertical_speed))
        dvv = float(np.clip(vv - v0[2], -L.vertical_acceleration * dt, L.vertical_acceleration * dt))
        v_new = np.array([v0[0] + dvh[0], v0[1] + dvh[1], v0[2] + dvv])
        # positions: within v_max*dt of the previous ones
        dph, _ = _clamp_norm(p1[:2] - p0[:2], L.horizontal_speed * dt)
        dpv = float(np.clip(p1[2] - p0[2], -L.vertical_speed * dt, L.vertical_speed * dt))
        p_new = np.array([p0[0] + dph[0], p0[1] + dph[1], p0[2] + dpv])
        # accelerations: within the limits
        ah, _ = _clamp_norm(a1[:2], L.horizontal_acceleration)
        av = float(np.clip(a1[2], -L.vertical_acceleration, L.vertical_acceleration))
        a_new = np.array([ah[0], ah[1], av])
        # yaw
        max_dyaw = L.yaw_rate_rad * dt
        yaw_new = ref.yaw + float(np.clip(yaw - ref.yaw, -max_dyaw, max_dyaw))
        rate_new = float(np.clip(yaw_rate, -L.yaw_rate_rad, L.yaw_rate_rad))
        deviation = max(float(np.max(np.abs(v_new - v1))), float(np.max(np.abs(p_new - p1))),
                        float(np.max(np.abs(a_new - a1))), abs(yaw_new - yaw), abs(rate_new - yaw_rate))
        if deviation > 1e-9:
            self.guard_interventions += 1
            log.debug("guard corrected a step by %.3g", deviation)
        return p_new, v_new, a_new, yaw_new, rate_new


def _t3(x: np.ndarray) -> Vec3:
    return (float(x[0]), float(x[1]), float(x[2]))
