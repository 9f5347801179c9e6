"""Scan pattern generation for the scan-ground executor (seed 000 Sec. VI-E, Fig. 14a; Sec. VII Fig. 16a).

"The area to be covered ... can be specified ... [as] a polygon using the *area* parameter and the
sequence of waypoints which guarantees the area coverage can then be calculated" (Sec. VI-E). This
module computes that sequence as a boustrophedon (lawn-mower) pattern; everything is in local
metres ``(north, east)``, angles in degrees clockwise from north.

* **Spacing** follows the sensor footprint at the scan altitude (:func:`footprint`,
  :func:`line_spacing`): a downward camera with field of view ``fov`` at height ``h`` sees a strip
  ``2 h tan(fov / 2)`` wide; neighbouring lines overlap by ``overlap`` of it.
* **Direction** (:func:`scan_pattern`): unless ``angle_deg`` is given, the lines run parallel to an
  edge of the area's convex hull, the one giving the fewest scan segments (hence turns) and, on a
  tie, the smallest width across the lines, which by the rotating-calipers theorem is the polygon's
  minimum width. Every hull edge direction is tried.
* **Lines**: as few as cover the width (``n = ceil(width / spacing)``), spread evenly ``width / n``
  apart (at most ``spacing``), the outer ones half that inside the edges. Each line is *responsible* for the
  band half-way to its neighbours (never wider than ``spacing / 2`` on each side); a line's segment
  spans the extent of the area inside its band (not merely on the line itself), so with a footprint
  half-width of at least ``spacing / 2`` every point of the area is seen: this is the coverage
  guarantee :func:`uncovered` checks. At a slanted edge a segment may therefore end up to
  ``spacing / 2`` outside the polygon (the camera sees the corner it would otherwise miss).
* **Non-convex areas** (the paper is silent; [12] is cited): a band that meets the area in several
  pieces gives several segments. The segments are grouped into cells by a boustrophedon cellular
  decomposition (a segment continues a cell when it overlaps exactly one segment of the previous
  line and that one overlaps only it), each cell is flown as its own lawn-mower, cells are visited
  greedily nearest-first, and every connection between segments and cells is routed by
  :class:`~companion.tst.planning.inside_route.InsideRouter` so the path stays inside the area grown by
  the half band (``spacing / 2``, as a polygonal buffer: at most ``0.51 spacing``) and never cuts
  across a notch.
* **Start**: the pattern begins at the end nearest ``start_ne`` (the vehicle's position).
"""

from __future__ import annotations

import itertools
import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from shapely import affinity
from shapely.geometry import LineString, Polygon, box
from shapely.geometry.base import BaseGeometry
from shapely.ops import unary_union

from companion.sensing.footprint import Fov, Sensor, footprint, footprint_size, fov_pair, line_spacing
from companion.tst.planning.inside_route import InsideRouter

__all__ = [
    "Fov", "ScanPattern", "Sensor", "as_polygon", "coverage_fraction", "covered_area", "footprint",
    "footprint_size", "fov_pair", "line_spacing", "scan_pattern", "scan_specs", "uncovered",
]

log = logging.getLogger(__name__)

Point = tuple[float, float]
Segment = tuple[Point, Point]

_EPS = 1e-9


# --- the pattern -----------------------------------------------------------------------------------
@dataclass(frozen=True)
class ScanPattern:
    """A scan pattern: the waypoints to fly in order and the scan lines (in flight order and direction).

    ``spacing``: distance between lines (m); ``angle_deg``: direction of the lines, degrees clockwise
    from north in [0, 180); ``length_m``: length of the waypoint path; ``cells``: number of cells of
    the decomposition (1 for a convex area).
    """

    waypoints: list[Point]
    lines: list[Segment]
    spacing: float
    angle_deg: float
    length_m: float
    cells: int = 1
    area_m2: float = 0.0
    scan_length_m: float = field(default=0.0)

    @property
    def turns(self) -> int:
        """Number of turns (waypoints other than the first and the last)."""
        return max(0, len(self.waypoints) - 2)


