"""Scan-ground pattern generation (seed 000 Sec. VI-E, Fig. 14a; the Fig. 16 area)."""

from __future__ import annotations

import itertools
import math
import random

import numpy as np
import pytest
import shapely
from shapely import affinity
from shapely.geometry import LineString, Polygon

from companion.tst.planning.coverage import (
    ScanPattern,
    Sensor,
    coverage_fraction,
    footprint,
    footprint_size,
    line_spacing,
    scan_pattern,
    scan_specs,
    uncovered,
)
from companion.tst.planning.waypoint_order import (
    order_segments,
    order_waypoints,
    path_length,
    repeat,
    segments,
)

RECT = [(0.0, 0.0), (40.0, 0.0), (40.0, 30.0), (0.0, 30.0)]
L_SHAPE = [(0, 0), (40, 0), (40, 10), (10, 10), (10, 30), (0, 30)]
U_SHAPE = [(0, 0), (30, 0), (30, 30), (20, 30), (20, 10), (10, 10), (10, 30), (0, 30)]
TRIANGLE = [(0, 0), (50, 5), (10, 35)]
ROTATED = list(affinity.rotate(Polygon([(0, 0), (40, 0), (40, 12), (0, 12)]), 30,
                               origin=(0, 0)).exterior.coords)[:-1]
FIG16 = [(0.0, 0.0), (38.0, 2.0), (41.0, 29.0), (3.0, 31.0)]  # about 40 x 30 m


def _grid_points(poly: Polygon, step: float = 0.25) -> np.ndarray:
    """Sample points of the area: a grid plus every boundary vertex and edge midpoint."""
    x0, y0, x1, y1 = poly.bounds
    xs, ys = np.meshgrid(np.arange(x0, x1 + step, step), np.arange(y0, y1 + step, step))
    pts = np.column_stack([xs.ravel(), ys.ravel()])
    inside = shapely.contains_xy(poly, pts[:, 0], pts[:, 1])
    ring = np.asarray(poly.exterior.coords)
    edge_mid = (ring[:-1] + ring[1:]) / 2.0
    return np.vstack([pts[inside], ring, edge_mid])


def _max_distance_to_lines(points: np.ndarray, pattern: ScanPattern) -> float:
    """For each point, the perpendicular distance to the nearest scan line it projects onto; the max."""
    best = np.full(len(points), np.inf)
    for a, b in pattern.lines:
        a, b = np.asarray(a), np.asarray(b)
        d = b - a
        length2 = float(d @ d)
        if length2 < 1e-18:
            continue
        t = ((points - a) @ d) / length2
        perp = np.abs((points - a) @ np.array([-d[1], d[0]])) / math.sqrt(length2)
        perp[(t < -1e-9) | (t > 1 + 1e-9)] = np.inf  # beyond the line's ends: not in its strip
        best = np.minimum(best, perp)
    return float(best.max())


# --- footprint -------------------------------------------------------------------------------------
def test_footprint_of_a_square_and_a_rectangular_field_of_view() -> None:
    assert footprint(10.0, 60.0) == pytest.approx(2 * 10 * math.tan(math.radians(30)))
    assert footprint(10.0, 90.0) == pytest.approx(20.0)
    w, length = footprint_size(5.0, (90.0, 60.0))
    assert w == pytest.approx(10.0)
    assert length == pytest.approx(2 * 5 * math.tan(math.radians(30)))
    assert footprint(5.0, (90.0, 60.0)) == pytest.approx(10.0)


def test_line_spacing_follows_the_footprint_and_overlap() -> None:
    assert line_spacing(10.0, 90.0) == pytest.approx(16.0)
    assert line_spacing(10.0, 90.0, overlap=0.5) == pytest.approx(10.0)
    assert line_spacing(20.0, 90.0, overlap=0.0) == pytest.approx(40.0)


