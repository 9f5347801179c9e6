"""Seed 000 Sec. VII's scan-and-search mission over loopback UDP against the bundled model.

``taskflight.fig16.reproduce`` flies ``mission_specs/scan_and_search.yaml`` (indoor sensors, the model in
its own process, the companion with its behaviors and mission layers) with the operator's two
break-ins: the first resumed, the second ended by enough. Asserted: the mission succeeded; the planned
scan covers the area (every point within the camera footprint of the scan path); after the resume the
vehicle went on to the waypoint it was flying to; after enough the rest of the scan was skipped and
never flown; the landing point is the fly-to's; every streamed setpoint from take-off to landing is
continuous (seed 000: "the setpoints remained continuous from takeoff to landing") by the planner's own
trajectories: within the jerk limits, with the generator's guard never acting.
"""

from __future__ import annotations

import math
from typing import Any

import pytest
from shapely.geometry import LineString, Polygon

from companion.flight.simulate import jerk_violations, step_violations
from companion.flightlog import read_flight_log
from taskflight.fig16 import DEFAULT_BREAK_INS, reproduce

pytestmark = pytest.mark.integration

SPEEDUP = 3.0  # the companion's ticks run on the wall clock: room for a loaded CI machine


@pytest.fixture(scope="module")
def flight(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    streamed: list[Any] = []
    nodes: list[Any] = []

    def hook(node: Any) -> None:
        nodes.append(node)
        node.setpoint_listeners.append(lambda sp, fields, t: streamed.append(sp))

    result = reproduce(tmp_path_factory.mktemp("fig16"), SPEEDUP, node_hook=hook)
    return {"result": result, "records": read_flight_log(result.log_path), "streamed": streamed,
            "node": nodes[0]}


def _events(records: list[dict[str, Any]], name: str) -> list[dict[str, Any]]:
    return [r for r in records if r["type"] == "event" and r["event"] == name]


def _positions(records: list[dict[str, Any]], t0: float, t1: float = math.inf) -> list[tuple[float, ...]]:
    return [tuple(r["p"]) for r in records if r["type"] == "position" and t0 <= r["t"] <= t1]


def test_the_mission_succeeds_and_lands_at_the_fly_to_point(flight: dict[str, Any]) -> None:
    result = flight["result"]
    assert result.ok, result.problems
    plan = _events(flight["records"], "plan")[0]
    assert plan["area_ne"] and len(plan["waypoints_neu"]) == result.waypoints >= 8
    assert result.landing_point is not None
    assert math.dist(result.landing_point[:2], (0.0, 6.0)) < 0.5 and result.landing_point[2] < 0.2
    assert result.png is not None and result.png.read_bytes()[:4] == b"\x89PNG"
    assert "scan-ground (paused/enoughed)" in result.table_md


def test_the_scan_covers_the_area(flight: dict[str, Any]) -> None:
    plan = _events(flight["records"], "plan")[0]
    area = Polygon(plan["area_ne"])
    path = LineString([w[:2] for w in plan["waypoints_neu"]])
    altitude = plan["waypoints_neu"][0][2]
    half_width = altitude * math.tan(math.radians(60.0) / 2)  # the indoor platform's camera, 60 degrees
    assert path.buffer(half_width).covers(area)


def test_resume_goes_on_to_the_waypoint_it_was_flying_to(flight: dict[str, Any]) -> None:
    records = flight["records"]
    plan = _events(records, "plan")[0]
    first = DEFAULT_BREAK_INS[0]
    target = plan["waypoints_neu"][first.at - 1]  # 1-based: the waypoint flown to when paused
    ends = [e for e in _events(records, "break_in_end") if e["outcome"] == "continued"]
    assert len(ends) == 1
    after = _positions(records, ends[0]["t"])
    reached = next((i for i, p in enumerate(after) if math.dist(p[:2], target[:2]) < 0.3), None)
    assert reached is not None, f"never reached {target} after the resume"
    start = _events(records, "break_in_start")[0]
    during = _positions(records, start["t"], ends[0]["t"])
    assert max(math.dist(p[:2], during[0][:2]) for p in during) > 1.0  # the joystick moved it


def test_enough_skips_the_rest_of_the_scan(flight: dict[str, Any]) -> None:
    result, records = flight["result"], flight["records"]
    second = DEFAULT_BREAK_INS[1]
    assert result.skipped == list(range(second.at - 1, result.waypoints))
    plan = _events(records, "plan")[0]
    enough = next(e for e in _events(records, "break_in_end") if e["outcome"] == "enoughed")
    later = _positions(records, enough["t"])
    for i in result.skipped[1:]:  # the one being flown to may be passed on the way; the rest never
        w = plan["waypoints_neu"][i]
        assert min(math.dist(p[:2], w[:2]) for p in later) > 0.5, f"waypoint {i} was flown"


def test_every_streamed_setpoint_is_continuous(flight: dict[str, Any]) -> None:
    """Every setpoint the link streamed, take-off to landing. The step bounds are the ones the generator's
    guard clamps every step to (:mod:`companion.flight.reference`), so alone they would pass whatever the
    planner did: the guard never had to act, and the jerk limits, which only the planner keeps, held too."""
    streamed, queue = flight["streamed"], flight["node"].queue
    assert len(streamed) > 500
    assert queue.guard_interventions == 0
    assert step_violations(streamed, queue.limits) == [] and jerk_violations(streamed, queue.limits) == []
