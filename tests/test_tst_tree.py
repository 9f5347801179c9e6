"""TST trees (seed 000 Sec. III, Fig. 2) and the leaf task types of Fig. 11a-14a."""

from __future__ import annotations

import pytest

from companion.tst.params import Interval, ParamError, Qualitative
from companion.tst.registry import leaf_type, leaf_type_names
from companion.tst.tree import TreeError, TstNode, check_structure, param_to_json

POS = [58.3951, 15.5733, 3.0]
AREA = [[58.3950, 15.5730], [58.3950, 15.5732], [58.3951, 15.5731]]


def mission_tree() -> TstNode:
    return TstNode("S", children=[
        TstNode("take-off"),
        TstNode("scan-ground", {"area": AREA, "speed": "standard"}),
        TstNode("fly-to", {"position": POS, "speed": "fast"}),
        TstNode("land"),
    ])


def test_registry_matches_the_papers_parameter_tables() -> None:
    assert leaf_type("take-off").param_names == ()
    assert set(leaf_type("fly-to").param_names) == {
        "position", "commanded_speed", "speed", "follow_ground_flag", "follow_ground_altitude",
        "fly_straight_line_flag"}
    assert set(leaf_type("land").param_names) == {"position", "land_at_current_position_flag"}
    assert set(leaf_type("scan-ground").param_names) == {
        "area", "waypoints_scan_flag", "waypoints", "loiter_mode", "segment_flag", "any_order_flag", "speed",
        "altitude", "follow_ground_flag", "follow_ground_altitude", "repeat_flag", "sensor_type", "data_uuid",
        "generate_scan_specs_flag",
        "commanded_speed", "commanded_altitude"}  # ours: a team task's speed and altitude, in numbers
    scan = leaf_type("scan-ground")
    assert scan.param("sensor_type").options == ("artva", "laser", "camera")  # type: ignore[union-attr]
    assert scan.param("altitude").options == ("high", "standard", "low", "unspecified")  # type: ignore[union-attr]
    assert leaf_type("fly-to").param("speed").options == ("slow", "standard", "fast")  # type: ignore[union-attr]
    assert leaf_type("wait").param("duration").unit == "s"  # type: ignore[union-attr]
    assert {"hover", "request-operator-assistance", "external-velocity"} <= set(leaf_type_names())


def test_auto_ids_in_preorder_and_parents() -> None:
    root = mission_tree()
    assert [n.id for n in root.iter()] == ["n1", "n2", "n3", "n4", "n5"]
    assert [n.type for n in root.iter()] == ["S", "take-off", "scan-ground", "fly-to", "land"]
    scan = root.find("n3")
    assert scan is not None and scan.parent is root and scan.root is root
    assert [n.id for n in scan.path()] == ["n1", "n3"]
    assert root.find("nope") is None


def test_explicit_ids_are_kept_and_skipped_by_auto_ids() -> None:
    root = TstNode("S", id="n2", children=[TstNode("take-off"), TstNode("land", id="touchdown")])
    assert [n.id for n in root.iter()] == ["n2", "n1", "touchdown"]


def test_duplicate_ids_refused() -> None:
    with pytest.raises(TreeError, match="duplicate node id 'a'"):
        TstNode("S", children=[TstNode("take-off", id="a"), TstNode("land", id="a")])


def test_unknown_type_lists_known_types() -> None:
    with pytest.raises(TreeError, match=r"unknown task type 'jump' \(known: S, C, IF, WHILE, take-off"):
        TstNode("jump")