@pytest.mark.parametrize("call", [
    lambda: footprint(0.0, 60.0), lambda: footprint(-1.0, 60.0), lambda: footprint(10.0, 180.0),
    lambda: footprint(10.0, (60.0,)), lambda: line_spacing(10.0, 60.0, overlap=1.0),
    lambda: footprint(float("nan"), 60.0),
])
def test_bad_footprint_inputs_are_refused(call) -> None:
    with pytest.raises(ValueError):
        call()


# --- coverage --------------------------------------------------------------------------------------
@pytest.mark.parametrize("area", [RECT, ROTATED, TRIANGLE, L_SHAPE, U_SHAPE, FIG16],
                         ids=["rectangle", "rotated", "triangle", "L", "U", "fig16"])
def test_every_point_of_the_area_is_within_the_footprint_of_some_scan_line(area) -> None:
    spacing = line_spacing(5.0, 60.0)  # indoor-ish: 5 m altitude, 60 deg camera, 20 % overlap
    half = footprint(5.0, 60.0) / 2.0
    pattern = scan_pattern(area, spacing, start_ne=(-5.0, -5.0))
    assert uncovered(area, pattern, half).is_empty
    assert coverage_fraction(area, pattern, half) == pytest.approx(1.0, abs=1e-9)
    # independent of shapely's buffers: sampled points, perpendicular distance to a line's strip
    assert _max_distance_to_lines(_grid_points(Polygon(area)), pattern) <= spacing / 2.0 + 1e-6


def test_the_coverage_check_can_fail() -> None:
    pattern = scan_pattern(RECT, 6.0)
    gap = uncovered(RECT, pattern, 1.0)  # footprint narrower than the spacing
    assert not gap.is_empty
    assert coverage_fraction(RECT, pattern, 1.0) == pytest.approx(2.0 / 6.0, rel=0.05)
    dropped = ScanPattern(pattern.waypoints, pattern.lines[:-1], pattern.spacing, pattern.angle_deg,
                          pattern.length_m)
    assert not uncovered(RECT, dropped, 3.0).is_empty


def test_lines_run_along_the_long_side_to_minimise_turns() -> None:
    long_thin = affinity.rotate(Polygon([(0, 0), (100, 0), (100, 10), (0, 10)]), 30, origin=(0, 0))
    pattern = scan_pattern(long_thin, 4.0)
    assert pattern.angle_deg == pytest.approx(30.0)
    assert len(pattern.lines) == 3  # ceil(10 / 4); across it would be 25 lines
    across = scan_pattern(long_thin, 4.0, angle_deg=120.0)
    assert across.angle_deg == pytest.approx(120.0)
    assert len(across.lines) == 25
    assert pattern.turns < across.turns


def test_as_few_lines_as_cover_the_width_spread_evenly() -> None:
    pattern = scan_pattern(RECT, 4.0, start_ne=(0.0, 0.0), angle_deg=0.0)  # 30 m wide: 8 lines
    easts = [a[1] for a, _ in pattern.lines]
    assert len(pattern.lines) == 8
    step = 30.0 / 8  # <= the 4 m spacing, so every band is narrower than the footprint asks
    assert easts[0] == pytest.approx(step / 2)
    assert np.diff(easts) == pytest.approx([step] * 7)
    assert easts[-1] == pytest.approx(30.0 - step / 2)


def test_the_pattern_starts_at_the_end_nearest_the_start_and_alternates() -> None:
    pattern = scan_pattern(RECT, 4.0, start_ne=(45.0, 35.0), angle_deg=0.0)
    assert pattern.waypoints[0] == pytest.approx((40.0, 30.0 - 30.0 / 16))
    dirs = [np.sign(b[0] - a[0]) for a, b in pattern.lines]
    assert all(d1 == -d2 for d1, d2 in itertools.pairwise(dirs))
    other = scan_pattern(RECT, 4.0, start_ne=(-1.0, -1.0), angle_deg=0.0)
    assert other.waypoints[0] == pytest.approx((0.0, 30.0 / 16))


