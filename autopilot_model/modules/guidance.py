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
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import shapely
from shapely.geometry import Point, Polygon
from shapely.geometry import box as shapely_box
from shapely.geometry.polygon import orient
from shapely.ops import nearest_points

from taskflight.validate import finite as _finite
from taskflight.validate import finite3 as _finite3

__all__ = ["Envelope", "SetpointGenerator"]

log = logging.getLogger(__name__)

Vec3 = tuple[float, float, float]

_INF = math.inf
_TWO_PI = 2.0 * math.pi
_TARGET_INSET = 1e-6  # m: a clamped target lies this far inside a polygon edge (float safety)
_SNAP_EPS = 1e-9  # m (rad): slack of the arrival snap

# P_t kinds
_POS, _VEL, _ACC, _HOLD = 0, 1, 2, 3
_MODE_NAMES = {_POS: "position", _VEL: "velocity", _ACC: "acceleration", _HOLD: "hold"}
# yaw kinds
_YAW_ANGLE, _YAW_RATE = 0, 1


def _wrap(a: float) -> float:
    """Wrap an angle to [-pi, pi)."""
    return (a + math.pi) % _TWO_PI - math.pi


def _stop_bound(d: float, s: float, acc: float, dt: float, v_end2: float = 0.0) -> float:
    """Largest speed ``s_new`` toward a point at distance ``d`` for the coming step (current speed ``s``)
    such that, after the trapezoidal move of this step, decelerating at ``acc`` still reaches the point with
    at most the speed ``sqrt(v_end2)``: the discrete form of ``sqrt(v_end^2 + 2 a d)``.

    Solves ``s_new^2 - v_end^2 <= 2 acc (d - (s + s_new) dt / 2)``. When even stopping this step passes the
    point, returns the speed that lands exactly on it (negative: turn back).
    """
    c0 = d - 0.5 * s * dt
    k = v_end2 + 2.0 * acc * c0
    if k >= 0.0:
        adt = acc * dt
        return 0.5 * (math.sqrt(adt * adt + 4.0 * k) - adt)
    return 2.0 * d / dt - s


def _wall_bound(d: float, s: float, acc: float, dt: float) -> float:
    """Largest velocity component toward a boundary at distance ``d`` (current component ``s``) that still
    lets P_d stop before it decelerating at ``acc``; never asks for more than a full braking step."""
    sb = s - acc * dt
    if d <= 0.0:  # on or beyond the boundary: never further out, brake as hard as allowed
        return sb if sb > 0.0 else 0.0
    b = _stop_bound(d, s, acc, dt)
    return b if b > sb else sb


