"""Delegation of a TST to a platform (seed 000 Sec. III-A, Fig. 3): check, get_constraints, expand, delegate.

Each of the five rejections of delegation (seed 000 Sec. III-A) is caught with a reason that names it:
a waypoint outside the fence, a mission longer than the endurance, an unknown task, a missing sensor,
a bad altitude.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
from pathlib import Path

import pytest
from shapely.geometry import LineString, Point, Polygon
from shapely.ops import unary_union

from companion.tst.constraints import ConstraintProblem
from companion.tst.delegation import ENDURANCE_LABEL, check, delegate, expand, get_constraints
from companion.tst.delegation_plan import local_to_geopoint
from companion.tst.params import plan_point
from companion.tst.planning.coverage import line_spacing
from companion.tst.platform import bundled_platform
from companion.tst.registry import leaf_type_names
from companion.tst.spec import load_mission, mission_from_dict, mission_from_yaml, mission_to_dict
from companion.tst.tree import TstNode

ROOT = Path(__file__).resolve().parents[1]
SCAN_AND_SEARCH = ROOT / "mission_specs" / "scan_and_search.yaml"
INDOOR = bundled_platform("indoor")


def geo(n: float, e: float, up: float | None = None) -> list[float]:
    """A geopoint n metres north, e east (and up) of the indoor platform's home."""
    lat, lon, alt = local_to_geopoint((n, e, up or 0.0), INDOOR)
    return [lat, lon] if up is None else [lat, lon, alt]


def mission(*leaves: dict) -> object:
    """S(take-off, *leaves, land) as a Mission."""
    children = [{"type": "take-off", "id": "up"}, *leaves, {"type": "land", "id": "down"}]
    return mission_from_dict({"mission": "t", "tree": {"type": "S", "id": "root", "children": children}})


def fly_to(node_id: str, n: float, e: float, up: float, **params: object) -> dict:
    return {"type": "fly-to", "id": node_id, "params": {"position": geo(n, e, up), **params}}


def area(n0: float, e0: float, n1: float, e1: float) -> list[list[float]]:
    return [geo(n0, e0), geo(n0, e1), geo(n1, e1), geo(n1, e0)]


# --- accepted missions ------------------------------------------------------------------------------------


def test_scan_and_search_is_accepted_on_the_indoor_platform_with_a_covering_scan() -> None:
    original = load_mission(SCAN_AND_SEARCH)
    d = delegate(original, INDOOR)
    assert d.accepted and d.reasons == [] and d.solution is not None and d.solution.ok
    takeoff, scan, fly, land = (d.plans[i] for i in ("take-off", "scan", "fly-to", "land"))
    assert takeoff.position_neu == (0.0, 0.0, 2.0) and takeoff.altitude_m == 2.0
    # scan: standard altitude and speed of the platform, lines spaced by the camera footprint
    assert scan.altitude_m == INDOOR.altitudes["standard"] and scan.speed_m_s == INDOOR.speeds["standard"]
    assert scan.extra["spacing_m"] == pytest.approx(line_spacing(2.0, 60.0, 0.2))
    assert scan.extra["data_uuid"] == "scan-and-search-1" and scan.extra["sensor_type"] == "camera"
    poly = Polygon(scan.area_ne)
    half = scan.extra["spacing_m"] / 2
    assert len(scan.waypoints_neu) >= 6
    for n, e, up in scan.waypoints_neu:
        assert up == 2.0 and poly.buffer(half + 1e-6).covers(Point(n, e))
    # every point of the area is within half a line spacing of a scan line (the lines are legs)
    lines = list(itertools.pairwise(scan.waypoints_neu))
    strips = [LineString([a[:2], b[:2]]).buffer(half + 1e-6) for a, b in lines]
    assert poly.difference(unary_union(strips)).area < 1e-6
    # fly-to: fast, 6 m east of home; land where the fly-to ended
    assert fly.speed_m_s == INDOOR.speeds["fast"] and fly.position_neu is not None
    assert fly.position_neu[1] == pytest.approx(6.0, abs=0.05) and fly.straight_line
    assert land.position_neu == pytest.approx((fly.position_neu[0], fly.position_neu[1], 0.0))
    # the expected duration is the sum of the leaves' and under the endurance
    leaves = ("take-off", "scan", "fly-to", "land")
    assert d.expected_s == pytest.approx(sum(d.plans[i].expected_s for i in leaves))
    assert 0 < d.expected_s < INDOOR.endurance_s
    # the caller's mission is not touched
    assert original.root.find("scan").children == []


