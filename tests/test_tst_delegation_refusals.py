"""Delegation checks what execution will do (seed 000 Sec. III-A): each refusal names the node and the reason.

A C node whose branches both fly, a fly-to without a position, a take-off without an altitude, a speed
above the envelope's limit, a relation with only an upper bound; ``taskflight mission
check`` prints every one of them offline (through the CLI, in a subprocess).
"""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
from pathlib import Path

import pytest

from companion.behaviors.activation import format_activation
from companion.tst.delegation import delegate
from companion.tst.delegation_plan import local_to_geopoint
from companion.tst.platform import Platform, bundled_platform
from companion.tst.spec import mission_from_dict
from harness.behaviors import World

ROOT = Path(__file__).resolve().parents[1]
INDOOR = bundled_platform("indoor")
OUTDOOR = bundled_platform("outdoor")


def geo(n: float, e: float, up: float | None = None, platform: Platform = INDOOR) -> list[float]:
    lat, lon, alt = local_to_geopoint((n, e, up or 0.0), platform)
    return [lat, lon] if up is None else [lat, lon, alt]


def tree(*children: dict) -> object:
    return mission_from_dict({"mission": "t", "tree": {"type": "S", "id": "root", "children": [
        {"type": "take-off", "id": "up"}, *children, {"type": "land", "id": "down"}]}})


def test_a_c_node_whose_branches_both_fly_is_refused_naming_it() -> None:
    both = {"type": "C", "id": "both", "children": [
        {"type": "fly-to", "id": "a", "params": {"position": geo(5, 0, 2)}},
        {"type": "S", "id": "b", "children": [
            {"type": "fly-to", "id": "b1", "params": {"position": geo(0, 5, 2)}}]},
    ]}
    d = delegate(tree(both), INDOOR)
    assert not d.accepted
    assert any(r.startswith("node both (C): concurrent flight") and "a (a: fly-to)" in r
               and "b (b1: fly-to)" in r for r in d.reasons), d.reasons
    # one flying branch beside a wait is fine
    fine = {"type": "C", "id": "fine", "children": [
        {"type": "fly-to", "id": "a", "params": {"position": geo(5, 0, 2)}},
        {"type": "wait", "id": "w", "params": {"duration": 3}}]}
    assert delegate(tree(fine), INDOOR).accepted


def test_no_silent_fallback_for_a_fly_to_without_a_position_or_a_take_off_without_an_altitude() -> None:
    # a mission file without the position does not load (Fig. 12a: required); a node made in code without
    # one is refused at delegation, and its executor never flies a made-up point
    nowhere = tree({"type": "fly-to", "id": "nowhere", "params": {"position": geo(5, 0, 2)}})
    for n in nowhere.root.iter():  # type: ignore[attr-defined]
        n.params.pop("position", None) if n.id == "nowhere" else None
    d = delegate(nowhere, INDOOR)
    assert not d.accepted and any(r.startswith("node nowhere (fly-to): no position") for r in d.reasons)
    no_takeoff = dataclasses.replace(INDOOR, takeoff_altitude=None)
    d = delegate(tree(), no_takeoff)
    assert not d.accepted and any(r.startswith("node up (take-off): no altitude") for r in d.reasons)


def test_a_speed_above_the_envelope_is_refused_and_an_interval_is_clamped_and_shown() -> None:
    fast = {"type": "fly-to", "id": "fast", "params": {"position": geo(5, 0, 2), "commanded_speed": 5}}
    d = delegate(tree(fast), INDOOR)
    assert not d.accepted
    assert any(r.startswith("node fast (fly-to): bad speed: commanded_speed 5 m/s is above the envelope's "
                            "speed limit 2 m/s") for r in d.reasons), d.reasons
    d = delegate(tree({"type": "fly-to", "id": "band", "params": {
        "position": geo(5, 0, 2), "commanded_speed": {"interval": [1, 3]}}}), INDOOR)
    assert d.accepted and d.plans["band"].speed_m_s is not None and d.plans["band"].speed_m_s <= 2.0
    assert "band.commanded_speed" in d.fixed and d.fixed["band.commanded_speed"] <= 2.0  # shown
    assert d.solution is not None
    labels = " ".join(d.solution.details) + " ".join(str(x) for x in d.fixed)
    assert "(given)" not in labels