@dataclass(frozen=True, eq=False)
class Envelope:
    """P_env of seed 000 Sec. IV-D: the positions, speeds, accelerations and yaw rates P_d may take.

    Horizontal region: a ``box`` ``(north_min, north_max, east_min, east_max)`` or a ``polygon``, a sequence
    of ``(north, east)`` vertices (shapely; holes are not supported), or both (their intersection), or
    neither (unbounded). Vertically ``alt_floor`` <= altitude <= ``alt_ceiling``, in metres *up* relative to
    the origin (altitude = -down). Speeds in m/s (horizontal norm; vertical up and down separately),
    accelerations in m/s^2 (horizontal norm; vertical), yaw rate in rad/s and yaw acceleration in rad/s^2.

    Raises:
        ValueError: on an invalid configuration (min >= max, non-positive limits, invalid polygon).
    """

    box: Sequence[float] | None = None
    polygon: Sequence[Sequence[float]] | None = None
    alt_floor: float = -_INF
    alt_ceiling: float = _INF
    max_speed_h: float = 10.0
    max_speed_up: float = 2.5
    max_speed_down: float = 1.5
    max_accel_h: float = 2.5
    max_accel_v: float = 2.5
    max_yaw_rate: float = math.radians(90.0)
    max_yaw_accel: float = math.radians(270.0)
    # derived, filled by __post_init__
    north_min: float = field(init=False, default=-_INF)
    north_max: float = field(init=False, default=_INF)
    east_min: float = field(init=False, default=-_INF)
    east_max: float = field(init=False, default=_INF)
    shape: Polygon | None = field(init=False, default=None, repr=False)

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        for name in ("max_speed_h", "max_speed_up", "max_speed_down", "max_accel_h", "max_accel_v",
                     "max_yaw_rate", "max_yaw_accel"):
            v = _finite(getattr(self, name), name)
            if v <= 0.0:
                raise ValueError(f"{name}: must be > 0, got {v}")
            set_(self, name, v)
        lo = float(self.alt_floor)
        hi = float(self.alt_ceiling)
        if math.isnan(lo) or math.isnan(hi) or not lo < hi:
            raise ValueError(f"alt_floor ({lo}) must be below alt_ceiling ({hi})")
        set_(self, "alt_floor", lo)
        set_(self, "alt_ceiling", hi)
        if self.box is not None:
            try:
                b = tuple(float(x) for x in self.box)
            except (TypeError, ValueError) as exc:
                raise ValueError(f"box: expected 4 numbers, got {self.box!r}") from exc
            if len(b) != 4 or any(math.isnan(x) for x in b) or not (b[0] < b[1] and b[2] < b[3]):
                raise ValueError(f"box: expected (north_min, north_max, east_min, east_max), min < max: {b}")
            set_(self, "box", b)
            set_(self, "north_min", b[0])
            set_(self, "north_max", b[1])
            set_(self, "east_min", b[2])
            set_(self, "east_max", b[3])
        if self.polygon is not None:
            try:
                pts = tuple((float(n), float(e)) for n, e in self.polygon)
            except (TypeError, ValueError) as exc:
                raise ValueError(f"polygon: expected (north, east) vertices, got {self.polygon!r}") from exc
            if len(pts) < 3 or not all(math.isfinite(c) for pt in pts for c in pt):
                raise ValueError("polygon: need at least 3 finite (north, east) vertices")
            poly = Polygon(pts)  # x = north, y = east
            if not poly.is_valid or poly.area <= 0.0:
                raise ValueError(f"polygon: invalid ({shapely.is_valid_reason(poly)})")
            if self.box is not None:
                clipped = poly.intersection(shapely_box(b[0], b[2], b[1], b[3]))
                if not isinstance(clipped, Polygon) or clipped.is_empty:
                    raise ValueError("polygon and box do not intersect in a single polygon")
                poly = clipped
            poly = orient(poly, 1.0)  # exterior counter-clockwise in (n, e)
            set_(self, "polygon", pts)
            set_(self, "shape", poly)
            bn0, be0, bn1, be1 = poly.bounds
            set_(self, "north_min", bn0)
            set_(self, "north_max", bn1)
            set_(self, "east_min", be0)
            set_(self, "east_max", be1)

    # ---------------------------------------------------------------------------- geometry queries
    def contains(self, p_ned: Sequence[float], tol: float = 1e-9) -> bool:
        """Whether ``p_ned`` lies in P_env (boundary included, within ``tol`` metres)."""
        n, e, d = (float(x) for x in p_ned)
        alt = -d
        if not (self.alt_floor - tol <= alt <= self.alt_ceiling + tol):
            return False
        if self.shape is not None:
            return bool(self.shape.distance(Point(n, e)) <= tol)
        return (self.north_min - tol <= n <= self.north_max + tol
                and self.east_min - tol <= e <= self.east_max + tol)

    def nearest_inside(self, p_ned: Sequence[float]) -> tuple[Vec3, bool]:
        """The point of P_env nearest to ``p_ned`` and whether ``p_ned`` was outside P_env."""
        n, e, d = _finite3(p_ned, "p_ned")
        outside = False
        down_min, down_max = -self.alt_ceiling, -self.alt_floor
        if d < down_min:
            d, outside = down_min, True
        elif d > down_max:
            d, outside = down_max, True
        if self.shape is None:
            nc = min(max(n, self.north_min), self.north_max)
            ec = min(max(e, self.east_min), self.east_max)
            if nc != n or ec != e:
                n, e, outside = nc, ec, True
        elif not shapely.intersects_xy(self.shape, n, e):  # the boundary is inside
            inner = self.shape.buffer(-_TARGET_INSET, join_style="mitre")
            geom = inner if isinstance(inner, Polygon) and not inner.is_empty else self.shape
            q = nearest_points(geom, Point(n, e))[0]
            n, e, outside = float(q.x), float(q.y), True
        return (n, e, d), outside