def test_scan_ground_expands_into_fly_to_children_at_the_waypoints() -> None:
    d = delegate(load_mission(SCAN_AND_SEARCH), INDOOR)
    scan_node = d.mission.root.find("scan")
    plan = d.plans["scan"]
    assert len(scan_node.children) == len(plan.waypoints_neu) == d.waypoints
    for k, (child, wp) in enumerate(zip(scan_node.children, plan.waypoints_neu, strict=True), start=1):
        assert child.type == "fly-to" and child.id == f"scan.wp{k}"
        assert child.params["fly_straight_line_flag"] is True and child.params["speed"] == "standard"
        back = plan_point(child.params["position"], INDOOR.home)
        assert math.dist(back, wp) < 0.01
        assert d.plans[child.id].position_neu == wp and d.plans[child.id].extra["waypoint"] == k
    # the expanded tree dumps and loads again (spec's "expansion" key)
    again = mission_from_dict(json.loads(json.dumps(mission_to_dict(d.mission))))
    assert len(again.root.find("scan").children) == len(scan_node.children)


def test_to_dict_is_json_with_each_nodes_plan() -> None:
    d = delegate(load_mission(SCAN_AND_SEARCH), INDOOR)
    data = json.loads(json.dumps(d.to_dict()))
    assert data["accepted"] is True and data["platform"] == "indoor" and data["nodes"] == 5 + d.waypoints
    scan = data["tree"]["children"][1]
    assert scan["id"] == "scan" and len(scan["plan"]["waypoints_neu"]) == d.waypoints
    assert scan["expansion"][0]["plan"]["task"] == "fly-to"
    assert data["tree"]["children"][0]["plan"]["altitude_m"] == 2.0


def test_free_parameters_are_fixed_and_written_into_the_delegated_copy() -> None:
    m = mission({"type": "scan-ground", "id": "scan",
                 "params": {"area": area(2, -3, 8, 3), "speed": "slow | standard",
                            "altitude": "unspecified"}},
                fly_to("go", 5, 5, 3.0, commanded_speed={"interval": [1.0, 5.0]}), fly_to("walk", 3, 3, 2.0))
    d = delegate(m, INDOOR)
    assert d.accepted, d.reasons
    assert d.fixed["walk.speed"] == "standard" and d.plans["walk"].speed_m_s == INDOOR.speeds["standard"]
    assert d.fixed["scan.speed"] == "standard" and d.fixed["scan.altitude"] == "standard"
    assert 1.0 <= d.fixed["go.commanded_speed"] <= INDOOR.max_speed[0]
    node = d.mission.root.find("go")
    assert node.params["commanded_speed"] == d.fixed["go.commanded_speed"] == d.plans["go"].speed_m_s
    assert d.mission.root.find("scan").params["speed"] == "standard"


def test_a_short_endurance_makes_the_solver_fly_the_free_speeds_faster() -> None:
    free = {"type": "scan-ground", "id": "scan",
            "params": {"area": area(2, -4, 10, 4), "speed": "standard | fast"}}
    relaxed = delegate(mission(free), INDOOR)
    assert relaxed.accepted and relaxed.fixed["scan.speed"] == "standard"
    # endurance 3 s short of the flight at standard speed: fast is needed, and enough
    percent = (relaxed.expected_s - 3 + INDOOR.reserve_s) / INDOOR.battery_capacity_s * 100
    tight = delegate(mission(free), INDOOR.with_battery(percent))
    assert tight.accepted, tight.reasons
    assert tight.fixed["scan.speed"] == "fast" and tight.plans["scan"].speed_m_s == INDOOR.speeds["fast"]
    assert tight.expected_s <= INDOOR.with_battery(percent).endurance_s + 1e-6


def test_control_nodes_are_delegated_like_any_subtree() -> None:
    m = mission_from_yaml(f"""
mission: search
tree:
  type: S
  children:
    - {{type: take-off}}
    - type: WHILE
      condition: "not_seen(?x)"
      body: {{type: scan-ground, id: sweep, params: {{area: {area(2, -3, 6, 3)}}}}}
    - type: IF
      condition: "visible(?x), object(?x, person)"
      then: {{type: hover, id: look, params: {{duration: 10, position: {geo(4, 0, 2.0)}}}}}
      else: {{type: wait, id: pause, params: {{duration: 4}}}}
    - type: C
      children:
        - {{type: request-operator-assistance, params: {{message: "person found"}}}}
        - {{type: wait, params: {{duration: 3}}}}
    - {{type: land}}
""")
    d = delegate(m, INDOOR)
    assert d.accepted, d.reasons
    assert d.plans["look"].duration_s == 10 and d.plans["pause"].expected_s == 4
    assert len(d.plans["sweep"].waypoints_neu) == len(d.mission.root.find("sweep").children) > 0
    # IF counts its longer branch, C its longer child, WHILE one pass
    leaves = {i: d.plans[i].expected_s for i in ("n2", "sweep", "look")}
    assert d.expected_s >= sum(leaves.values()) + 3