def test_pattern_fields_are_consistent() -> None:
    pattern = scan_pattern(FIG16, 4.0)
    legs = sum(math.dist(a, b) for a, b in itertools.pairwise(pattern.waypoints))
    assert pattern.length_m == pytest.approx(legs)
    assert pattern.scan_length_m == pytest.approx(sum(math.dist(a, b) for a, b in pattern.lines))
    assert pattern.area_m2 == pytest.approx(Polygon(FIG16).area)
    for a, b in pattern.lines:  # every scan line is flown between consecutive waypoints
        i = next(k for k, w in enumerate(pattern.waypoints) if math.dist(w, a) < 1e-9)
        assert pattern.waypoints[i + 1] == pytest.approx(b)
    assert 0.0 <= pattern.angle_deg < 180.0


def test_a_non_convex_area_is_decomposed_and_the_path_does_not_cut_across_the_notch() -> None:
    spacing = 4.0
    pattern = scan_pattern(U_SHAPE, spacing, start_ne=(-5.0, -5.0), angle_deg=0.0)
    assert pattern.cells >= 2  # the arms of the U are cells of their own
    assert uncovered(U_SHAPE, pattern, spacing / 2.0).is_empty
    path = LineString(pattern.waypoints)
    assert Polygon(U_SHAPE).buffer(0.52 * spacing).covers(path)
    notch_core = Polygon([(10, 10), (20, 10), (20, 30), (10, 30)]).buffer(-0.52 * spacing)
    assert not path.intersects(notch_core)


def test_an_area_with_a_hole_is_covered_around_it() -> None:
    area = Polygon([(0, 0), (40, 0), (40, 40), (0, 40)], [[(15, 15), (25, 15), (25, 25), (15, 25)]])
    pattern = scan_pattern(area, 4.0)
    assert uncovered(area, pattern, 2.0).is_empty
    hole_core = Polygon([(15, 15), (25, 15), (25, 25), (15, 25)]).buffer(-2.1)
    assert not LineString(pattern.waypoints).intersects(hole_core)


def test_a_narrow_area_gets_one_line_down_the_middle() -> None:
    pattern = scan_pattern([(0, 0), (30, 0), (30, 3), (0, 3)], 4.0)
    assert len(pattern.lines) == 1
    assert pattern.lines[0][0][1] == pytest.approx(1.5)


@pytest.mark.parametrize("area", [[(0, 0), (1, 1)], [(0, 0), (10, 10), (10, 0), (0, 10)],
                                  [(0, 0), (1, 0), (2, 0)]],
                         ids=["two points", "bow-tie", "no area"])
def test_bad_areas_are_refused(area) -> None:
    with pytest.raises(ValueError, match="area"):
        scan_pattern(area, 4.0)


def test_bad_spacing_is_refused() -> None:
    with pytest.raises(ValueError, match="spacing"):
        scan_pattern(RECT, 0.0)


# --- scan specs ------------------------------------------------------------------------------------
def test_scan_specs_describe_the_scan() -> None:
    sensor = Sensor("camera", 60.0, 0.2)
    spacing = line_spacing(5.0, sensor.fov_deg, sensor.overlap)
    pattern = scan_pattern(FIG16, spacing)
    specs = scan_specs(pattern, 5.0, 1.0, sensor, polygon_ne=FIG16)
    assert specs["lines"] == len(pattern.lines)
    assert specs["duration_s"] == pytest.approx(pattern.length_m / 1.0)
    assert specs["footprint_m"] == pytest.approx([footprint(5.0, 60.0)] * 2)
    assert specs["overlap"] == pytest.approx(0.2)
    assert specs["coverage_fraction"] == pytest.approx(1.0)
    assert specs["area_m2"] == pytest.approx(Polygon(FIG16).area)
    stopping = scan_specs(pattern, 5.0, 1.0, sensor, accel_m_s2=0.5)
    assert stopping["duration_s"] > specs["duration_s"]  # stops at every waypoint (E_H)
    with pytest.raises(ValueError):
        scan_specs(pattern, 5.0, 0.0, sensor)