def test_an_interval_speed_is_not_called_given_in_a_conflict() -> None:
    # 150 m of flight at most 2 m/s against a few seconds of battery: the conflict names the chosen speed
    short = dataclasses.replace(OUTDOOR, battery_percent=1.0)
    d = delegate(tree({"type": "fly-to", "id": "band", "params": {
        "position": geo(150, 0, 10, OUTDOOR), "commanded_speed": {"interval": [1, 2]}}}), short)
    assert not d.accepted
    text = " ".join(d.reasons)
    assert "band.commanded_speed" in text and "chosen by delegation from [1, 2]" in text, d.reasons
    assert "band.commanded_speed = 1.5 (given)" not in text


def test_a_relation_with_only_an_upper_bound_resolves_to_the_bound() -> None:
    wait = {"type": "wait", "id": "w", "params": {"duration": "duration <= 0.5 * endurance_left"}}
    d = delegate(tree(wait), INDOOR)
    assert d.accepted, d.reasons
    assert d.fixed["w.duration"] == pytest.approx(0.5 * INDOOR.endurance_s)  # not 0 s
    whole = {"type": "wait", "id": "w", "params": {"duration": "duration <= endurance_left"}}
    d = delegate(tree(whole), INDOOR)  # the whole endurance plus the take-off and landing: refused
    assert not d.accepted and any("mission longer than the endurance" in r for r in d.reasons), d.reasons


def outdoor_scan(side: float) -> object:
    area = [geo(-150, -150, None, OUTDOOR), geo(-150, -150 + side, None, OUTDOOR),
            geo(-150 + side, -150 + side, None, OUTDOOR), geo(-150 + side, -150, None, OUTDOOR)]
    scan = {"type": "scan-ground", "id": "scan", "params": {"area": area, "altitude": "standard",
                                                           "sensor_type": "camera"}}
    return tree(scan)


@pytest.mark.integration  # a 14-minute flight in simulated time: ~15 s of CPU
def test_the_300_m_outdoor_scan_is_accepted_and_flown_to_its_end_by_the_executive_layer() -> None:
    """Delegation accepts the scan only if the executive layer lets it finish: FOLLOW_PATH's time-out is
    planned from the path at the speed allowed (``timeout: {factor, margin_s}``), so the 830 s scan that a
    fixed 600 s time-out killed mid-flight is flown to its last waypoint, on the outdoor platform's own
    limits and envelope (the kinematic stand-in, simulated time)."""
    d = delegate(outdoor_scan(300.0), OUTDOOR)
    assert d.accepted, d.reasons
    plan = d.plans["scan"]
    assert plan.expected_s is not None and plan.expected_s > 600.0  # what the fixed time-out killed
    world = World(limits=OUTDOOR.flight_limits(), envelope=OUTDOOR.flight_envelope())
    world.take_off(plan.waypoints_neu[0][2])
    r = world.activate(format_activation("FOLLOW_PATH", {"path": [tuple(p) for p in plan.waypoints_neu],
                                                         "speed": plan.speed_m_s}))
    assert r.accepted, r.reason
    ended = world.wait_ended("FOLLOW_PATH", 3.0 * plan.expected_s)
    assert ended.cause.value == "goal_achieved", ended.to_dict()
    assert ended.ended_at - ended.started_at > 600.0
    last = plan.waypoints_neu[-1]
    assert math.dist(world.pos_neu, last) < 1.0, (world.pos_neu, last)


