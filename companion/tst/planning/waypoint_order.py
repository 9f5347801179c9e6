"""The waypoint flags of the scan-ground executor (seed 000 Sec. VI-E, Fig. 14a).

With ``waypoints_scan_flag`` the scan flies a given list of waypoints instead of an area pattern, and
Fig. 14a adds three flags; what each means and what this module does with it:

* ``segment_flag`` -- "Interpret the waypoints as a sequence of straight line segments"; "the flight
  between these segments can be performed in an arbitrary way" (Sec. VI-E). :func:`segments` pairs
  the waypoints ``(w0, w1), (w2, w3), ...``: each pair is a segment to scan, the flight from one
  segment's end to the next one's start is a free transfer. The paper does not say how an odd count
  is read; it is refused.
* ``any_order_flag`` -- "the order of scanning segments does not have to be enforced" (and, in
  Fig. 14a, "fly segments or waypoints in any order"). :func:`order_waypoints` orders waypoints to
  shorten the flight from the vehicle's position (nearest neighbour, then 2-opt); :func:`order_segments`
  does the same for segments. The paper is silent on the direction a segment is flown in; scanning a
  straight line is symmetric, so by default a segment may be flown either way (``allow_reverse``).
  Neither ever returns an order longer than the given one.
* ``repeat_flag`` -- "we are in patrol mode and repeat the scan of the area", "the scanning should be
  done continuously" (Sec. VI-E) until the task is enoughed. The paper does not say how the next pass
  starts; :func:`repeat` flies back and forth (w0 .. wn, wn-1 .. w0, w1 ...), which avoids the
  transfer from the last waypoint back to the first; a closed tour (first == last) is flown round.

Paths are open (they start at ``start`` and do not return). Coordinates are local metres (n, e).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator, Sequence

import numpy as np

__all__ = ["order_segments", "order_waypoints", "path_length", "repeat", "segments"]

Point = tuple[float, float]
Segment = tuple[Point, Point]


def _pts(points: Sequence[Sequence[float]]) -> np.ndarray:
    arr = np.asarray([tuple(map(float, p[:2])) for p in points], dtype=float).reshape(-1, 2)
    if not np.all(np.isfinite(arr)):
        raise ValueError("waypoints: coordinates must be finite")
    return arr


def path_length(points: Sequence[Sequence[float]], start: Sequence[float] | None = None) -> float:
    """Length of the open path through ``points`` (from ``start`` first, if given)."""
    arr = _pts(([start] if start is not None else []) + list(points))
    return float(np.sum(np.hypot(*np.diff(arr, axis=0).T))) if len(arr) > 1 else 0.0


def _two_opt(order: list[int], dist: np.ndarray) -> list[int]:
    """2-opt on an open path ``[0] + order`` over the distance matrix (node 0 is the fixed start)."""
    path = [0, *order]
    n = len(path)
    improved = True
    while improved:
        improved = False
        for i in range(1, n - 1):
            for j in range(i + 1, n):
                a, b = path[i - 1], path[i]
                c = path[j]
                d_old = dist[a, b] + (dist[c, path[j + 1]] if j + 1 < n else 0.0)
                d_new = dist[a, c] + (dist[b, path[j + 1]] if j + 1 < n else 0.0)
                if d_new < d_old - 1e-9:
                    path[i:j + 1] = path[i:j + 1][::-1]
                    improved = True
    return path[1:]


def order_waypoints(points: Sequence[Sequence[float]], start: Sequence[float]) -> list[int]:
    """A short order to visit ``points`` from ``start`` (indices into ``points``), for any_order_flag.

    Nearest neighbour from ``start``, improved by 2-opt; the given order (also 2-opt improved) is tried
    too and the shortest wins, so the result is never longer than ``range(len(points))``.
    """
    pts = _pts(points)
    n = len(pts)
    if n <= 1:
        return list(range(n))
    nodes = np.vstack([_pts([start]), pts])
    dist = np.hypot(*(nodes[:, None, :] - nodes[None, :, :]).transpose(2, 0, 1))
    left = set(range(1, n + 1))
    nn: list[int] = []
    cur = 0
    while left:
        here = cur
        cur = min(left, key=lambda k: (float(dist[here, k]), k))
        nn.append(cur)
        left.remove(cur)
    candidates = [_two_opt(nn, dist), _two_opt(list(range(1, n + 1)), dist), list(range(1, n + 1))]

    def length(order: list[int]) -> float:
        return float(sum(dist[a, b] for a, b in itertools.pairwise([0, *order])))

    best = min(candidates, key=length)
    return [k - 1 for k in best]


def segments(waypoints: Sequence[Sequence[float]]) -> list[Segment]:
    """segment_flag: the waypoints as separate scan segments ``(w0, w1), (w2, w3), ...``."""
    pts = [tuple(p) for p in _pts(waypoints).tolist()]
    if len(pts) % 2:
        raise ValueError(f"waypoints: segment_flag needs an even number of waypoints (pairs), got {len(pts)}")
    return [(pts[i], pts[i + 1]) for i in range(0, len(pts), 2)]


def _segments_length(segs: Sequence[Segment], plan: Sequence[tuple[int, bool]], start: Point) -> float:
    pos, total = start, 0.0
    for i, rev in plan:
        a, b = segs[i][::-1] if rev else segs[i]
        total += math.dist(pos, a) + math.dist(a, b)
        pos = b
    return total


def order_segments(segs: Sequence[Segment], start: Sequence[float],
                   allow_reverse: bool = True) -> list[tuple[int, bool]]:
    """segment_flag with any_order_flag: ``[(segment index, reversed), ...]`` shortening the flight.

    Nearest free segment end first; with ``allow_reverse`` then improved by 2-opt over segments
    (reversing a run of segments also flips each of them, so only the two transfers at its ends
    change). Never longer than flying the segments as given.
    """
    s0 = (float(start[0]), float(start[1]))
    n = len(segs)
    plan: list[tuple[int, bool]] = []
    left = set(range(n))
    pos = s0
    while left:
        options = [(math.dist(pos, segs[i][1 if r else 0]), i, r)
                   for i in sorted(left) for r in ((False, True) if allow_reverse else (False,))]
        _, i, r = min(options)
        plan.append((i, r))
        left.remove(i)
        pos = segs[i][0 if r else 1]
    if allow_reverse:
        plan = _two_opt_segments(segs, plan, s0)
    given = [(i, False) for i in range(n)]
    return min([plan, given], key=lambda p: _segments_length(segs, p, s0))


def _two_opt_segments(segs: Sequence[Segment], plan: list[tuple[int, bool]],
                      start: Point) -> list[tuple[int, bool]]:
    def ends(k: int) -> tuple[Point, Point]:
        i, r = plan[k]
        a, b = segs[i]
        return (b, a) if r else (a, b)

    n = len(plan)
    improved = True
    while improved:
        improved = False
        for i in range(n):
            for j in range(i, n):
                before = start if i == 0 else ends(i - 1)[1]
                first_in, last_out = ends(i)[0], ends(j)[1]
                after = ends(j + 1)[0] if j + 1 < n else None
                d_old = math.dist(before, first_in) + (math.dist(last_out, after) if after else 0.0)
                d_new = math.dist(before, last_out) + (math.dist(first_in, after) if after else 0.0)
                if d_new < d_old - 1e-9:
                    plan[i:j + 1] = [(k, not r) for k, r in reversed(plan[i:j + 1])]
                    improved = True
    return plan


def repeat(waypoints: Sequence[Sequence[float]], laps: int | None = None) -> Iterator[tuple[int, Point]]:
    """repeat_flag: ``(index, waypoint)`` back and forth over the waypoints, ``laps`` passes or forever.

    One lap is one pass over all the waypoints; the turnaround waypoint is not repeated
    (0, 1, 2, 1, 0, 1, ...). A closed tour (first == last, e.g. 0 1 2 3 with 3 = 0) is flown round
    (0 1 2 3 1 2 3 ...).
    With ``laps=None`` the iterator never ends: the executor stops it when the task is enoughed.
    """
    pts = [tuple(p) for p in _pts(waypoints).tolist()]
    if not pts:
        return
    closed = len(pts) > 2 and math.dist(pts[0], pts[-1]) < 1e-9
    lap = 0
    while laps is None or lap < laps:
        if closed:  # round: 0 .. n-1 (= 0), then 1 .. n-1 each lap
            idx = list(range(len(pts)))
        else:  # back and forth
            idx = list(range(len(pts))) if lap % 2 == 0 else list(range(len(pts) - 1, -1, -1))
        if lap > 0 and len(pts) > 1:
            idx = idx[1:]
        for i in idx:
            yield i, pts[i]
        lap += 1
