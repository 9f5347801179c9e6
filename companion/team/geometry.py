"""Local metric geometry for team tasks (seed 003 Sec. II: border patrol and area division).

Task points are WGS84 (lat, lon, alt above the team datum); lengths, areas and cuts are computed in a
local frame of metres around a datum with ArduPilot's flat-earth conversion (:mod:`taskflight_common.geo`, the
one the whole project uses), x = north, y = east as in NED; z is kept as the altitude (m up), since task
points carry altitudes, not depths. Shapely does the planar work: polyline lengths,
``substring`` pieces of a border, polygon areas and the equal-area cut of a scan area.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from itertools import pairwise

from shapely import affinity
from shapely.geometry import LineString, Polygon, box
from shapely.ops import substring

from companion.team.types import GeoPoint
from taskflight_common.geo import geodetic_to_ned, ned_to_geodetic

#: relative tolerance of the bisection on area (the parts' areas agree to far better than 1 %)
AREA_TOL = 1e-6


class LocalFrame:
    """Metres north (x) and east (y) of a datum (lat, lon), altitude kept as z (m above the datum)."""

    def __init__(self, lat: float, lon: float) -> None:
        self.lat = float(lat)
        self.lon = float(lon)

    @classmethod
    def around(cls, points: Sequence[GeoPoint]) -> LocalFrame:
        """A frame whose datum is the mean of ``points`` (small distortion over a few km)."""
        if not points:
            raise ValueError("points: empty")
        return cls(sum(p[0] for p in points) / len(points), sum(p[1] for p in points) / len(points))

    def to_local(self, p: GeoPoint) -> tuple[float, float, float]:
        n, e, _ = geodetic_to_ned((self.lat, self.lon, 0.0), p[0], p[1], 0.0)
        return (n, e, float(p[2]) if len(p) > 2 else 0.0)

    def to_geo(self, x: float, y: float, z: float = 0.0) -> GeoPoint:
        lat, lon, _ = ned_to_geodetic((self.lat, self.lon, 0.0), x, y, 0.0)
        return (lat, lon, float(z))

    def line(self, points: Sequence[GeoPoint]) -> LineString:
        return LineString([self.to_local(p)[:2] for p in points])

    def polygon(self, points: Sequence[GeoPoint]) -> Polygon:
        return Polygon([self.to_local(p)[:2] for p in points])

    def geo_points(self, coords: Sequence[Sequence[float]], z: float) -> tuple[GeoPoint, ...]:
        return tuple(self.to_geo(c[0], c[1], z) for c in coords)


def distance_m(a: GeoPoint, b: GeoPoint) -> tuple[float, float]:
    """(horizontal, vertical) distance in metres between two geopoints (flat earth around ``a``)."""
    n, e, _ = geodetic_to_ned((a[0], a[1], 0.0), b[0], b[1], 0.0)
    return math.hypot(n, e), abs(float(b[2]) - float(a[2]))


def split_line_equal(line: LineString, n: int) -> list[LineString]:
    """``n`` consecutive pieces of equal length of ``line`` (seed 003 Sec. II: the border divided)."""
    if n < 1:
        raise ValueError(f"n: must be >= 1, got {n}")
    total = line.length
    return [substring(line, total * i / n, total * (i + 1) / n) for i in range(n)]


def longest_axis_angle(poly: Polygon) -> float:
    """Direction (rad from +x) of the long side of the polygon's minimum rotated rectangle."""
    rect = poly.minimum_rotated_rectangle
    c = list(rect.exterior.coords)
    best = (0.0, 0.0)
    for (x0, y0), (x1, y1) in pairwise(c):
        d = math.hypot(x1 - x0, y1 - y0)
        if d > best[0]:
            best = (d, math.atan2(y1 - y0, x1 - x0))
    return best[1]


def split_polygon_equal_area(poly: Polygon, n: int) -> list[Polygon]:
    """``n`` parts of equal area of ``poly`` (seed 003 Sec. II division applied to an area scan).

    The polygon is rotated so that its longest axis (of its minimum rotated rectangle) lies along x and
    cut by n - 1 lines perpendicular to it; each cut's position is found by bisection on the area to its
    left (the area is monotone in the cut position). Each part is the polygon intersected with its strip,
    rotated back. A part must come out as one simple polygon: a non-convex area whose strip falls apart
    into several pieces raises :class:`ValueError` (ask for fewer parts or split the area by hand).
    """
    if n < 1:
        raise ValueError(f"n: must be >= 1, got {n}")
    if n == 1:
        return [poly]
    angle = longest_axis_angle(poly)
    origin = poly.centroid
    rot = affinity.rotate(poly, -angle, origin=origin, use_radians=True)
    minx, miny, maxx, maxy = rot.bounds
    pad = 1.0 + (maxy - miny)
    total = rot.area

    def left_area(x: float) -> float:
        return rot.intersection(box(minx - pad, miny - pad, x, maxy + pad)).area

    cuts = [minx]
    for k in range(1, n):
        target = total * k / n
        lo, hi = cuts[-1], maxx
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            if left_area(mid) < target:
                lo = mid
            else:
                hi = mid
            if hi - lo <= AREA_TOL * max(1.0, maxx - minx):
                break
        cuts.append(0.5 * (lo + hi))
    cuts.append(maxx)
    parts = []
    for k in range(n):
        x0 = minx - pad if k == 0 else cuts[k]
        x1 = maxx + pad if k == n - 1 else cuts[k + 1]
        piece = rot.intersection(box(x0, miny - pad, x1, maxy + pad))
        if not isinstance(piece, Polygon) or piece.is_empty:
            raise ValueError(f"area: part {k + 1} of {n} is not one simple polygon (the area is too "
                             f"concave to cut into {n} strips); use fewer parts")
        piece = piece.simplify(0.0)
        parts.append(affinity.rotate(piece, angle, origin=origin, use_radians=True))
    return parts