def test_leaf_params_are_checked_and_defaults_filled() -> None:
    node = TstNode("fly-to", {"position": POS, "commanded-speed": 2})
    assert node.params["position"] == tuple(POS)
    assert node.params["commanded_speed"] == 2.0
    assert node.params["fly_straight_line_flag"] is False
    with pytest.raises(ParamError, match="unknown parameter of fly-to") as exc:
        TstNode("fly-to", {"position": POS, "altitude": 3})
    assert exc.value.field == "altitude"
    with pytest.raises(ParamError, match="missing required parameter") as exc:
        TstNode("fly-to", {"speed": "fast"})
    assert exc.value.field == "position"
    with pytest.raises(ParamError, match="not both"):
        TstNode("fly-to", {"position": POS, "speed": "fast", "commanded_speed": 2})
    with pytest.raises(ParamError, match="expected one of slow, standard, fast"):
        TstNode("fly-to", {"position": POS, "speed": "ludicrous"})
    with pytest.raises(ParamError, match="must be >= 0 s"):
        TstNode("wait", {"duration": -1})


def test_free_parameters() -> None:
    node = TstNode("fly-to", {"position": POS, "commanded_speed": {"interval": [1, 3]}})
    assert node.free_params() == {"commanded_speed": Interval(1, 3)}
    scan = TstNode("scan-ground", {"area": AREA, "speed": "slow | standard"})
    assert scan.free_params() == {"speed": Qualitative(("slow", "standard"))}
    wait = TstNode("wait", {"duration": "duration <= endurance_left"})
    assert set(wait.free_params()) == {"duration"}
    with pytest.raises(ParamError, match="unknown value 'warp'"):
        TstNode("scan-ground", {"area": AREA, "speed": "slow | warp"})
    with pytest.raises(ParamError, match="does not mention duration"):
        TstNode("wait", {"duration": "altitude <= 3"})
    with pytest.raises(ParamError, match="interval given for a qualitative"):
        TstNode("scan-ground", {"area": AREA, "speed": {"interval": [1, 2]}})
    with pytest.raises(ParamError, match="goes below the minimum"):
        TstNode("wait", {"duration": {"interval": [-1, 2]}})


def test_land_alternatives_of_fig_13() -> None:
    assert TstNode("land").params == {"land_at_current_position_flag": True}
    at = TstNode("land", {"position": POS})
    assert at.params["land_at_current_position_flag"] is False
    with pytest.raises(ParamError, match="required when land_at_current_position_flag is false"):
        TstNode("land", {"land_at_current_position_flag": False})
    with pytest.raises(ParamError, match="land_at_current_position_flag is true"):
        TstNode("land", {"land_at_current_position_flag": True, "position": POS})


def test_scan_ground_area_or_waypoints() -> None:
    scan = TstNode("scan-ground", {"area": AREA})
    assert scan.params["speed"] == "unspecified" and scan.params["sensor_type"] == "camera"
    wp = TstNode("scan-ground", {"waypoints_scan_flag": True, "waypoints": [[58.0, 15.0], [58.1, 15.0]],
                                 "any_order_flag": True})
    assert wp.params["loiter_mode"] == "pass" and wp.params["any_order_flag"] is True
    with pytest.raises(ParamError, match="only with waypoints_scan_flag"):
        TstNode("scan-ground", {"area": AREA, "segment_flag": True})
    with pytest.raises(ParamError, match="required when waypoints_scan_flag is true"):
        TstNode("scan-ground", {"waypoints_scan_flag": True})
    with pytest.raises(ParamError) as exc:
        TstNode("scan-ground", {})
    assert exc.value.field == "area"
    with pytest.raises(ParamError, match="required when follow_ground_flag is true"):
        TstNode("scan-ground", {"area": AREA, "follow_ground_flag": True})


def test_control_node_rules() -> None:
    with pytest.raises(TreeError, match="at most 1 child"):
        TstNode("WHILE", condition="visible(?x)", children=[TstNode("wait", {"duration": 1}),
                                                              TstNode("wait", {"duration": 1})])
    with pytest.raises(TreeError, match="only IF and WHILE"):
        TstNode("S", condition="visible(?x)")
    with pytest.raises(TreeError, match="has no parameters"):
        TstNode("S", {"speed": 1})
    with pytest.raises(TreeError, match="needs at least 1 child"):
        check_structure(TstNode("C"))
    with pytest.raises(TreeError, match="needs a condition"):
        check_structure(TstNode("IF", children=[TstNode("land")]))
    iff = TstNode("IF", condition="visible(?x)", children=[TstNode("hover"), TstNode("land")])
    check_structure(iff)
    assert iff.then is iff.children[0] and iff.else_ is iff.children[1] and iff.body is None


