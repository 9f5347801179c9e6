"""Success is the vehicle, not the setpoint; time-outs from the plan; no silent clamp (seed 001 5.2.1, 6.2.1).

Over the executive layer's unit world (a real queue, the kinematic vehicle): with the measured state
frozen (the vehicle does not follow: a fence, wind) a behavior whose commands ended is not
``goal_achieved``; time-outs come from distance over the speed allowed (:mod:`companion.behaviors.timeouts`);
a speed beyond the flight envelope is refused at the format check with the reason.
"""

from __future__ import annotations

import itertools
import math

import pytest

from companion.behaviors.activation import ActivationError, check_format, parse_activation
from companion.behaviors.catalog import load_catalog
from companion.behaviors.timeouts import allowed_speed, envelope_refusal, planned_duration, time_limit
from companion.flight import EventKind, Limits
from harness.behaviors import World

CATALOG = load_catalog()
LIMITS = Limits()  # 5 m/s horizontal, 2 m/s vertical: the queue's defaults


def causes_while_running(w: World, behavior: str, timeout_s: float) -> tuple[list[str], object]:
    """Run until ``behavior`` ends; the causes of the ends seen on the way (sampled each tick), the end."""
    n = len([e for e in w.coordinator.ended if e.behavior == behavior])
    seen: list[str] = []

    def ended() -> bool:
        ends = [e for e in w.coordinator.ended if e.behavior == behavior]
        seen.extend(e.cause.value for e in ends[n:] if e.cause.value not in seen)
        return len(ends) > n

    w.run_until(ended, timeout_s, f"end of {behavior}")
    return seen, w.ended(behavior)


def test_frozen_position_go_to_point_is_not_achieved_when_its_commands_end() -> None:
    w = World()
    w.take_off()
    start = w.sim.state().p
    w.frozen = True  # the autopilot reports the vehicle where it was (held by its fence, by wind)
    r = w.activate("GO_TO_POINT coordinate: (8, 0, 5)")
    assert r.accepted, r.reason
    seq = w.queue.events.last_seq
    seen, end = causes_while_running(w, "GO_TO_POINT", 60)
    finished = [e for e in w.queue.events.since(seq) if e.kind is EventKind.FINISHED]
    assert finished, "the command (the setpoint) reached the point"
    assert seen == ["wrong_progress"], seen
    assert end.cause.value == "wrong_progress" and "8.0 m" in end.detail, end
    assert math.dist(w.vehicle().p, start) < 1e-9  # the measured vehicle never moved


def test_go_to_point_achieved_once_the_measured_vehicle_is_there() -> None:
    w = World()
    w.take_off()
    assert w.activate("GO_TO_POINT coordinate: (8, 0, 5)").accepted
    end = w.wait_ended("GO_TO_POINT", 30)
    assert end.cause.value == "goal_achieved"
    assert math.dist(w.pos_neu, (8, 0, 5)) <= CATALOG.get("GO_TO_POINT").goal["tolerance_m"]


@pytest.mark.parametrize("text", ["ROTATE angle: 90", "FOLLOW_PATH path: ((5, 0, 5), (5, 5, 5))"])
def test_frozen_rotate_and_follow_path_end_wrong_progress(text: str) -> None:
    w = World()
    w.take_off()
    w.frozen = True
    behavior = text.split()[0]
    assert w.activate(text).accepted
    seen, end = causes_while_running(w, behavior, 60)
    assert seen == ["wrong_progress"], (seen, end)


def test_frozen_take_off_is_not_achieved() -> None:
    w = World(frozen=True)  # the autopilot's altitude stays on the ground
    assert w.activate("TAKE_OFF altitude: 5").accepted
    seen, end = causes_while_running(w, "TAKE_OFF", 60)
    assert seen == ["wrong_progress"] and "from the goal" in end.detail, end