BAD_MISSION = """\
mission: refusals
tree:
  type: S
  id: root
  children:
    - {type: take-off, id: up}
    - type: C
      id: both
      children:
        - {type: fly-to, id: a, params: {position: [-35.363216, 149.165230, 2.0]}}
        - {type: fly-to, id: b, params: {position: [-35.363261, 149.165285, 2.0]}}
    - {type: fly-to, id: fast, params: {position: [-35.363216, 149.165230, 2.0], commanded_speed: 5}}
    - {type: fly-to, id: high, params: {position: [-35.363216, 149.165230, 30.0]}}
    - {type: land, id: down}
"""


def test_mission_check_prints_every_refusal_with_node_and_reason(tmp_path: Path) -> None:
    mission = tmp_path / "bad.yaml"
    mission.write_text(BAD_MISSION)
    platform = tmp_path / "platform.yaml"
    text = (ROOT / "mission_specs" / "platform_indoor.yaml").read_text()
    platform.write_text(text.replace("profile: indoor ", "takeoff_altitude: null\nprofile: indoor "))
    done = subprocess.run([sys.executable, "-m", "taskflight.cli", "mission", "check", str(mission),
                           "--platform", str(platform)], cwd=ROOT, capture_output=True, text=True,
                          timeout=120, stdin=subprocess.DEVNULL)
    assert done.returncode == 1, done.stderr
    out = done.stdout
    assert "REJECTED" in out
    for expected in ("node up (take-off): no altitude", "node both (C): concurrent flight",
"node fast (fly-to): bad speed",
                     "node high (fly-to): bad altitude"):
        assert f"  - {expected}" in out, out


PLAIN = """
mission: plain
tree:
  type: S
  children:
    - {type: take-off, id: to}
    - type: S
      id: legs
      children:
        - {type: fly-to, id: fly, params: {position: [-35.36, 149.16, 3]}}
        - {type: wait, id: rest, params: {duration: 5}}
    - {type: land, id: land}
"""


def test_prepare_rechecks_readiness_against_the_rest_of_the_plan() -> None:
    """Fig. 3 prepare(): before each node the vehicle is checked against the plan left from it; a node
    that is not ready fails with the reason and never asks for its behavior."""
    from companion.tst.execution import TstExecutionSystem
    from companion.tst.plan import NodePlan
    from companion.tst.spec import mission_from_yaml
    from harness.behaviors import World

    w = World()
    asked: list[tuple[str, float]] = []

    def readiness(node_id: str, seconds_left: float) -> str | None:
        asked.append((node_id, seconds_left))
        if seconds_left > 100:
            return f"battery: {seconds_left:.0f} s of plan left, 100 s of endurance"
        return None

    ts = TstExecutionSystem(w.layer, readiness=readiness)
    w.layer.cycle_listeners.append(ts.tick)
    plans = [NodePlan("to", "take-off", altitude_m=3.0, expected_s=5.0),
             NodePlan("fly", "fly-to", position_neu=(60.0, 0.0, 3.0), speed_m_s=1.0, expected_s=150.0),
             NodePlan("rest", "wait", duration_s=5.0, expected_s=5.0),
             NodePlan("land", "land", expected_s=4.0)]
    ts.load(mission_from_yaml(PLAIN, "m.yaml"), {p.node_id: p for p in plans})
    mission = ts.mission
    assert mission is not None
    nodes = {str(n.id): n for n in mission.root.iter()}
    assert ts.seconds_left(nodes["fly"]) == pytest.approx(159.0)  # fly + rest + land
    assert ts.seconds_left(nodes["rest"]) == pytest.approx(9.0)
    ts.start()
    status = ts.status()
    assert status["state"] == "failed", status
    assert "not ready: battery: 164 s of plan left" in status["fail_reason"]
    assert asked == [("to", pytest.approx(164.0))]
    assert not w.layer.coordinator.ended and w.layer.coordinator.activation("TAKE_OFF") is None
