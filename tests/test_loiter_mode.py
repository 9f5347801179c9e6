"""scan-ground's ``loiter_mode`` is flown (seed 000 Fig. 14a): ``pass`` flies through the waypoints without
stopping (H_Pos's end speed, Fig. 7a), ``stop`` comes to rest at each. Measured on the kinematic vehicle
under the real queue, executive layer and TST executor; the speed is sampled over the whole path."""

from __future__ import annotations

import math
from typing import Any

import pytest

from companion.behaviors.library.follow_path import pass_speed
from companion.flight.simulate import jerk_violations
from companion.tst.execution import TstExecutionSystem
from companion.tst.plan import NodePlan
from companion.tst.spec import mission_from_yaml
from harness.behaviors import World

CRUISE = 4.0
ALT = 5.0


def zigzag(turn_deg: float, legs: int = 5, length: float = 15.0) -> list[tuple[float, float, float]]:
    """Legs of ``length`` m alternating left and right of north: each waypoint turns by ``turn_deg``."""
    half = math.radians(turn_deg / 2)
    n = e = 0.0
    out = []
    for i in range(legs):
        n += length * math.cos(half)
        e += (1 if i % 2 == 0 else -1) * length * math.sin(half)
        out.append((round(n, 3), round(e, 3), ALT))
    return out


def fly_scan(loiter_mode: str, path: list[tuple[float, float, float]]
             ) -> tuple[World, list[Any], dict[str, Any]]:
    """A waypoint scan-ground node flown by the TST executor; the vehicle's samples (t, p, horizontal
    speed, index of the leg being flown) from the scan's start to its end, and FOLLOW_PATH's parameters."""
    w = World()
    w.take_off(ALT)
    text = ("mission: m\ntree: {type: scan-ground, id: scan, params: {waypoints_scan_flag: true, "
            f"waypoints: [[-35.36, 149.16], [-35.361, 149.16]], loiter_mode: {loiter_mode}}}}}\n")
    plan = NodePlan("scan", "scan-ground", waypoints_neu=list(path), speed_m_s=CRUISE,
                    extra={"loiter_mode": loiter_mode})
    ts = TstExecutionSystem(w.layer, mark=lambda *a, **k: None)
    w.layer.cycle_listeners.append(ts.tick)
    ts.load(mission_from_yaml(text, "m.yaml"), {"scan": plan})
    ts.start()
    samples: list[Any] = []
    asked: dict[str, Any] = {}

    def sample() -> bool:
        act = w.coordinator.activation("FOLLOW_PATH")
        if act is not None:
            asked.update(act.params)
        s = w.sim.state()
        samples.append((w.sim.t, s.p, math.hypot(s.v[0], s.v[1]), w.queue.status().current_command_index))
        return not ts.running

    w.run_until(sample, 120, "the scan's end")
    assert ts.status()["state"] == "succeeded"
    ended = w.ended("FOLLOW_PATH")
    assert ended is not None and ended.cause.value == "goal_achieved"
    return w, samples, asked


def near(samples: list[Any], wp: tuple[float, float, float], radius: float = 1.0) -> list[float]:
    return [v for _, p, v, _ in samples if math.hypot(p[0] - wp[0], p[1] - wp[1]) <= radius]


@pytest.mark.parametrize(("turn_deg", "share"), [(20.0, 0.5), (30.0, 0.5), (90.0, 0.25)])
def test_pass_flies_through_every_waypoint_and_stop_rests_at_each(turn_deg: float, share: float) -> None:
    """Pass keeps at least ``share`` of the cruise speed over the whole path between its first and last
    waypoints (a right angle is flown through more slowly than a gentle turn, never stopping)."""
    path = zigzag(turn_deg)
    w, passing, asked = fly_scan("pass", path)
    assert asked["loiter_mode"] == "pass"
    # continuous through every waypoint (Sec. IV-D): the planner kept the limits; the guard never acted
    assert w.queue.guard_interventions == 0
    assert jerk_violations(w.sim.setpoints, w.queue.limits) == []
    # from the first waypoint to the start of the last leg's braking: every sample, not only at the waypoints
    through = [v for _, _, v, leg in passing if leg is not None and 1 <= leg < len(path) - 1]
    assert through and min(through) > share * CRUISE, f"slowest {min(through):.2f} m/s"
    for wp in path[:-1]:
        assert min(near(passing, wp)) > share * CRUISE, wp
    _, stopping, _ = fly_scan("stop", path)
    for wp in path[:-1]:
        assert min(near(stopping, wp)) < 0.1, wp  # at rest at each waypoint
    assert passing[-1][0] - passing[0][0] < stopping[-1][0] - stopping[0][0]  # and passing is quicker
    assert math.dist(passing[-1][1][:2], path[-1][:2]) < 0.1  # both end at rest at the last waypoint
    assert passing[-1][2] < 0.05


def test_the_pass_speed_falls_with_the_turn_and_stops_on_a_turn_back() -> None:
    a, b = (0.0, 0.0, 5.0), (10.0, 0.0, 5.0)
    assert pass_speed(a, b, (20.0, 0.0, 5.0), 4.0, 1.25) == pytest.approx(4.0)  # straight on
    assert pass_speed(a, b, (20.0, 1.0, 5.0), 4.0, 1.25) == pytest.approx(4.0)  # 6 degrees
    assert pass_speed(a, b, (20.0, 10.0, 5.0), 4.0, 1.25) == pytest.approx(1.25 / math.sin(math.radians(45)))
    assert pass_speed(a, b, (10.0, 10.0, 5.0), 4.0, 1.25) == pytest.approx(1.25)  # right angle
    assert pass_speed(a, b, (0.0, 1.0, 5.0), 4.0, 1.25) == 0.0  # back the way it came
    assert pass_speed(a, b, (10.0, 0.0, 9.0), 4.0, 1.25) == 0.0  # a climb on the spot


def test_follow_path_refuses_an_unknown_loiter_mode() -> None:
    w = World()
    w.take_off(ALT)
    r = w.activate("FOLLOW_PATH path: ((5, 0, 5), (10, 0, 5)) loiter_mode: hover")
    assert not r.accepted and "loiter_mode" in r.reason