def test_append_child_for_expand_keeps_ids_and_takes_next_free() -> None:
    root = mission_tree()
    scan = root.find("n3")
    assert scan is not None
    expansion = TstNode("S", children=[TstNode("fly-to", {"position": POS}),
                                       TstNode("fly-to", {"position": POS})])
    scan.append_child(expansion)
    assert [n.id for n in root.iter()] == ["n1", "n2", "n3", "n6", "n7", "n8", "n4", "n5"]
    assert expansion.parent is scan and expansion.root is root
    assert [n.id for n in expansion.children[1].path()] == ["n1", "n3", "n6", "n8"]


def test_append_child_refuses_duplicates_and_leaves_tree_unchanged() -> None:
    root = mission_tree()
    before = [n.id for n in root.iter()]
    with pytest.raises(TreeError, match="duplicate node id 'n2'"):
        root.append_child(TstNode("wait", {"duration": 1}, id="n2"))
    assert [n.id for n in root.iter()] == before
    with pytest.raises(TreeError, match="already has a parent"):
        root.append_child(root.children[0])
    loop = TstNode("WHILE", condition="visible(?x)", children=[TstNode("hover")])
    with pytest.raises(TreeError, match="at most 1 child"):
        loop.append_child(TstNode("land"))
    assert len(loop.children) == 1


def test_to_dict_is_json_ready() -> None:
    root = TstNode("S", children=[
        TstNode("IF", condition="visible(?x)", children=[TstNode("hover", {"duration": 3})]),
        TstNode("fly-to", {"position": POS, "commanded_speed": {"interval": [1, 2]}}),
    ])
    d = root.to_dict()
    assert d["type"] == "S" and d["id"] == "n1"
    assert d["children"][0] == {"id": "n2", "type": "IF", "condition": "visible(?x)",
                                "then": {"id": "n3", "type": "hover", "params": {"duration": 3.0}}}
    fly = d["children"][1]["params"]
    assert fly["position"] == POS and fly["commanded_speed"] == {"interval": [1.0, 2.0]}
    assert param_to_json(((1.0, 2.0), (3.0, 4.0))) == [[1.0, 2.0], [3.0, 4.0]]


def test_behaviors_layer_types_and_external_velocity() -> None:
    assert TstNode("hover").params == {}
    assert TstNode("hover", {"duration": 4, "position": POS}).params["duration"] == 4.0
    assert TstNode("external-velocity").params == {"source": "joystick"}
    ask = TstNode("request-operator-assistance", {"message": "person at the fence"})
    assert ask.params == {"message": "person at the fence"}
    with pytest.raises(ParamError, match="missing required parameter") as exc:
        TstNode("request-operator-assistance")
    assert exc.value.field == "message"


@pytest.mark.parametrize("node_type, params", [
    ("fly-to", {"position": POS, "commanded_speed": {"interval": [1, 3]}, "follow_ground_flag": True,
                "follow_ground_altitude": 2.0}),
    ("land", {"position": POS}),
    ("scan-ground", {"waypoints_scan_flag": True, "waypoints": [[58.0, 15.0, 3.0]], "speed": "slow | fast"}),
    ("scan-ground", {"area": AREA, "data_uuid": "u1", "generate_scan_spec_flag": True}),
    ("wait", {"duration": "duration <= endurance_left"}),
])
def test_validation_is_idempotent(node_type: str, params: dict) -> None:
    """Building a node from another node's normalized parameters gives the same parameters (expand copies)."""
    node = TstNode(node_type, params)
    assert TstNode(node_type, dict(node.params)).params == node.params