def test_relations_between_parameters_and_platform_quantities() -> None:
    m = mission(fly_to("go", 5, 5, 3.0, commanded_speed="commanded_speed <= 0.5 * max_speed"),
                {"type": "wait", "id": "w", "params": {"duration": {"interval": [2, 6]}}})
    d = delegate(m, INDOOR)
    assert d.accepted, d.reasons
    assert min(INDOOR.speeds.values()) <= d.fixed["go.commanded_speed"] <= 0.5 * INDOOR.max_speed[0] + 1e-9
    assert d.fixed["w.duration"] == pytest.approx(4.0) and d.plans["w"].duration_s == pytest.approx(4.0)
    bad = delegate(mission(fly_to("go", 5, 5, 3.0, commanded_speed="commanded_speed <= fuel")), INDOOR)
    assert not bad.accepted and "unknown name 'fuel'" in bad.reasons[0]


def test_waypoint_scan_with_any_order_is_planned_in_a_shorter_order_and_passes_its_flags_on() -> None:
    """Delegation orders the waypoints by the shorter path (``any_order_flag``) and passes ``repeat_flag``,
    ``loiter_mode`` and the data's uuid on to the executor in the plan, as given. Flying ``loiter_mode`` is
    not checked here: the waypoints planned for ``stop`` are those planned for ``pass``."""
    wps = [geo(10, 0), geo(2, 0), geo(8, 0), geo(4, 0)]
    params = {"waypoints_scan_flag": True, "waypoints": wps, "any_order_flag": True, "repeat_flag": True,
              "loiter_mode": "stop", "data_uuid": "p1"}
    d = delegate(mission({"type": "scan-ground", "id": "patrol", "params": params}), INDOOR)
    assert d.accepted, d.reasons
    plan = d.plans["patrol"]
    norths = [round(w[0]) for w in plan.waypoints_neu]
    assert norths == [2, 4, 8, 10]
    assert plan.extra["repeat"] is True and plan.extra["loiter_mode"] == "stop"
    assert plan.extra["data_uuid"] == "p1"
    assert all(w[2] == INDOOR.altitudes["standard"] for w in plan.waypoints_neu)
    passing = delegate(mission({"type": "scan-ground", "id": "patrol",
                                "params": {**params, "loiter_mode": "pass"}}), INDOOR).plans["patrol"]
    assert passing.waypoints_neu == plan.waypoints_neu and passing.extra["loiter_mode"] == "pass"


# --- the five rejections -------------------------------------------------------------------------------


def test_rejects_a_waypoint_outside_the_fence() -> None:
    d = delegate(mission(fly_to("far", 35, 0, 2.0)), INDOOR)
    assert not d.accepted and d.plans == {}
    assert len(d.reasons) == 1
    assert "node far (fly-to)" in d.reasons[0] and "outside the fence" in d.reasons[0]
    assert "35.0 m north" in d.reasons[0]


def test_rejects_a_scan_area_outside_the_fence() -> None:
    big = {"type": "scan-ground", "id": "big", "params": {"area": area(0, 0, 30, 10)}}
    d = delegate(mission(big), INDOOR)
    assert not d.accepted and "node big (scan-ground): area outside the fence" in d.reasons[0]


def test_rejects_a_straight_leg_that_leaves_a_non_convex_fence() -> None:
    from companion.flight.limits import Envelope

    ell = Envelope([(0, -1), (20, -1), (20, 1), (1, 1), (1, 20), (0, 20)], altitude_ceiling=10)  # an L
    platform = dataclasses.replace(INDOOR, envelope=ell)
    d = delegate(mission(fly_to("a", 15, 0, 2.0), fly_to("b", 0.5, 15, 2.0)), platform)
    assert not d.accepted and any("node b (fly-to): flight outside the fence" in r for r in d.reasons)