# --- the waypoint flags ----------------------------------------------------------------------------
def test_order_waypoints_shortens_a_scrambled_tour() -> None:
    rng = random.Random(3)
    line = [(float(i) * 10.0, 0.0) for i in range(12)]
    scrambled = line[:]
    rng.shuffle(scrambled)
    order = order_waypoints(scrambled, (0.0, 0.0))
    assert sorted(order) == list(range(len(scrambled)))
    best = path_length([scrambled[i] for i in order], (0.0, 0.0))
    assert best == pytest.approx(110.0)  # straight down the line
    assert best < path_length(scrambled, (0.0, 0.0))


def test_order_waypoints_never_returns_a_longer_tour_than_the_given_order() -> None:
    rng = random.Random(7)
    for trial in range(40):
        pts = [(rng.uniform(0, 50), rng.uniform(0, 50)) for _ in range(rng.randint(2, 15))]
        if trial % 4 == 0:  # an already good order
            pts = [pts[i] for i in order_waypoints(pts, (0.0, 0.0))]
        order = order_waypoints(pts, (0.0, 0.0))
        assert sorted(order) == list(range(len(pts)))
        assert path_length([pts[i] for i in order], (0, 0)) <= path_length(pts, (0, 0)) + 1e-9
    assert order_waypoints([], (0, 0)) == []
    assert order_waypoints([(3, 4)], (0, 0)) == [0]


def test_segments_pairs_the_waypoints() -> None:
    segs = segments([(0, 0), (10, 0), (0, 5), (10, 5)])
    assert segs == [((0.0, 0.0), (10.0, 0.0)), ((0.0, 5.0), (10.0, 5.0))]
    with pytest.raises(ValueError, match="even"):
        segments([(0, 0), (1, 0), (2, 0)])


def test_order_segments_flies_each_segment_once_and_never_longer() -> None:
    from companion.tst.planning.waypoint_order import _segments_length
    segs = segments([(0, 0), (10, 0), (0, 5), (10, 5), (0, 10), (10, 10)])
    given = [(i, False) for i in range(3)]
    plan = order_segments(segs, (0.0, 0.0))
    assert sorted(i for i, _ in plan) == [0, 1, 2]
    assert plan[1][1] is True  # the middle one is flown backwards: a lawn-mower
    assert _segments_length(segs, plan, (0, 0)) < _segments_length(segs, given, (0, 0))
    rng = random.Random(11)
    for _ in range(30):
        pts = [(rng.uniform(0, 50), rng.uniform(0, 50)) for _ in range(2 * rng.randint(1, 8))]
        s = segments(pts)
        for rev in (True, False):
            p = order_segments(s, (0.0, 0.0), allow_reverse=rev)
            assert sorted(i for i, _ in p) == list(range(len(s)))
            assert rev or not any(r for _, r in p)
            assert _segments_length(s, p, (0, 0)) <= _segments_length(s, [(i, False) for i in range(len(s))],
                                                                        (0, 0)) + 1e-9


def test_repeat_patrols_back_and_forth() -> None:
    wps = [(0, 0), (10, 0), (10, 10)]
    assert [i for i, _ in repeat(wps, laps=3)] == [0, 1, 2, 1, 0, 1, 2]
    forever = repeat(wps)
    assert [i for i, _ in itertools.islice(forever, 10)] == [0, 1, 2, 1, 0, 1, 2, 1, 0, 1]
    closed = [(0, 0), (10, 0), (10, 10), (0, 0)]
    assert [i for i, _ in repeat(closed, laps=2)] == [0, 1, 2, 3, 1, 2, 3]
    assert list(repeat([], laps=2)) == []
    assert [p for _, p in repeat([(1, 2)], laps=3)] == [(1.0, 2.0)] * 3  # hold the point each lap