def as_polygon(polygon_ne: Sequence[Sequence[float]] | Polygon) -> Polygon:
    """A valid shapely Polygon from ``[(n, e), ...]`` (or a Polygon); ValueError naming the problem."""
    if isinstance(polygon_ne, Polygon):
        poly = polygon_ne
    else:
        pts = [tuple(map(float, p[:2])) for p in polygon_ne]
        if len(pts) < 3:
            raise ValueError(f"area: a polygon needs at least 3 points, got {len(pts)}")
        if not all(math.isfinite(c) for p in pts for c in p):
            raise ValueError("area: coordinates must be finite")
        poly = Polygon(pts)
    if not poly.is_valid:
        from shapely.validation import explain_validity
        raise ValueError(f"area: invalid polygon ({explain_validity(poly)})")
    if poly.area <= _EPS:
        raise ValueError("area: the polygon has no area")
    return poly


def _to_uv(geom: BaseGeometry, angle_deg: float) -> BaseGeometry:
    """(n, e) -> (u along the lines, v across them)."""
    a = math.radians(angle_deg)
    c, s = math.cos(a), math.sin(a)
    return affinity.affine_transform(geom, [c, s, -s, c, 0.0, 0.0])


def _from_uv(u: float, v: float, angle_deg: float) -> Point:
    a = math.radians(angle_deg)
    c, s = math.cos(a), math.sin(a)
    return (u * c - v * s, u * s + v * c)


def _line_positions(vmin: float, vmax: float, spacing: float) -> list[float]:
    """As few lines as cover the width, spread evenly: ``n`` lines ``width / n`` (<= spacing) apart,
    the outer ones half that inside the edges (no pair of lines closer than the rest)."""
    width = vmax - vmin
    n = max(1, math.ceil(width / spacing - 1e-9))
    step = width / n
    return [vmin + step / 2.0 + k * step for k in range(n)]


def _band_segments(uv_poly: BaseGeometry, spacing: float) -> list[tuple[float, list[tuple[float, float]]]]:
    """For each line: its v and the merged u-intervals of the area inside the band it is responsible for."""
    umin, vmin, umax, vmax = uv_poly.bounds
    vs = _line_positions(vmin, vmax, spacing)
    edges = [vmin] + [(a + b) / 2.0 for a, b in itertools.pairwise(vs)] + [vmax]
    out = []
    for k, v in enumerate(vs):
        piece = uv_poly.intersection(box(umin - 1.0, edges[k], umax + 1.0, edges[k + 1]))
        parts = getattr(piece, "geoms", [piece])
        spans = sorted((g.bounds[0], g.bounds[2]) for g in parts if not g.is_empty and g.area > 0.0)
        merged: list[tuple[float, float]] = []
        for a, b in spans:
            if merged and a <= merged[-1][1] + _EPS:
                merged[-1] = (merged[-1][0], max(merged[-1][1], b))
            else:
                merged.append((a, b))
        out.append((v, merged))
    return out


def _cells(bands: list[tuple[float, list[tuple[float, float]]]]) -> list[list[tuple[float, float, float]]]:
    """Boustrophedon cellular decomposition: lists of (v, u0, u1), one segment per consecutive line."""
    def overlaps(a: tuple[float, float], b: tuple[float, float]) -> bool:
        return a[0] <= b[1] + _EPS and b[0] <= a[1] + _EPS

    cells: list[list[tuple[float, float, float]]] = []
    prev_cell: list[int] = []  # cell index of each segment of the previous line
    prev: list[tuple[float, float]] = []
    for v, spans in bands:
        cur_cell = []
        for seg in spans:
            up = [i for i, p in enumerate(prev) if overlaps(p, seg)]
            if len(up) == 1 and sum(overlaps(prev[up[0]], s) for s in spans) == 1:
                idx = prev_cell[up[0]]
            else:
                idx = len(cells)
                cells.append([])
            cells[idx].append((v, seg[0], seg[1]))
            cur_cell.append(idx)
        prev, prev_cell = spans, cur_cell
    return [c for c in cells if c]


