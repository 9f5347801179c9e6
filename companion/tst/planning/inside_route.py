"""Shortest transfers that stay inside a region (for the scan-ground pattern, seed 000 Sec. VI-E).

A boustrophedon pattern over a non-convex area is flown cell by cell; the transfer from the end of
one cell to the start of the next (and, at a concave boundary, from one scan line to the next) must
not cut across the outside of the area. :class:`InsideRouter` answers the straight segment when it
stays inside the region, otherwise the shortest path through the region's visibility graph (its
vertices, connected when the segment between them is covered by the region) found with Dijkstra.
Coordinates are local metres ``(north, east)``; the region is a shapely (Multi)Polygon.
"""

from __future__ import annotations

import heapq
import logging
import math
from collections.abc import Sequence

import numpy as np
import shapely
from shapely.geometry import LineString, MultiPolygon, Polygon
from shapely.geometry.base import BaseGeometry

log = logging.getLogger(__name__)

Point = tuple[float, float]


def _vertices(region: BaseGeometry) -> np.ndarray:
    """Every ring vertex of a (Multi)Polygon, without the closing duplicates."""
    polys = region.geoms if isinstance(region, MultiPolygon) else [region]
    pts: list[tuple[float, float]] = []
    for p in polys:
        if not isinstance(p, Polygon) or p.is_empty:
            continue
        for ring in [p.exterior, *p.interiors]:
            pts.extend(ring.coords[:-1])
    if not pts:
        return np.zeros((0, 2))
    return np.unique(np.round(np.asarray(pts, dtype=float), 9), axis=0)


class InsideRouter:
    """Shortest paths inside ``region`` between arbitrary points of it (visibility graph + Dijkstra)."""

    def __init__(self, region: BaseGeometry, tol_m: float = 1e-6) -> None:
        self.region = region
        self._check = region.buffer(tol_m)
        shapely.prepare(self._check)
        self._nodes = _vertices(region)
        self._adj: list[list[tuple[int, float]]] | None = None

    def visible(self, a: Point, b: Point) -> bool:
        """True if the straight segment a-b lies inside the region."""
        if math.dist(a, b) < 1e-12:
            return bool(self._check.covers(shapely.Point(a)))
        return bool(self._check.covers(LineString([a, b])))

    def _visible_many(self, a: Sequence[float], others: np.ndarray) -> np.ndarray:
        starts = np.broadcast_to(np.asarray(a, float), others.shape)
        lines = shapely.linestrings(np.stack([starts, others], 1))
        return np.asarray(shapely.covers(self._check, lines), dtype=bool)

    def _graph(self) -> list[list[tuple[int, float]]]:
        if self._adj is None:
            n = len(self._nodes)
            adj: list[list[tuple[int, float]]] = [[] for _ in range(n)]
            for i in range(n - 1):
                others = self._nodes[i + 1:]
                ok = self._visible_many(self._nodes[i], others)
                for k in np.flatnonzero(ok):
                    j = i + 1 + int(k)
                    d = float(np.hypot(*(self._nodes[i] - self._nodes[j])))
                    adj[i].append((j, d))
                    adj[j].append((i, d))
            self._adj = adj
        return self._adj

    def route(self, a: Point, b: Point) -> list[Point]:
        """The shortest polyline from ``a`` to ``b`` inside the region (``[a, b]`` when straight is fine).

        If no inside path exists (a point outside the region, or a disconnected region) the straight
        segment is returned and a warning logged: the pattern stays flyable, the caller can check.
        """
        a, b = (float(a[0]), float(a[1])), (float(b[0]), float(b[1]))
        if self.visible(a, b):
            return [a, b]
        adj = self._graph()
        n = len(self._nodes)
        src, dst = n, n + 1
        from_a = self._visible_many(a, self._nodes) if n else np.zeros(0, bool)
        to_b = self._visible_many(b, self._nodes) if n else np.zeros(0, bool)
        dist = {src: 0.0}
        prev: dict[int, int] = {}
        heap: list[tuple[float, int]] = [(0.0, src)]
        done: set[int] = set()
        while heap:
            d, u = heapq.heappop(heap)
            if u in done:
                continue
            done.add(u)
            if u == dst:
                break
            if u == src:
                edges = [(int(j), math.dist(a, self._nodes[j])) for j in np.flatnonzero(from_a)]
            else:
                edges = list(adj[u])
                if to_b[u]:
                    edges.append((dst, math.dist(tuple(self._nodes[u]), b)))
            for v, w in edges:
                nd = d + w
                if nd < dist.get(v, math.inf) - 1e-12:
                    dist[v] = nd
                    prev[v] = u
                    heapq.heappush(heap, (nd, v))
        if dst not in dist:
            log.warning("no path inside the region from %s to %s; using the straight segment", a, b)
            return [a, b]
        path: list[Point] = [b]
        u = prev[dst]
        while u != src:
            path.append((float(self._nodes[u][0]), float(self._nodes[u][1])))
            u = prev[u]
        path.append(a)
        return path[::-1]