class SetpointGenerator:
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
            self._setup_polygon(env.shape)  # type: ignore[arg-type]
        else:
            # Box walls: both axes may brake at once, so each brakes with a_h / sqrt(2) (|dv_h| <= a_h dt).
            self._ae = self._ah / math.sqrt(2.0)
            self._nmin, self._nmax = env.north_min, env.north_max
            self._emin, self._emax = env.east_min, env.east_max
        # beyond this distance no wall bound can bite (_wall_bound >= max speed): no need to look
        vh = self._vh + 0.5
        self._reach_h = vh * vh / (2.0 * self._ae) + vh * dt + 0.5

    def _setup_polygon(self, poly: Polygon) -> None:
        """Pre-compute the polygon edges for the pure-math per-step queries."""
        if len(poly.interiors):
            raise ValueError("polygon envelopes with holes are not supported")
        coords = list(poly.exterior.coords)[:-1]  # counter-clockwise in (north, east)
        pts = [c for i, c in enumerate(coords) if c != coords[i - 1]]
        m = len(pts)
        convex = []
        kappa = 1.0
        for i in range(m):
            an, ae = pts[i - 1]
            bn, be = pts[i]
            cn, ce = pts[(i + 1) % m]
            en, ee, fn, fe = bn - an, be - ae, cn - bn, ce - be
            cross = en * fe - ee * fn
            # left turn = convex corner. Two walls approached at once need a combined deceleration of
            # a / cos(phi / 2), phi the angle between their normals (the turn angle): brake with less.
            convex.append(cross > 0.0)
            if cross > 0.0:
                turn = math.atan2(cross, en * fn + ee * fe)
                kappa = min(kappa, math.cos(0.5 * turn))
        edges = []
        for i in range(m):
            an, ae = pts[i]
            bn, be = pts[(i + 1) % m]
            en, ee = bn - an, be - ae
            l2 = en * en + ee * ee
            ln = math.sqrt(l2)
            # the region is on the left of each edge: the outward normal is on the right, (ee, -en)
            edges.append((an, ae, en, ee, 1.0 / l2, ee / ln, -en / ln, convex[i], convex[(i + 1) % m]))
        if kappa < 0.3:
            log.warning("polygon envelope has very sharp corners: wall braking uses %.2f of max_accel_h",
                        kappa)
        self._edges = tuple(edges)
        self._ae = self._ah * kappa
        self._pref = (math.inf, math.inf)  # where the constraint distance _dref was measured
        self._dref = -math.inf
        self._dtrue = -math.inf  # distance to the boundary at _pref
        self._near = False  # the walls were evaluated in this step
        self._in_poly = False  # P_d known to be inside the polygon (else: test it)

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
                    sd = _stop_bound(dist, s_k, acc, dt, vend * vend)
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
            hi = _wall_bound(d_floor, vd, av, dt) if d_floor < reach else _INF
            lo = -_wall_bound(d_ceil, -vd, av, dt) if d_ceil < reach else -_INF
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
                hn = _wall_bound(d1, vn, ae, dt) if d1 < reach else _INF
                ln = -_wall_bound(d2, -vn, ae, dt) if d2 < reach else -_INF
                he = _wall_bound(d3, ve, ae, dt) if d3 < reach else _INF
                le = -_wall_bound(d4, -ve, ae, dt) if d4 < reach else -_INF
                if not (ln <= cn <= hn and le <= ce <= he):
                    limited = True
                    # closest admissible point toward the candidate: from the clipped current velocity
                    # (admissible) toward the clipped candidate, as far as the acceleration bound allows
                    qn = min(max(cn, ln), hn)
                    qe = min(max(ce, le), he)
                    s0n = min(max(vn, ln), hn)
                    s0e = min(max(ve, le), he)
                    cn, ce = _toward(vn, ve, s0n, s0e, qn, qe, ahdt)

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
            rd = sgn * min(self._yaw_rmax, _stop_bound(abs(err), r * sgn, self._ya, dt))
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

    # ------------------------------------------------------------------------------------ polygon
    def _poly_limit(self, pn: float, pe: float, vn: float, ve: float, cn: float, ce: float,
                    ) -> tuple[float, float, bool]:
        """Bound the horizontal velocity candidate by the polygon walls within reach.

        Each edge gives one constraint ``n . v <= wall_bound(d)``: inside the edge's slab and beyond a convex
        vertex the edge's line (normal, line distance: exact for the convex parts), beyond a reflex vertex
        the vertex itself (radial direction and distance). The constraint distances are 1-Lipschitz in p,
        so far from every wall one distance measurement covers many steps.
        """
        reach = self._reach_h
        v2 = vn * vn + ve * ve
        if v2 > self._vh * self._vh:  # faster than the envelope (after a reset): look further
            vv = math.sqrt(v2) + 1.0
            reach = vv * vv / (2.0 * self._ae) + vv * self.dt + 1.0
        rn, re_ = self._pref
        if math.hypot(pn - rn, pe - re_) + reach < self._dref:
            self._near = False
            return cn, ce, False
        dt = self.dt
        ae = self._ae
        cons = []
        dcon = _INF
        dtrue = _INF
        known = self._in_poly  # P_d stays inside once it is: no crossing-number test needed
        inside = known
        near_n = near_e = 0.0
        for an, aa, en, ee, il2, onn, one, conv_a, conv_b in self._edges:
            wn, we = pn - an, pe - aa
            if not known and (aa > pe) != (aa + ee > pe) and pn < an + (pe - aa) * en / ee:
                inside = not inside  # crossing number (point in polygon)
            t = (wn * en + we * ee) * il2
            sd = wn * onn + we * one  # signed distance to the line, > 0 outside
            if t < 0.0:
                qn, qe, conv = -wn, -we, conv_a  # p -> vertex a
                dist = math.sqrt(qn * qn + qe * qe)
            elif t > 1.0:
                qn, qe, conv = an + en - pn, aa + ee - pe, conv_b  # p -> vertex b
                dist = math.sqrt(qn * qn + qe * qe)
            else:
                qn, qe, conv = -sd * onn, -sd * one, True  # p -> its projection on the edge
                dist = -sd if sd < 0.0 else sd
            if conv and sd <= 0.0:  # the edge's line (exact for the convex parts)
                d, nn, ne = -sd, onn, one
            elif dist > 1e-12:  # toward the nearest point of the edge (a reflex vertex, a far edge)
                d, nn, ne = dist, qn / dist, qe / dist
            else:
                d, nn, ne = 0.0, onn, one
            if dist < dtrue:
                dtrue = dist
                near_n, near_e = onn, one
            if d < dcon:
                dcon = d
            if d < reach:
                cons.append((nn, ne, d))
        self._pref = (pn, pe)
        self._near = True
        self._dtrue = dtrue
        inside = inside or dtrue <= 1e-9  # the boundary belongs to P_env
        self._in_poly = inside
        self._dref = dcon if inside else -_INF
        if not inside:  # outside (after a reset or a new envelope): not further out through the nearest edge
            cons = [(near_n, near_e, 0.0)]
        elif not cons:
            return cn, ce, False
        ok = True
        for i, (nn, ne, d) in enumerate(cons):
            b = _wall_bound(d, vn * nn + ve * ne, ae, dt)
            cons[i] = (nn, ne, b)
            if nn * cn + ne * ce > b:
                ok = False
        if ok:
            return cn, ce, False
        ahdt = self._ahdt
        # one wall (sliding along it): project onto its constraint line
        q = _project_one(cons, cn, ce)
        s0 = _project_one(cons, vn, ve)
        if q is not None and s0 is not None:
            cn, ce = _toward(vn, ve, s0[0], s0[1], q[0], q[1], ahdt)
            return cn, ce, True
        # feasible velocity polygon = big square clipped by the half-planes n.v <= b
        big = max(self._vh, math.hypot(vn, ve), math.hypot(cn, ce)) + 1.0
        vp = [(-big, -big), (big, -big), (big, big), (-big, big)]
        for nn, ne, b in cons:
            vp = _clip_halfplane(vp, nn, ne, b)
            if not vp:
                break
        if not vp:  # infeasible (cannot happen from an admissible state): brake straight
            sp = math.sqrt(v2)
            if sp <= ahdt:
                return 0.0, 0.0, True
            k = 1.0 - ahdt / sp
            return vn * k, ve * k, True
        qn, qe = _nearest_in_convex(vp, cn, ce)
        s0n, s0e = _nearest_in_convex(vp, vn, ve)
        cn, ce = _toward(vn, ve, s0n, s0e, qn, qe, ahdt)
        return cn, ce, True

    def _inside(self, pn: float, pe: float) -> bool:
        """Point in polygon (crossing number, boundary within 1e-9 m included), pure math."""
        inside = False
        dmin2 = _INF
        for an, ae, en, ee, il2, *_ in self._edges:
            be = ae + ee
            if (ae > pe) != (be > pe) and pn < an + (pe - ae) * en / ee:
                inside = not inside
            wn, we = pn - an, pe - ae
            t = (wn * en + we * ee) * il2
            t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
            wn -= t * en
            we -= t * ee
            d2 = wn * wn + we * we
            if d2 < dmin2:
                dmin2 = d2
        return inside or dmin2 <= 1e-18

    def _poly_clamp(self, pn: float, pe: float, npn: float, npe: float) -> tuple[float, float, bool]:
        """Pull a new point that left the polygon (float residue) back onto its boundary."""
        if not self._in_poly or self._inside(npn, npe):
            return npn, npe, False
        best = _INF
        bn = be = 0.0
        for an, ae, en, ee, il2, onn, one, *_ in self._edges:
            t = ((npn - an) * en + (npe - ae) * ee) * il2
            t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
            qn, qe = an + t * en, ae + t * ee
            dd = math.hypot(qn - npn, qe - npe)
            if dd < best:
                best, bn, be = dd, qn - onn * 1e-12, qe - one * 1e-12
        self._note_clamp(best)
        return bn, be, True