def _traverse(cell: list[tuple[float, float, float]], backwards: bool,
              start_high: bool) -> list[tuple[Point, Point]]:
    """The cell's segments in flight order, alternating direction (u-v coordinates)."""
    order = cell[::-1] if backwards else cell
    segs = []
    for i, (v, u0, u1) in enumerate(order):
        high_first = start_high != (i % 2 == 1)
        segs.append(((u1, v), (u0, v)) if high_first else ((u0, v), (u1, v)))
    return segs


def _choose_angle(poly: Polygon, spacing: float) -> float:
    hull = np.asarray(poly.convex_hull.exterior.coords)
    candidates: dict[float, None] = {}
    for (n0, e0), (n1, e1) in itertools.pairwise(hull):
        if math.hypot(n1 - n0, e1 - e0) > 1e-9:
            candidates[round(math.degrees(math.atan2(e1 - e0, n1 - n0)) % 180.0, 9) % 180.0] = None
    best: tuple[int, float] | None = None
    best_angle = 0.0
    for ang in candidates:
        uv = _to_uv(poly, ang)
        bands = _band_segments(uv, spacing)
        key = (sum(len(s) for _, s in bands), round(uv.bounds[3] - uv.bounds[1], 6))
        if best is None or key < best:
            best, best_angle = key, ang
    return best_angle


def scan_pattern(polygon_ne: Sequence[Sequence[float]] | Polygon, spacing_m: float,
                 start_ne: Sequence[float] | None = None, angle_deg: float | None = None) -> ScanPattern:
    """A boustrophedon pattern covering the area (see the module docstring for the method)."""
    poly = as_polygon(polygon_ne)
    if not (math.isfinite(spacing_m) and spacing_m > 0.0):
        raise ValueError(f"spacing_m: must be > 0, got {spacing_m!r}")
    ang = _choose_angle(poly, spacing_m) if angle_deg is None else float(angle_deg) % 180.0
    uv_poly = _to_uv(poly, ang)
    cells = _cells(_band_segments(uv_poly, spacing_m))
    # the region transfers stay in: the area grown by the half band (polygonal buffer that contains
    # the round one, so every scan line endpoint is inside it)
    q = 4
    grow = spacing_m / 2.0 / math.cos(math.pi / (4 * q)) + 1e-6
    router = InsideRouter(poly.buffer(grow, quad_segs=q))
    if start_ne is None:
        pos = _from_uv(uv_poly.bounds[0], uv_poly.bounds[1], ang)
    else:
        pos = (float(start_ne[0]), float(start_ne[1]))
    waypoints: list[Point] = []
    lines: list[Segment] = []

    def go(p: Point) -> None:
        if not waypoints:
            waypoints.append(p)
            return
        for q_pt in router.route(waypoints[-1], p)[1:]:
            if math.dist(q_pt, waypoints[-1]) > 1e-9:
                waypoints.append(q_pt)

    todo = list(range(len(cells)))
    while todo:
        best = None
        for ci in todo:
            for backwards in (False, True):
                for start_high in (False, True):
                    (u, v), _ = _traverse(cells[ci], backwards, start_high)[0]
                    d = math.dist(pos, _from_uv(u, v, ang))
                    if best is None or d < best[0] - 1e-9:
                        best = (d, ci, backwards, start_high)
        assert best is not None
        _, ci, backwards, start_high = best
        todo.remove(ci)
        for a, b in _traverse(cells[ci], backwards, start_high):
            pa, pb = _from_uv(*a, ang), _from_uv(*b, ang)
            go(pa)
            go(pb)
            lines.append((pa, pb))
        pos = waypoints[-1]
    length = sum(math.dist(a, b) for a, b in itertools.pairwise(waypoints))
    pattern = ScanPattern(waypoints=waypoints, lines=lines, spacing=float(spacing_m), angle_deg=ang,
                          length_m=length, cells=len(cells), area_m2=poly.area,
                          scan_length_m=sum(math.dist(a, b) for a, b in lines))
    log.debug("scan pattern: %d lines, %d cells, angle %.1f deg, %.1f m", len(lines), len(cells), ang, length)
    return pattern


