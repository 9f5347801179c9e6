"""Guidance: the setpoint generator with its envelope (seed 000 Sec. IV-D, Fig. 9).

Seed 000 Sec. IV-D: "The configuration of a flight command being executed produces a set of target parameters
P_t which includes target positions, speeds, rates etc. [...] The role of the setpoint generation module is
to produce trajectories of desired parameters for positions, velocities, and accelerations:
P_d = [p_d, v_d, a_d] based on P_t. This is achieved using the constant acceleration model and taking into
account the constraints in form of allowed maximum values P_env = [p_env, v_env, a_env]." The setpoint
generation "allows for arbitrary and seamless change or adjustment of commands being executed avoiding the
discontinuities associated with mode switching" and makes it "impossible to command a UAV to leave a
designated operational area or to exceed a safe speed" (Sec. IV). Sec. IV-A: end conditions are evaluated on
the setpoints, "[t]his results in the setpoints arriving exactly at the desired values (e.g. a waypoint)".

:class:`Envelope` is P_env; :class:`SetpointGenerator` turns P_t (position / velocity / acceleration / hold
targets, yaw or yaw-rate targets) into P_d, one step of ``dt`` per :meth:`SetpointGenerator.update`.

The step (constant-acceleration model, trapezoidal position update ``p += (v + v_new) / 2 * dt``, which is
exact for a constant acceleration ``a = (v_new - v) / dt``):

1. a desired velocity from P_t: toward a position target along the straight 3-D line, at
   ``min(speed, channel limits, braking bound)``, the braking bound being the *discrete* version of
   ``sqrt(v_end^2 + 2 a d)`` (exact for the trapezoidal update, so P_d lands on the target); a velocity
   target clipped to the limits; an acceleration target integrated; hold: zero, then the stop point;
2. the velocity moves toward it by at most ``a_max * dt`` (horizontal and vertical limits separately; the
   change is scaled uniformly so a straight line stays straight);
3. the envelope: for every boundary within reach (box walls, polygon edges, floor, ceiling) the velocity
   toward it is bounded so that P_d can still stop before it with the braking acceleration; the bounded
   velocity closest to the candidate that stays within the acceleration bound is taken (``limit_reached``);
   a final clamp only removes floating-point residue.

Continuity holds by construction: ``|dv_h| <= a_max_h dt``, ``|dv_v| <= a_max_v dt``, hence (the update
being trapezoidal and the velocities within limits) ``|dp_h| <= v_max_h dt``, ``|dp_v| <= v_max_v dt``.

Everything in :meth:`SetpointGenerator.update` is plain :mod:`math` on floats; shapely is only used to
validate and pre-process the polygon and to clamp a position target into it (when the target is set).

Files: this one holds the generator (targets, the step, yaw); :mod:`.guidance_envelope` P_env
(:class:`Envelope`, importable from here too); :mod:`.guidance_polygon` the polygon walls of step 3 (a
mixin); :mod:`.guidance_math` the braking bounds and the 2-D geometry they share.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from typing import Any

from taskflight_common.validate import finite as _finite
from taskflight_common.validate import finite3 as _finite3

from .guidance_envelope import Envelope, Vec3
from .guidance_math import stop_bound, toward, wall_bound
from .guidance_polygon import PolygonWalls

__all__ = ["Envelope", "SetpointGenerator"]

log = logging.getLogger(__name__)

_INF = math.inf
_TWO_PI = 2.0 * math.pi
_SNAP_EPS = 1e-9  # m (rad): slack of the arrival snap

# P_t kinds
_POS, _VEL, _ACC, _HOLD = 0, 1, 2, 3
_MODE_NAMES = {_POS: "position", _VEL: "velocity", _ACC: "acceleration", _HOLD: "hold"}
# yaw kinds
_YAW_ANGLE, _YAW_RATE = 0, 1


def _wrap(a: float) -> float:
    """Wrap an angle to [-pi, pi)."""
    return (a + math.pi) % _TWO_PI - math.pi


class SetpointGenerator(PolygonWalls):
    """The setpoint generator of seed 000 Fig. 9: P_t -> P_d within P_env, one step of ``dt`` per update.

    Outputs (read after :meth:`update`): ``p``, ``v``, ``a`` (NED 3-tuples), ``yaw`` (rad, [-pi, pi)),
    ``yaw_rate`` (rad/s); flags ``limit_reached`` (the envelope bounded P_d this step, or the target asked
    for more than the envelope allows), ``target_unreachable`` (the current position target lies outside
    P_env: P_d flies to the nearest point inside instead), ``at_target`` (P_d arrived at the position target
    with its end speed; latched until the next target; also set once a ``hold`` has stopped) and
    ``yaw_at_target`` (P_d's yaw reached the yaw target).

    Args:
        envelope: P_env.
        dt: step of :meth:`update` in seconds.
    """

    def __init__(self, envelope: Envelope, dt: float) -> None:
        dt = _finite(dt, "dt")
        if dt <= 0.0:
            raise ValueError(f"dt must be > 0, got {dt}")
        self.dt = dt
        self.p: Vec3 = (0.0, 0.0, 0.0)
        self.v: Vec3 = (0.0, 0.0, 0.0)
        self.a: Vec3 = (0.0, 0.0, 0.0)
        self.yaw = 0.0
        self.yaw_rate = 0.0
        self.limit_reached = False
        self.target_unreachable = False
        self.at_target = False
        self.yaw_at_target = False
        #: largest correction (m) the final clamp ever had to apply (float residue only when all is well)
        self.clamp_max = 0.0
        self._mode = _HOLD
        self._t: Vec3 = (0.0, 0.0, 0.0)  # position target (clamped into P_env)
        self._t_req: tuple[Any, ...] = ()  # the request as given, to recognise a repeated target
        self._speed = _INF
        self._end_speed = 0.0
        self._vt: Vec3 = (0.0, 0.0, 0.0)  # velocity target (clipped)
        self._at: Vec3 = (0.0, 0.0, 0.0)  # acceleration target
        self._req_clipped = False
        self._yaw_mode = _YAW_RATE
        self._yaw_t = 0.0
        self._yaw_rate_t = 0.0
        self._yaw_rmax = 0.0
        self.set_envelope(envelope)
        self.reset((0.0, 0.0, 0.0))

    # ------------------------------------------------------------------------------ configuration
    def set_dt(self, dt: float) -> None:
        """Step :meth:`update` by ``dt`` seconds from now on (the schedule's period of the caller)."""
        dt = _finite(dt, "dt")
        if dt <= 0.0:
            raise ValueError(f"dt must be > 0, got {dt}")
        self.dt = dt
        self.set_envelope(self.envelope)

    def set_envelope(self, envelope: Envelope) -> None:
        """Use a new P_env (e.g. after a parameter change). If P_d lies outside it, P_d is brought back
        inside at the limits (it cannot jump)."""
        env = envelope
        dt = self.dt
        self.envelope = env
        self._vh = env.max_speed_h
        self._vup = env.max_speed_up
        self._vdn = env.max_speed_down
        self._ah = env.max_accel_h
        self._av = env.max_accel_v
        self._ahdt = env.max_accel_h * dt
        self._avdt = env.max_accel_v * dt
        self._yr = env.max_yaw_rate
        self._ya = env.max_yaw_accel
        self._yadt = env.max_yaw_accel * dt
        # vertical walls (down coordinate): floor at down = -alt_floor, ceiling at down = -alt_ceiling
        self._d_floor = -env.alt_floor
        self._d_ceil = -env.alt_ceiling
        vv = max(self._vup, self._vdn) + 0.5
        self._reach_v = vv * vv / (2.0 * self._av) + vv * dt + 0.5
        # arrival snap: the last step of the discrete braking profile covers at most a dt^2 / 2
        self._snap_h = self._ah * dt * dt + _SNAP_EPS
        self._snap_v = self._av * dt * dt + _SNAP_EPS
        self._poly = env.shape is not None
        if self._poly:
            self._setup_polygon(env.shape)
        else:
            # Box walls: both axes may brake at once, so each brakes with a_h / sqrt(2) (|dv_h| <= a_h dt).
            self._ae = self._ah / math.sqrt(2.0)
            self._nmin, self._nmax = env.north_min, env.north_max
            self._emin, self._emax = env.east_min, env.east_max
        # beyond this distance no wall bound can bite (wall_bound >= max speed): no need to look
        vh = self._vh + 0.5
        self._reach_h = vh * vh / (2.0 * self._ae) + vh * dt + 0.5

    # ---------------------------------------------------------------------------------- targets P_t
    def reset(self, p: Sequence[float], v: Sequence[float] = (0.0, 0.0, 0.0), yaw: float = 0.0,
              yaw_rate: float = 0.0) -> None:
        """Re-initialise P_d at the vehicle state (take-off from the ground, mode changes).

        P_t becomes ``hold`` (brake from ``v`` and hold where stopped) with a yaw rate target of zero.
        """
        pp = _finite3(p, "p")
        vv = _finite3(v, "v")
        y = _finite(yaw, "yaw")
        yr = _finite(yaw_rate, "yaw_rate")
        self.p, self.v, self.a = pp, vv, (0.0, 0.0, 0.0)
        self.yaw = _wrap(y)
        self.yaw_rate = yr
        self._mode = _HOLD
        self._t_req = ()
        self._yaw_mode = _YAW_RATE
        self._yaw_rate_t = 0.0
        self._req_clipped = False
        self.limit_reached = self.target_unreachable = self.at_target = self.yaw_at_target = False
        if self._poly:
            self._dref = -math.inf
            self._in_poly = False

    def set_position_target(self, p_ned: Sequence[float], speed: float | None = None,
                            end_speed: float = 0.0) -> None:
        """Fly the straight 3-D line to ``p_ned`` at ``speed`` (3-D, m/s; default and cap: the envelope's
        channel limits) and arrive with ``end_speed`` (0: stop exactly on it; > 0: pass it at that speed and
        keep that velocity until the next target). A target outside P_env is replaced by the nearest point
        inside and ``target_unreachable`` is set. Repeating the current target changes nothing."""
        t = _finite3(p_ned, "p_ned")
        s = _INF if speed is None else _finite(speed, "speed")
        if s <= 0.0:
            raise ValueError(f"speed must be > 0, got {speed}")
        ve = _finite(end_speed, "end_speed")
        if ve < 0.0:
            raise ValueError(f"end_speed must be >= 0, got {end_speed}")
        req = (t, s, ve)
        if self._mode == _POS and req == self._t_req:
            return
        tc, outside = self.envelope.nearest_inside(t)
        if outside:
            log.debug("position target %s outside P_env: flying to %s", t, tc)
        self._t = tc
        self._t_req = req
        self._speed = s
        self._end_speed = ve
        self._req_clipped = s != _INF and s > max(self._vh, self._vup, self._vdn)
        self._mode = _POS
        self.target_unreachable = outside
        self.at_target = False

    def set_velocity_target(self, v_ned: Sequence[float]) -> None:
        """Fly at ``v_ned`` (clipped to the envelope's speeds) until told otherwise."""
        vn, ve, vd = _finite3(v_ned, "v_ned")
        clipped = False
        h = math.hypot(vn, ve)
        if h > self._vh:
            k = self._vh / h
            vn, ve, clipped = vn * k, ve * k, True
        if vd > self._vdn:
            vd, clipped = self._vdn, True
        elif vd < -self._vup:
            vd, clipped = -self._vup, True
        self._vt = (vn, ve, vd)
        self._req_clipped = clipped
        self._mode = _VEL
        self._t_req = ()
        self.target_unreachable = self.at_target = False

    def set_acceleration_target(self, a_ned: Sequence[float]) -> None:
        """Accelerate at ``a_ned`` (clipped to the envelope; the speed stays within its limits)."""
        a = _finite3(a_ned, "a_ned")
        self._at = a
        self._req_clipped = math.hypot(a[0], a[1]) > self._ah or abs(a[2]) > self._av
        self._mode = _ACC
        self._t_req = ()
        self.target_unreachable = self.at_target = False

    def hold(self) -> None:
        """Stop as quickly as the limits allow and hold the stop point (a yaw rotation stops too)."""
        if self._mode != _HOLD:
            self._mode = _HOLD
            self._t_req = ()
            self._req_clipped = False
            self.target_unreachable = self.at_target = False
        if self._yaw_mode == _YAW_RATE:
            self._yaw_rate_t = 0.0

    def set_yaw_target(self, yaw: float, rate: float | None = None) -> None:
        """Turn the shortest way to ``yaw`` (rad) at most at ``|rate|`` rad/s (None or 0: max_yaw_rate, as
        MAV_CMD_CONDITION_YAW's 0 = default rate; capped at max_yaw_rate)."""
        y = _wrap(_finite(yaw, "yaw"))
        r = 0.0 if rate is None else abs(_finite(rate, "rate"))
        if r == 0.0:
            r = self._yr
        if self._yaw_mode != _YAW_ANGLE or y != self._yaw_t:
            self.yaw_at_target = False
        self._yaw_t = y
        self._yaw_rmax = min(r, self._yr)
        self._yaw_mode = _YAW_ANGLE

    def set_yaw_rate_target(self, rate: float) -> None:
        """Turn at ``rate`` rad/s (clipped to max_yaw_rate) until told otherwise."""
        r = _finite(rate, "rate")
        self._yaw_rate_t = min(max(r, -self._yr), self._yr)
        self._yaw_mode = _YAW_RATE
        self.yaw_at_target = False

    @property
    def mode(self) -> str:
        """The kind of the current translational target: position, velocity, acceleration or hold."""
        return _MODE_NAMES[self._mode]

    @property
    def target(self) -> Vec3 | None:
        """The position P_d is flying to (clamped into P_env), or None when not in position mode."""
        return self._t if self._mode == _POS else None

    # ------------------------------------------------------------------------------------ the step
    def update(self) -> None:
        """Advance P_d by one step of ``dt`` (seed 000 Fig. 9: P_t -> setpoint generation -> P_d)."""
        dt = self.dt
        pn, pe, pd = self.p
        vn, ve, vd = self.v
        ahdt = self._ahdt
        avdt = self._avdt
        mode = self._mode
        limited = self._req_clipped
        arrived = False

        # ---- 1. desired velocity from P_t
        if mode == _POS:
            tn, te, td = self._t
            dn, de, dd = tn - pn, te - pe, td - pd
            dist = math.sqrt(dn * dn + de * de + dd * dd)
            vend = self._end_speed
            if (vend == 0.0 and dn * dn + de * de <= self._snap_h * self._snap_h
                    and abs(dd) <= self._snap_v and vn * vn + ve * ve <= ahdt * ahdt and abs(vd) <= avdt):
                # arrived: snap exactly onto the target (seed 000 Sec. IV-A); within the step bounds
                self.a = (-vn / dt, -ve / dt, -vd / dt)
                self.v = (0.0, 0.0, 0.0)
                self.p = (tn, te, td)
                self.at_target = True
                self.limit_reached = limited
                self._update_yaw(dt)
                return
            if dist > 1e-12:
                inv = 1.0 / dist
                un, ue, ud = dn * inv, de * inv, dd * inv
                uh = math.sqrt(un * un + ue * ue)
                cap = self._speed
                acc = _INF
                if uh > 1e-12:
                    cap = min(cap, self._vh / uh)
                    acc = self._ah / uh
                if ud > 1e-12:
                    cap = min(cap, self._vdn / ud)
                    acc = min(acc, self._av / ud)
                elif ud < -1e-12:
                    cap = min(cap, self._vup / -ud)
                    acc = min(acc, self._av / -ud)
                s_k = vn * un + ve * ue + vd * ud
                if vend > cap:
                    vend = cap
                if vend > 0.0 and dist <= 0.5 * (s_k + vend) * dt:
                    sd = vend  # passes the target this step
                else:
                    sd = stop_bound(dist, s_k, acc, dt, vend * vend)
                    if sd > cap:
                        sd = cap
                wn, we, wd = un * sd, ue * sd, ud * sd
            else:
                un = ue = ud = 0.0
                wn = we = wd = 0.0
        elif mode == _VEL:
            wn, we, wd = self._vt
        elif mode == _ACC:
            an, ae, ad = self._at
            wn, we, wd = vn + an * dt, ve + ae * dt, vd + ad * dt
            h = math.sqrt(wn * wn + we * we)
            if h > self._vh:
                k = self._vh / h
                wn *= k
                we *= k
            if wd > self._vdn:
                wd = self._vdn
            elif wd < -self._vup:
                wd = -self._vup
        else:  # hold
            wn = we = wd = 0.0

        # ---- 2. accelerate toward it, at most a_max dt per channel, same scale on all (straight lines)
        dvn, dve, dvd = wn - vn, we - ve, wd - vd
        k = 1.0
        dvh2 = dvn * dvn + dve * dve
        if dvh2 > ahdt * ahdt:
            k = ahdt / math.sqrt(dvh2)
        if dvd > avdt or dvd < -avdt:
            kv = avdt / abs(dvd)
            if kv < k:
                k = kv
        if k < 1.0:
            cn, ce, cd = vn + k * dvn, ve + k * dve, vd + k * dvd
        else:
            cn, ce, cd = wn, we, wd

        # ---- 3. envelope: the velocity toward each boundary within reach is bounded by its stop bound
        # vertical (1-D): floor below (down grows toward it), ceiling above
        d_floor = self._d_floor - pd
        d_ceil = pd - self._d_ceil
        reach = self._reach_v
        if d_floor < reach or d_ceil < reach:
            av = self._av
            hi = wall_bound(d_floor, vd, av, dt) if d_floor < reach else _INF
            lo = -wall_bound(d_ceil, -vd, av, dt) if d_ceil < reach else -_INF
            if cd > hi:
                cd, limited = hi, True
            if cd < lo:
                cd, limited = lo, True
            # never more than the acceleration bound (only bites when the state was infeasible)
            if cd > vd + avdt:
                cd = vd + avdt
            elif cd < vd - avdt:
                cd = vd - avdt
        # horizontal
        if self._poly:
            cn, ce, lim_h = self._poly_limit(pn, pe, vn, ve, cn, ce)
            limited = limited or lim_h
        else:
            reach = self._reach_h
            d1 = self._nmax - pn
            d2 = pn - self._nmin
            d3 = self._emax - pe
            d4 = pe - self._emin
            if d1 < reach or d2 < reach or d3 < reach or d4 < reach:
                ae = self._ae
                hn = wall_bound(d1, vn, ae, dt) if d1 < reach else _INF
                ln = -wall_bound(d2, -vn, ae, dt) if d2 < reach else -_INF
                he = wall_bound(d3, ve, ae, dt) if d3 < reach else _INF
                le = -wall_bound(d4, -ve, ae, dt) if d4 < reach else -_INF
                if not (ln <= cn <= hn and le <= ce <= he):
                    limited = True
                    # closest admissible point toward the candidate: from the clipped current velocity
                    # (admissible) toward the clipped candidate, as far as the acceleration bound allows
                    qn = min(max(cn, ln), hn)
                    qe = min(max(ce, le), he)
                    s0n = min(max(vn, ln), hn)
                    s0e = min(max(ve, le), he)
                    cn, ce = toward(vn, ve, s0n, s0e, qn, qe, ahdt)

        # ---- 4. integrate (constant acceleration over the step)
        npn = pn + 0.5 * (vn + cn) * dt
        npe = pe + 0.5 * (ve + ce) * dt
        npd = pd + 0.5 * (vd + cd) * dt
        # final clamp: floating-point residue only (the bounds above keep P_d inside)
        if npd > self._d_floor and pd <= self._d_floor:
            self._note_clamp(npd - self._d_floor)
            npd, limited = self._d_floor, True
        elif npd < self._d_ceil and pd >= self._d_ceil:
            self._note_clamp(self._d_ceil - npd)
            npd, limited = self._d_ceil, True
        if self._poly:
            # near the boundary and the step as long as the distance to it: check the new point
            if self._near and math.hypot(npn - pn, npe - pe) >= self._dtrue:
                npn, npe, lim_c = self._poly_clamp(pn, pe, npn, npe)
                limited = limited or lim_c
        else:
            if npn > self._nmax and pn <= self._nmax:
                self._note_clamp(npn - self._nmax)
                npn, limited = self._nmax, True
            elif npn < self._nmin and pn >= self._nmin:
                self._note_clamp(self._nmin - npn)
                npn, limited = self._nmin, True
            if npe > self._emax and pe <= self._emax:
                self._note_clamp(npe - self._emax)
                npe, limited = self._emax, True
            elif npe < self._emin and pe >= self._emin:
                self._note_clamp(self._emin - npe)
                npe, limited = self._emin, True

        # passing the target with the end speed: at target, keep that velocity (seed 000 Sec. IV-A)
        if (mode == _POS and self._end_speed > 0.0 and dist > 1e-12
                and (npn - pn) * un + (npe - pe) * ue + (npd - pd) * ud >= dist - _SNAP_EPS):
            arrived = True
        inv_dt = 1.0 / dt
        self.a = ((cn - vn) * inv_dt, (ce - ve) * inv_dt, (cd - vd) * inv_dt)
        self.v = (cn, ce, cd)
        self.p = (npn, npe, npd)
        self.limit_reached = limited
        if arrived:
            vend = min(self._end_speed, self._vh / uh if uh > 1e-12 else _INF)
            self._vt = (un * vend, ue * vend, ud * vend)
            self._mode = _VEL
            self._t_req = ()
            self.at_target = True
        elif mode == _HOLD and cn == 0.0 and ce == 0.0 and cd == 0.0:
            # stopped: hold the stop point
            self._t = (npn, npe, npd)
            self._speed = _INF
            self._end_speed = 0.0
            self._mode = _POS
            self.at_target = True
        self._update_yaw(dt)

    def _note_clamp(self, amount: float) -> None:
        if amount > self.clamp_max:
            self.clamp_max = amount
            if amount > 1e-6:
                log.debug("P_d clamped into P_env by %.3g m", amount)

    # ---------------------------------------------------------------------------------------- yaw
    def _update_yaw(self, dt: float) -> None:
        """Yaw channel: rate-limited, acceleration-limited, shortest way, wrapped to [-pi, pi)."""
        y = self.yaw
        r = self.yaw_rate
        yadt = self._yadt
        if self._yaw_mode == _YAW_ANGLE:
            yt = self._yaw_t
            err = _wrap(yt - y)
            if abs(err) <= yadt * dt + _SNAP_EPS and abs(r) <= yadt:
                self.yaw = yt
                self.yaw_rate = 0.0
                self.yaw_at_target = True
                return
            sgn = 1.0 if err > 0.0 or (err == 0.0 and r >= 0.0) else -1.0
            rd = sgn * min(self._yaw_rmax, stop_bound(abs(err), r * sgn, self._ya, dt))
        else:
            rd = self._yaw_rate_t
        dr = rd - r
        if dr > yadt:
            dr = yadt
        elif dr < -yadt:
            dr = -yadt
        rn = r + dr
        self.yaw = _wrap(y + 0.5 * (r + rn) * dt)
        self.yaw_rate = rn