def _toward(vn: float, ve: float, sn: float, se: float, qn: float, qe: float, r: float,
            ) -> tuple[float, float]:
    """From the admissible point ``s`` toward the admissible point ``q``, as far as stays within ``r`` of
    the current velocity ``v`` (the acceleration bound). If ``s`` itself is out of reach (an infeasible
    state), the point at ``r`` from ``v`` toward ``s``."""
    wn, we = sn - vn, se - ve
    w2 = wn * wn + we * we
    r2 = r * r
    if w2 > r2:
        k = r / math.sqrt(w2)
        return vn + k * wn, ve + k * we
    if (qn - vn) ** 2 + (qe - ve) ** 2 <= r2:
        return qn, qe
    en, ee = qn - sn, qe - se
    e2 = en * en + ee * ee  # > 0 here: q is out of reach, s is not
    b = wn * en + we * ee
    disc = b * b - e2 * (w2 - r2)
    t = (-b + math.sqrt(disc if disc > 0.0 else 0.0)) / e2  # |w + t e| = r
    if t < 0.0:
        t = 0.0
    elif t > 1.0:
        t = 1.0
    return sn + t * en, se + t * ee


def _project_one(cons: list[tuple[float, float, float]], x: float, y: float) -> tuple[float, float] | None:
    """``(x, y)`` if it satisfies all constraints ``n . v <= b``; its projection onto the line of the only
    violated one if that satisfies the others; else None."""
    viol = None
    for c in cons:
        if c[0] * x + c[1] * y > c[2]:
            if viol is not None:
                return None
            viol = c
    if viol is None:
        return x, y
    nn, ne, b = viol
    k = nn * x + ne * y - b
    x -= k * nn
    y -= k * ne
    for c in cons:
        if c is not viol and c[0] * x + c[1] * y > c[2] + 1e-12:
            return None
    return x, y