# --- time-outs from the plan --------------------------------------------------------------------------------
def test_time_limit_is_distance_over_the_speed_allowed() -> None:
    goto = CATALOG.get("GO_TO_POINT")
    far = {"coordinate": (900.0, 900.0, 5.0)}
    t5 = time_limit(goto, far, LIMITS, (0.0, 0.0, 5.0))
    t2 = time_limit(goto, {**far, "speed": 2.0}, LIMITS, (0.0, 0.0, 5.0))
    assert t5 is not None and t2 is not None
    assert t5 > 1.5 * math.hypot(900, 900) / 5.0 > 120  # the old fixed 120 s would have killed it
    assert t2 > 1.5 * math.hypot(900, 900) / 2.0
    near = time_limit(goto, {"coordinate": (10.0, 0.0, 5.0)}, LIMITS, (0.0, 0.0, 5.0))
    assert near is not None and 20 < near < 40  # a short hop: the margin dominates
    assert allowed_speed({"speed": 20.0}, LIMITS) == 5.0 and allowed_speed({}, LIMITS) == 5.0


def test_emergency_land_1000_m_away_gets_more_than_180_s() -> None:
    land = CATALOG.get("LAND")
    limit = time_limit(land, {"coordinate": (1000.0, 0.0)}, LIMITS, (0.0, 0.0, 5.0))
    assert limit is not None and limit > 1000 / 5.0 > 180


def test_a_300_m_scan_is_not_killed_at_600_s() -> None:
    lanes = [(float(n), 0.0 if i % 2 == 0 else 300.0, 10.0) for i, n in enumerate(range(0, 301, 10))]
    path = [p for n, e, u in lanes for p in ((n, e, u), (n, 300.0 - e, u))]
    length = sum(math.dist(a[:2], b[:2]) for a, b in itertools.pairwise(path))
    planned = planned_duration("FOLLOW_PATH", {"path": path}, LIMITS, path[0])
    limit = time_limit(CATALOG.get("FOLLOW_PATH"), {"path": path}, LIMITS, path[0])
    assert planned is not None and limit is not None
    assert planned >= length / 5.0 and limit > 600
    assert time_limit(CATALOG.get("KEEP_MOVING"), {"velocity": (1.0, 0, 0)}, LIMITS) is None  # no plan
    assert time_limit(CATALOG.get("SELF_LOCALIZE"), {}, LIMITS) is None  # recurrent
    assert time_limit(CATALOG.get("WAIT"), {"duration": 100.0}, LIMITS) == 110.0  # its duration + margin


def test_land_1000_m_away_flies_there_without_a_time_out() -> None:
    w = World()
    w.take_off()
    r = w.activate("LAND coordinate: (1000, 0)", "emergency")
    assert r.accepted, r.reason
    limit = w.coordinator.activation("LAND").controller.time_limit_s
    assert limit is not None and limit > 180
    seen, end = causes_while_running(w, "LAND", limit + 10)
    assert seen == ["goal_achieved"], end
    assert abs(w.pos_neu[0] - 1000) < 1.0 and end.ended_at - end.started_at > 180


def test_keep_moving_has_no_goal_time_out() -> None:
    w = World()
    w.take_off()
    assert w.activate("KEEP_MOVING velocity: (1, 0, 0)").accepted
    assert w.coordinator.activation("KEEP_MOVING").controller.time_limit_s is None


# --- no silent clamp ----------------------------------------------------------------------------------------
def test_speed_beyond_the_envelope_is_refused_at_the_format_check() -> None:
    w = World()
    w.take_off()
    before = w.active()
    r = w.activate("GO_TO_POINT coordinate: (900, 900, 5) speed: 20")
    assert not r.accepted and r.reason.startswith("format: speed: 20 m/s is beyond"), r.reason
    assert "5 m/s" in r.reason
    r = w.activate("KEEP_MOVING velocity: (0, 0, 5)")
    assert not r.accepted and "vertical speed limit 2 m/s" in r.reason, r.reason
    assert w.active() == before
    with pytest.raises(ActivationError, match="speed"):
        w.coordinator.check("FOLLOW_PATH path: ((1, 0, 5)) speed: 6")
    assert w.activate("GO_TO_POINT coordinate: (10, 0, 5) speed: 5").accepted  # at the limit: flown
    # without limits (the catalog alone) the format check knows nothing of the envelope
    fast = parse_activation("GO_TO_POINT coordinate: (1, 0, 5) speed: 20")
    assert check_format(CATALOG, fast)["speed"] == 20
    assert envelope_refusal({"speed": 4.9}, LIMITS) is None