def test_rejects_a_mission_longer_than_the_endurance() -> None:
    d = delegate(load_mission(SCAN_AND_SEARCH), INDOOR.with_battery(20))  # 120 s - 60 s reserve
    assert not d.accepted and len(d.reasons) == 1
    assert d.reasons[0].startswith("mission longer than the endurance")
    assert "60 s left" in d.reasons[0]
    assert ENDURANCE_LABEL in d.solution.conflict


def test_rejects_an_unknown_task_the_platform_has_no_executor_for() -> None:
    platform = INDOOR.with_tasks(tuple(t for t in leaf_type_names() if t != "external-velocity"))
    d = delegate(mission({"type": "external-velocity", "id": "stick"}), platform)
    assert not d.accepted
    assert d.reasons == [f"node stick (external-velocity): unknown task: platform indoor has no executor for "
                         f"'external-velocity' (it runs: {', '.join(platform.tasks)})"]


def test_rejects_a_missing_sensor() -> None:
    d = delegate(mission({"type": "scan-ground", "id": "lidar",
                          "params": {"area": area(2, -3, 6, 3), "sensor_type": "laser"}}), INDOOR)
    assert not d.accepted
    assert d.reasons == ["node lidar (scan-ground): missing sensor: sensor_type laser, but platform indoor "
                         "has "
                         "no laser (sensors: camera)"]


@pytest.mark.parametrize("up, words", [(-1.0, "is negative"), (15.0, "above the ceiling 10 m"),
                                       (0.5, "below the floor 1 m")])
def test_rejects_a_bad_fly_to_altitude(up: float, words: str) -> None:
    d = delegate(mission(fly_to("hop", 5, 5, up)), INDOOR)
    assert not d.accepted and len(d.reasons) == 1
    assert d.reasons[0].startswith("node hop (fly-to): bad altitude: position altitude")
    assert words in d.reasons[0]


def test_rejects_a_scan_altitude_above_the_fence_ceiling_naming_the_constraints() -> None:
    platform = dataclasses.replace(INDOOR, autopilot_params={"FENCE_ALT_MAX": 2.5})
    d = delegate(mission({"type": "scan-ground", "id": "scan",
                          "params": {"area": area(2, -3, 6, 3), "altitude": "high"}}), platform)
    assert not d.accepted and d.reasons[0].startswith("bad altitude: constraints in conflict")
    assert {"scan.altitude = high (given)", "scan.altitude <= ceiling 2.5 m (FENCE_ALT_MAX)"} <= set(
        d.solution.conflict)
    assert "scan.altitude = high (given)" in d.reasons[0]


def test_rejects_a_speed_above_the_autopilot_limit() -> None:
    d = delegate(mission(fly_to("rush", 5, 5, 2.0, commanded_speed=5.0)), INDOOR)
    assert not d.accepted and d.reasons[0].startswith(
        "node rush (fly-to): bad speed: commanded_speed 5 m/s is above the envelope's speed limit 2 m/s "
        "(WPNAV_SPEED)")


def test_rejects_follow_ground_without_a_range_sensor() -> None:
    low = fly_to("low", 5, 5, 2.0, follow_ground_flag=True, follow_ground_altitude=1.5)
    d = delegate(mission(low), INDOOR)
    assert not d.accepted and "node low (fly-to): no range sensor" in d.reasons[0]
    ranged = dataclasses.replace(INDOOR, range_sensor=True)
    assert delegate(mission(fly_to("low", 5, 5, 2.0, follow_ground_flag=True, follow_ground_altitude=1.5)),
                    ranged).accepted


def test_several_problems_are_all_reported() -> None:
    d = delegate(mission(fly_to("far", 35, 0, 2.0), fly_to("high", 1, 1, 12.0)), INDOOR)
    assert not d.accepted and len(d.reasons) == 2
    assert "far" in d.reasons[0] and "high" in d.reasons[1]


# --- the executor methods one by one ---------------------------------------------------------------------


def test_check_of_one_node() -> None:
    assert check(TstNode("fly-to", {"position": geo(3, 3, 2.0)}, id="ok"), INDOOR) == []
    assert check(TstNode("S", children=[TstNode("take-off")]), INDOOR) == []
    bad = check(TstNode("scan-ground", {"waypoints_scan_flag": True,
                                        "waypoints": [geo(1, 1), geo(2, 2), geo(3, 3)],
                                        "segment_flag": True}, id="s"), INDOOR)
    assert bad == ["node s (scan-ground): bad parameters: segment_flag needs an even number of waypoints "
                   "(pairs)"]