def _clip_halfplane(poly: list[tuple[float, float]], nn: float, ne: float, b: float,
                    ) -> list[tuple[float, float]]:
    """Sutherland-Hodgman: the part of a convex polygon with ``nn*x + ne*y <= b``."""
    out: list[tuple[float, float]] = []
    m = len(poly)
    for i in range(m):
        xa, ya = poly[i]
        xb, yb = poly[(i + 1) % m]
        fa = nn * xa + ne * ya - b
        fb = nn * xb + ne * yb - b
        if fa <= 0.0:
            out.append((xa, ya))
        if (fa < 0.0 < fb) or (fb < 0.0 < fa):
            t = fa / (fa - fb)
            out.append((xa + t * (xb - xa), ya + t * (yb - ya)))
    return out


def _nearest_in_convex(poly: list[tuple[float, float]], x: float, y: float) -> tuple[float, float]:
    """The point of a convex polygon (any orientation) nearest to ``(x, y)``."""
    m = len(poly)
    if m == 1:
        return poly[0]
    sign = 0.0
    inside = True
    best = _INF
    bx = by = 0.0
    for i in range(m):
        xa, ya = poly[i]
        xb, yb = poly[(i + 1) % m]
        ex, ey = xb - xa, yb - ya
        cr = ex * (y - ya) - ey * (x - xa)
        if cr != 0.0:
            if sign == 0.0:
                sign = cr
            elif (cr > 0.0) != (sign > 0.0):
                inside = False
        l2 = ex * ex + ey * ey
        t = 0.0 if l2 == 0.0 else ((x - xa) * ex + (y - ya) * ey) / l2
        t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
        qx, qy = xa + t * ex, ya + t * ey
        d2 = (qx - x) ** 2 + (qy - y) ** 2
        if d2 < best:
            best, bx, by = d2, qx, qy
    if inside and m >= 3:
        return x, y
    return bx, by