# --- coverage check ------------------------------------------------------------------------------
def covered_area(pattern: ScanPattern, half_width_m: float) -> BaseGeometry:
    """The ground within ``half_width_m`` across any scan line (flat ends: conservative)."""
    strips = []
    for a, b in pattern.lines:
        if math.dist(a, b) > 1e-9:
            strips.append(LineString([a, b]).buffer(half_width_m, cap_style="flat"))
    return unary_union(strips)


def uncovered(polygon_ne: Sequence[Sequence[float]] | Polygon, pattern: ScanPattern,
              half_width_m: float, tol_m2: float = 1e-6) -> BaseGeometry:
    """The part of the area farther than ``half_width_m`` from every scan line (empty for a good pattern).

    Pieces smaller than ``tol_m2`` (floating-point slivers) are dropped.
    """
    poly = as_polygon(polygon_ne)
    rest = poly.difference(covered_area(pattern, half_width_m))
    parts = [g for g in getattr(rest, "geoms", [rest]) if not g.is_empty and g.area >= tol_m2]
    return unary_union(parts) if parts else Polygon()


def coverage_fraction(polygon_ne: Sequence[Sequence[float]] | Polygon, pattern: ScanPattern,
                      half_width_m: float) -> float:
    """Fraction of the area within ``half_width_m`` of some scan line (1.0 for a good pattern)."""
    poly = as_polygon(polygon_ne)
    return min(1.0, float(poly.intersection(covered_area(pattern, half_width_m)).area / poly.area))


# --- scan specs (generate_scan_specs_flag) ----------------------------------------------------------
def _leg_time(length_m: float, speed: float, accel: float | None) -> float:
    """Time to fly one leg from rest to rest (trapezoidal speed profile when ``accel`` is given)."""
    if accel is None:
        return length_m / speed
    if length_m >= speed * speed / accel:
        return length_m / speed + speed / accel
    return 2.0 * math.sqrt(length_m / accel)


def scan_specs(pattern: ScanPattern, altitude_m: float, speed_m_s: float, sensor: Sensor | None = None,
               accel_m_s2: float | None = None,
               polygon_ne: Sequence[Sequence[float]] | Polygon | None = None) -> dict[str, object]:
    """What a user wants to know about a scan before and after flying it (generate_scan_specs_flag).

    Fig. 14a: "If true generate scan specs and put in queue"; Sec. VI-E reads the flag as generating "a
    sub-area of interest to be subsequently scanned". The specs here describe one scan (pattern, sensor,
    footprint, expected duration) so that a follow-up scan of a sub-area can be specified from them.
    The duration assumes the E_H end condition of Fig. 14b: the vehicle stops at every waypoint, so with
    ``accel_m_s2`` each leg is flown with a trapezoidal speed profile; without it, at constant speed.
    """
    if not (math.isfinite(speed_m_s) and speed_m_s > 0.0):
        raise ValueError(f"speed_m_s: must be > 0, got {speed_m_s!r}")
    if accel_m_s2 is not None and not (math.isfinite(accel_m_s2) and accel_m_s2 > 0.0):
        raise ValueError(f"accel_m_s2: must be > 0, got {accel_m_s2!r}")
    sensor = sensor or Sensor()
    width, length = footprint_size(altitude_m, sensor.fov_deg)
    legs = [math.dist(a, b) for a, b in itertools.pairwise(pattern.waypoints)]
    specs: dict[str, object] = {
        "sensor_type": sensor.type,
        "altitude_m": altitude_m,
        "speed_m_s": speed_m_s,
        "footprint_m": [width, length],
        "spacing_m": pattern.spacing,
        "overlap": 1.0 - pattern.spacing / width,
        "angle_deg": pattern.angle_deg,
        "lines": len(pattern.lines),
        "waypoints": len(pattern.waypoints),
        "turns": pattern.turns,
        "cells": pattern.cells,
        "area_m2": pattern.area_m2,
        "length_m": pattern.length_m,
        "scan_length_m": pattern.scan_length_m,
        "duration_s": sum(_leg_time(d, speed_m_s, accel_m_s2) for d in legs),
    }
    if polygon_ne is not None:
        specs["coverage_fraction"] = coverage_fraction(polygon_ne, pattern, width / 2.0)
    return specs
