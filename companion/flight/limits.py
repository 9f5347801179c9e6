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

    def covers_envelope(self, other: Envelope) -> bool:
        """True when ``other``'s horizontal area lies inside this one's (an unbounded one covers all)."""
        if self._poly is None:
            return True
        return other._poly is not None and bool(self._poly.covers(other._poly))

    def intersected(self, polygon: list[tuple[float, float]]) -> Envelope:
        """This envelope with its horizontal area cut to ``polygon`` (the altitudes kept)."""
        cut = Polygon(polygon) if self._poly is None else self._poly.intersection(Polygon(polygon))
        if not isinstance(cut, Polygon) or cut.is_empty:
            raise ValueError("envelope: the fence and the polygon do not overlap in one area")
        return Envelope(list(cut.exterior.coords)[:-1], altitude_floor=self.altitude_floor,
                        altitude_ceiling=self.altitude_ceiling)

    def describe(self) -> str:
        """A short text of the envelope for logs."""
        if self._poly is None:
            horizontal = "unbounded horizontally"
        else:
            n0, e0, n1, e1 = self._poly.bounds
            horizontal = f"north {n0:g}..{n1:g} m, east {e0:g}..{e1:g} m"
        return f"{horizontal}, floor {self.altitude_floor}, ceiling {self.altitude_ceiling}"

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


@dataclass(frozen=True)
class FlightConfig:
    """What a flight-config file gives, field by field (:func:`load_flight_config_fields`): the limits it
    names and the parts of the envelope it names, so that it can *narrow* another source (the platform)
    without its defaults standing in for what it left out."""

    file: str
    limits: dict[str, float]
    envelope: Envelope | None = None  # its horizontal area (None: not given)
    altitude_floor: float | None = None
    altitude_ceiling: float | None = None

    def narrow(self, limits: Limits, envelope: Envelope) -> tuple[Limits, Envelope]:
        """``limits`` and ``envelope`` narrowed by this file; ``ValueError`` naming the first field
        that would widen them (nothing is changed then)."""
        return narrow(limits, envelope, self.limits, self.envelope, self.altitude_floor,
                      self.altitude_ceiling, source=self.file)

    def standalone(self) -> tuple[Limits, Envelope]:
        """The file on its own (no platform): the limits it names over the defaults, its envelope."""
        vertices = self.envelope.vertices if self.envelope is not None else None
        return Limits(**{**{f.name: getattr(Limits(), f.name) for f in fields(Limits)}, **self.limits}), \
            Envelope(list(vertices) if vertices else None, altitude_floor=self.altitude_floor,
                     altitude_ceiling=self.altitude_ceiling)


def narrow(limits: Limits, envelope: Envelope, new_limits: dict[str, float] | None = None,
           area: Envelope | None = None, floor: float | None = None, ceiling: float | None = None,
           source: str = "flight config") -> tuple[Limits, Envelope]:
    """Narrow ``limits`` / ``envelope`` (the platform's, seed 000 Sec. IV-D's P_env) by the given parts.

    Each given limit must not exceed the one it replaces, ``area`` must lie inside the envelope's area, a
    ``ceiling`` not above its ceiling, a ``floor`` not below its floor; otherwise ``ValueError`` names the
    field: a second source may narrow the envelope, never widen it.
    """
    values = {f.name: getattr(limits, f.name) for f in fields(Limits)}
    for name, value in (new_limits or {}).items():
        if name not in values:
            raise ValueError(f"{source}: limits.{name}: unknown limit")
        if value > values[name] + 1e-9:
            raise ValueError(f"{source}: limits.{name}: {value:g} widens the platform's {values[name]:g} "
                             "(a flight config may narrow the platform's envelope, never widen it)")
        values[name] = float(value)
    base_floor, base_ceiling = envelope.altitude_floor, envelope.altitude_ceiling
    if ceiling is not None and base_ceiling is not None and ceiling > base_ceiling + 1e-9:
        raise ValueError(f"{source}: envelope.altitude_ceiling: {ceiling:g} m is above the platform's "
                         f"ceiling {base_ceiling:g} m (a flight config may narrow it, never widen it)")
    if floor is not None and base_floor is not None and floor < base_floor - 1e-9:
        raise ValueError(f"{source}: envelope.altitude_floor: {floor:g} m is below the platform's floor "
                         f"{base_floor:g} m (a flight config may narrow it, never widen it)")
    if area is not None and area.bounded_horizontally and not envelope.covers_envelope(area):
        raise ValueError(f"{source}: envelope.box/polygon: reaches outside the platform's fence "
                         f"({envelope.describe()}; a flight config may narrow it, never widen it)")
    new_floor = floor if floor is not None else base_floor
    new_ceiling = ceiling if ceiling is not None else base_ceiling
    vertices = area.vertices if area is not None and area.bounded_horizontally else envelope.vertices
    try:
        out = Envelope(list(vertices) if vertices else None, altitude_floor=new_floor,
                       altitude_ceiling=new_ceiling)
    except ValueError as exc:
        raise ValueError(f"{source}: {exc}") from None
    return Limits(**values), out


def load_flight_config_fields(path: str | Path) -> FlightConfig:
    """Read a flight-config file keeping what it names (:class:`FlightConfig`); errors name file, line and
    field."""
    data = load_yaml(path)
    if data is None:
        return FlightConfig(str(path), {})
    root = Fields(data, "", str(path))
    root.unknown(["limits", "envelope"])
    given: dict[str, float] = {}
    if root.has("limits"):
        Limits.from_fields(root.sub("limits"))  # the same checks (names, numbers)
        lim = root.sub("limits")
        given = {str(k): lim.number(str(k), positive=True) for k in lim.data}
    if not root.has("envelope"):
        return FlightConfig(str(path), given)
    env = Envelope.from_fields(root.sub("envelope"))
    area = env if env.bounded_horizontally else None
    return FlightConfig(str(path), given, area, env.altitude_floor, env.altitude_ceiling)


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