def test_get_constraints_labels_name_the_node_and_the_limit() -> None:
    p = ConstraintProblem()
    node = TstNode("scan-ground", {"area": area(2, -3, 6, 3), "speed": "fast"}, id="n3")
    get_constraints(node, INDOOR, p)
    assert "n3.altitude <= ceiling 10 m (FENCE_ALT_MAX)" in p.labels
    assert "n3.altitude >= floor 1 m (altitude_min)" in p.labels
    assert "n3.speed <= max speed 2 m/s (WPNAV_SPEED)" in p.labels
    assert "n3.speed = fast (given)" in p.labels
    sol = p.solve(prefer="standard")
    assert sol.ok and sol.choices == {"n3.speed": "fast", "n3.altitude": "standard"}


def test_expand_appends_children_and_other_tasks_do_not_expand() -> None:
    node = TstNode("scan-ground", {"area": area(2, -3, 6, 3)}, id="sc")
    root = TstNode("S", children=[node])
    values = dict(node.params, altitude_m=2.0, speed="slow")
    kids = expand(node, INDOOR, values)
    assert kids and node.children == kids and all(k.parent is node for k in kids)
    assert {k.params["speed"] for k in kids} == {"slow"}
    assert root.find("sc.wp1") is kids[0]
    assert expand(TstNode("take-off"), INDOOR, {}) == []


# --- taskflight mission check ----------------------------------------------------------------------------


def test_cli_mission_check_accepts_scan_and_search(capsys: pytest.CaptureFixture[str]) -> None:
    from taskflight.cli import main

    assert main(["mission", "check", str(SCAN_AND_SEARCH)]) == 0
    out = capsys.readouterr().out
    assert "ACCEPTED" in out and "scan waypoints: 10" in out and "expected duration" in out
    assert "scan (scan-ground): 1 m/s, alt 2 m, 10 waypoints" in out


def test_cli_mission_check_json_and_free_parameters(tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    from taskflight.cli import main

    f = tmp_path / "m.yaml"
    f.write_text(f"mission: free\ntree:\n  type: S\n  children:\n    - {{type: take-off}}\n"
                 f"    - {{type: scan-ground, id: sc,\n"
                 f"       params: {{area: {area(2, -3, 6, 3)}, speed: 'slow | standard'}}}}\n"
                 f"    - {{type: land}}\n")
    assert main(["mission", "check", str(f), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["accepted"] and data["fixed"] == {"sc.speed": "standard", "sc.altitude": "standard"}
    assert data["tree"]["children"][1]["params"]["speed"] == "standard"
    assert main(["mission", "check", str(f)]) == 0
    assert "free parameters fixed: sc.speed = standard, sc.altitude = standard" in capsys.readouterr().out


def test_cli_mission_check_rejects_with_reasons_and_exit_1(capsys: pytest.CaptureFixture[str]) -> None:
    from taskflight.cli import main

    assert main(["mission", "check", str(SCAN_AND_SEARCH), "--battery", "15"]) == 1
    out = capsys.readouterr().out
    assert "REJECTED" in out and "  - mission longer than the endurance" in out
    assert main(["mission", "check", str(SCAN_AND_SEARCH), "--profile", "outdoor"]) == 1
    assert "bad altitude" in capsys.readouterr().out


def test_cli_mission_check_bad_files_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from taskflight.cli import main

    bad = tmp_path / "bad.yaml"
    bad.write_text("mission: x\ntree:\n  type: S\n  children:\n    - {type: teleport}\n")
    assert main(["mission", "check", str(bad)]) == 2
    err = capsys.readouterr().err
    assert f"{bad}:5: tree.children[0].type: unknown task type 'teleport'" in err
    plat = tmp_path / "p.yaml"
    plat.write_text("platform: p\nhome: [0, 0]\nspeeds: fast\n")
    assert main(["mission", "check", str(SCAN_AND_SEARCH), "--platform", str(plat)]) == 2
    assert f"{plat}:3: speeds:" in capsys.readouterr().err
    assert main(["mission", "check", str(SCAN_AND_SEARCH), "--battery", "150"]) == 2


def test_cli_mission_check_with_a_platform_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from taskflight.cli import main

    plat = tmp_path / "p.yaml"
    plat.write_text((ROOT / "mission_specs" / "platform_indoor.yaml").read_text().replace(
        "tasks: [take-off, fly-to, land,", "tasks: [take-off, fly-to,"))
    assert main(["mission", "check", str(SCAN_AND_SEARCH), "--platform", str(plat)]) == 1
    assert "node land (land): unknown task" in capsys.readouterr().out
