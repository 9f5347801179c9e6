"""Limits of the reference (v_max, a_max, jerk, yaw rate) and the operational envelope P_env.

Seed 000 Sec. IV-D / Fig. 9: the setpoint generation takes the target parameters P_t of the running
flight command and produces P_d within the allowed maxima P_env = [p_env, v_env, a_env]. Here
:class:`Limits` holds v_env / a_env (and jerk, since the generator is jerk-limited) and
:class:`Envelope` holds p_env: a horizontal box or polygon (shapely) plus an altitude floor and
ceiling. Both load from YAML through :mod:`taskflight_common.yamlio` (errors name file, line and field)::

    limits:   {horizontal_speed: 5, horizontal_acceleration: 2.5, vertical_speed: 2, yaw_rate: 90}
    envelope:
      box: {north_min: -100, north_max: 100, east_min: -100, east_max: 100}   # or polygon: [[n, e], ...]
      altitude_floor: 1.0       # m up; take-off and allow-landing commands may cross it
      altitude_ceiling: 60.0
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np
import shapely
from shapely.geometry import LineString, Point, Polygon
from shapely.ops import nearest_points

from taskflight_common.yamlio import ConfigError, Fields, load_yaml

from .commands import CommandError, FlightCommand, Frame, HorizontalMode, VerticalMode


@dataclass(frozen=True)
class Limits:
    """Maxima of the reference (horizontal norms, vertical absolute values). Angles in degrees.

    ``arrival_tolerance`` / ``heading_tolerance`` only serve end flags of *moving* targets
    (ExtPos, KeepDistance, Point...); fixed targets are reached exactly.
    """

    horizontal_speed: float = 5.0
    horizontal_acceleration: float = 2.5
    horizontal_jerk: float = 5.0
    vertical_speed: float = 2.0
    vertical_acceleration: float = 1.5
    vertical_jerk: float = 3.0
    yaw_rate: float = 90.0
    yaw_acceleration: float = 180.0
    yaw_jerk: float = 720.0
    arrival_tolerance: float = 0.1
    heading_tolerance: float = 2.0

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) \
                    or value <= 0:
                raise ValueError(f"limits.{f.name}: must be a finite number > 0, got {value!r}")

    # radians for the generator
    @property
    def yaw_rate_rad(self) -> float:
        return math.radians(self.yaw_rate)

    @property
    def yaw_acceleration_rad(self) -> float:
        return math.radians(self.yaw_acceleration)

    @property
    def yaw_jerk_rad(self) -> float:
        return math.radians(self.yaw_jerk)

    @classmethod
    def from_fields(cls, f: Fields) -> Limits:
        names = [x.name for x in fields(cls)]
        f.unknown(names)
        defaults = cls()
        return cls(**{n: f.number(n, getattr(defaults, n), positive=True) for n in names})


class Envelope:
    """The operational envelope p_env: horizontal polygon (a box is a rectangle) and altitude limits.

    ``None`` everywhere means unbounded. Altitudes are metres up (``-down``). The floor does not
    apply to take-off and allow-landing commands (they cross it by nature); see ``floor_exempt``.
    """

    def __init__(self, polygon: list[tuple[float, float]] | None = None, *,
                 altitude_floor: float | None = None, altitude_ceiling: float | None = None) -> None:
        self.vertices: tuple[tuple[float, float], ...] | None = None
        self._poly: Polygon | None = None
        if polygon is not None:
            pts = [(float(n), float(e)) for n, e in polygon]
            if len(pts) < 3 or not all(math.isfinite(c) for pt in pts for c in pt):
                raise ValueError("envelope.polygon: needs at least 3 finite (north, east) vertices")
            poly = Polygon(pts)
            if not poly.is_valid or poly.area <= 0:
                raise ValueError(f"envelope.polygon: not a simple polygon ({shapely.is_valid_reason(poly)})")
            poly = shapely.geometry.polygon.orient(poly, 1.0)
            self._poly = poly
            shapely.prepare(poly)
            self.vertices = tuple((float(x), float(y)) for x, y in list(poly.exterior.coords)[:-1])
            ring = np.array(poly.exterior.coords)
            self._seg_a = ring[:-1]
            self._seg_b = ring[1:]
        for name, value in (("altitude_floor", altitude_floor), ("altitude_ceiling", altitude_ceiling)):
            if value is not None and not math.isfinite(value):
                raise ValueError(f"envelope.{name}: must be finite")
        if altitude_floor is not None and altitude_ceiling is not None and altitude_floor >= altitude_ceiling:
            raise ValueError("envelope.altitude_floor: must be below altitude_ceiling")
        self.altitude_floor = altitude_floor
        self.altitude_ceiling = altitude_ceiling

    @classmethod
    def box(cls, north_min: float, north_max: float, east_min: float, east_max: float, **kw: Any) -> Envelope:
        if not (north_min < north_max and east_min < east_max):
            raise ValueError("envelope.box: needs north_min < north_max and east_min < east_max")
        corners = [(north_min, east_min), (north_max, east_min), (north_max, east_max), (north_min, east_max)]
        return cls(corners, **kw)

    @classmethod
    def from_fields(cls, f: Fields) -> Envelope:
        f.unknown(["box", "polygon", "altitude_floor", "altitude_ceiling"])
        floor = f.number("altitude_floor", None) if f.raw("altitude_floor", None) is not None else None
        ceiling = f.number("altitude_ceiling", None) if f.raw("altitude_ceiling", None) is not None else None
        if floor is not None and ceiling is not None and floor >= ceiling:
            raise f.error("altitude_floor", "must be below altitude_ceiling")
        if f.has("box") and f.has("polygon"):
            raise f.error("polygon", "give either box or polygon, not both")
        if f.has("box"):
            b = f.sub("box")
            b.unknown(["north_min", "north_max", "east_min", "east_max"])
            vals = [b.number(k) for k in ("north_min", "north_max", "east_min", "east_max")]
            if not (vals[0] < vals[1] and vals[2] < vals[3]):
                raise b.error(None, "needs north_min < north_max and east_min < east_max")
            return cls.box(*vals, altitude_floor=floor, altitude_ceiling=ceiling)
        if f.has("polygon"):
            raw = f.raw("polygon")
            if not isinstance(raw, list) or len(raw) < 3:
                raise f.error("polygon", "expected a list of at least 3 [north, east] vertices")
            pts = []
            for i, item in enumerate(raw):
                if not isinstance(item, list | tuple) or len(item) != 2 or not all(
                        isinstance(c, int | float) and not isinstance(c, bool) and math.isfinite(c)
                        for c in item):
                    line = raw.line_of(i) if hasattr(raw, "line_of") else f.line("polygon")
                    raise ConfigError(f.file, line, f"{f.path('polygon')}[{i}]",
                                      "expected [north, east] numbers")
                pts.append((float(item[0]), float(item[1])))
            try:
                return cls(pts, altitude_floor=floor, altitude_ceiling=ceiling)
            except ValueError as exc:
                raise f.error("polygon", str(exc).split(": ", 1)[-1]) from exc
        return cls(None, altitude_floor=floor, altitude_ceiling=ceiling)

    # --- queries -------------------------------------------------------------------------------------
    @property
    def bounded_horizontally(self) -> bool:
        return self._poly is not None

    def contains_ne(self, ne: tuple[float, float] | np.ndarray) -> bool:
        if self._poly is None:
            return True
        return bool(self._poly.covers(Point(float(ne[0]), float(ne[1]))))

    def covers_segment(self, a_ne: tuple[float, float], b_ne: tuple[float, float]) -> bool:
        """True when the straight horizontal segment a-b stays inside the envelope (edges included)."""
        if self._poly is None:
            return True
        if math.dist(a_ne, b_ne) < 1e-9:
            return self.contains_ne(a_ne)
        return bool(self._poly.covers(LineString([a_ne, b_ne])))

    def clamp_ne(self, ne: np.ndarray) -> tuple[np.ndarray, bool]:
        """Nearest horizontal point inside the envelope; ``True`` when it had to move."""
        if self._poly is None or self.contains_ne(ne):
            return np.asarray(ne, dtype=float), False
        near = nearest_points(self._poly, Point(float(ne[0]), float(ne[1])))[0]
        return np.array([near.x, near.y]), True

    def check_command(self, command: FlightCommand) -> None:
        """Raise :class:`CommandError` if an absolute target of ``command`` lies outside the envelope."""
        h, v = command.horizontal, command.vertical
        if h.mode is HorizontalMode.POS and h.resolved_frame is Frame.ABSOLUTE \
                and h.north is not None and h.east is not None and not self.contains_ne((h.north, h.east)):
            raise CommandError("horizontal.north", f"target ({h.north:g}, {h.east:g}) lies outside the "
                                                   "operational envelope")
        absolute_alt = v.mode is VerticalMode.WITH_HOR or (v.mode is VerticalMode.POS
                                                            and v.resolved_frame is Frame.ABSOLUTE)
        if absolute_alt and v.altitude is not None:
            _, moved = self.clamp_altitude(v.altitude, floor_exempt=v.take_off or v.allow_landing)
            if moved:
                raise CommandError("vertical.altitude",
                                   f"altitude {v.altitude:g} m lies outside the operational envelope")

    def clamp_altitude(self, alt: float, *, floor_exempt: bool = False) -> tuple[float, bool]:
        lo = None if floor_exempt else self.altitude_floor
        if lo is not None and alt < lo:
            return lo, True
        if self.altitude_ceiling is not None and alt > self.altitude_ceiling:
            return self.altitude_ceiling, True
        return alt, False

    def contains(self, p_ned: tuple[float, float, float] | np.ndarray, *, floor_exempt: bool = False) -> bool:
        _, moved = self.clamp_altitude(-float(p_ned[2]), floor_exempt=floor_exempt)
        return self.contains_ne(p_ned[:2]) and not moved

    def boundary_constraints(self, ne: np.ndarray, reach: float) -> list[tuple[np.ndarray, float]]:
        """Boundary pieces within ``reach`` of ``ne`` (inside) as (outward unit normal, distance).

        For each polygon edge the outward direction is the one from ``ne`` to the edge's closest
        point, which handles convex corners and reflex vertices alike.
        """
        if self._poly is None or not self.contains_ne(ne):
            return []
        ab = self._seg_b - self._seg_a
        ap = ne[None, :] - self._seg_a
        denom = np.maximum((ab * ab).sum(axis=1), 1e-12)
        t = np.clip((ap * ab).sum(axis=1) / denom, 0.0, 1.0)
        closest = self._seg_a + t[:, None] * ab
        delta = closest - ne[None, :]
        dist = np.hypot(delta[:, 0], delta[:, 1])
        out: list[tuple[np.ndarray, float]] = []
        for i in np.nonzero(dist < reach)[0]:
            if dist[i] > 1e-9:
                normal = delta[i] / dist[i]
            else:  # on the edge: the edge's outward normal (polygon is counter-clockwise in (n, e))
                normal = np.array([ab[i, 1], -ab[i, 0]]) / math.sqrt(denom[i])
            out.append((normal, float(dist[i])))
        return out


def load_flight_config(path: str | Path) -> tuple[Limits, Envelope]:
    """Read ``limits`` and ``envelope`` from a YAML file (both optional; defaults otherwise)."""
    data = load_yaml(path)
    if data is None:
        return Limits(), Envelope()
    root = Fields(data, "", str(path))
    root.unknown(["limits", "envelope"])
    limits = Limits.from_fields(root.sub("limits")) if root.has("limits") else Limits()
    envelope = Envelope.from_fields(root.sub("envelope")) if root.has("envelope") else Envelope()
    return limits, envelope
