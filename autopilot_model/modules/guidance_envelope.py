"""P_env of seed 000 Sec. IV-D: the region, speeds, accelerations and yaw rates the setpoints may take
(:class:`Envelope`, used by the setpoint generator of :mod:`.guidance`)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import shapely
from shapely.geometry import Point, Polygon
from shapely.geometry import box as shapely_box
from shapely.geometry.polygon import orient
from shapely.ops import nearest_points

from taskflight_common.validate import finite as _finite
from taskflight_common.validate import finite3 as _finite3

__all__ = ["Envelope", "Vec3"]

Vec3 = tuple[float, float, float]

_INF = math.inf
_TARGET_INSET = 1e-6  # m: a clamped target lies this far inside a polygon edge (float safety)


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
