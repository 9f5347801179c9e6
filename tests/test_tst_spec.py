"""The mission YAML / JSON format (companion/tst/spec.py): loading, round trip, located errors."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from companion.tst.params import Interval, LinearRelation
from companion.tst.spec import load_mission, mission_from_dict, mission_from_yaml, mission_to_dict
from taskflight_common.yamlio import ConfigError

SPECS = Path(__file__).resolve().parents[1] / "mission_specs"

GOOD = """\
mission: scan-and-search
tree:
  type: S
  children:
    - {type: take-off}
    - type: scan-ground
      params: {area: [[58.3950, 15.5730], [58.3950, 15.5732], [58.3951, 15.5731]],
               speed: standard, altitude: standard, sensor_type: camera}
    - type: WHILE
      id: search
      condition: "visible(?x), object(?x, person)"
      body: {type: hover, params: {duration: 5}}
    - type: IF
      condition: "visible(?x)"
      then: {type: request-operator-assistance, params: {message: "person found"}}
      else: {type: wait, params: {duration: "duration <= endurance_left"}}
    - {type: fly-to, params: {position: [58.3951, 15.5733, 3.0], speed: fast, fly_straight_line_flag: true}}
    - {type: land, params: {land_at_current_position_flag: true}}
"""


def error_of(text: str) -> ConfigError:
    with pytest.raises(ConfigError) as exc:
        mission_from_yaml(text, "m.yaml")
    return exc.value


def test_good_mission_loads() -> None:
    m = mission_from_yaml(GOOD, "m.yaml")
    assert m.name == "scan-and-search"
    types = [n.type for n in m.root.iter()]
    assert types == ["S", "take-off", "scan-ground", "WHILE", "hover", "IF", "request-operator-assistance",
                     "wait", "fly-to", "land"]
    loop = m.root.find("search")
    assert loop is not None and loop.condition == "visible(?x), object(?x, person)"
    assert loop.body is not None and loop.body.params["duration"] == 5.0
    iff = m.root.children[3]
    assert iff.then is not None and iff.then.type == "request-operator-assistance"
    assert iff.else_ is not None and isinstance(iff.else_.params["duration"], LinearRelation)
    assert m.root.children[4].params["position"] == (58.3951, 15.5733, 3.0)


def test_round_trip_through_json() -> None:
    m = mission_from_yaml(GOOD, "m.yaml")
    d = mission_to_dict(m)
    again = mission_from_dict(json.loads(json.dumps(d)))
    assert mission_to_dict(again) == d
    assert [n.id for n in again.root.iter()] == [n.id for n in m.root.iter()]


def test_expanded_tree_round_trips() -> None:
    from companion.tst.tree import TstNode

    m = mission_from_yaml(GOOD, "m.yaml")
    scan = m.root.children[1]
    scan.append_child(TstNode("S", children=[TstNode("fly-to", {"position": [58.3950, 15.5731, 2.0]})]))
    d = mission_to_dict(m)
    assert d["tree"]["children"][1]["expansion"][0]["type"] == "S"
    again = mission_from_dict(d)
    assert [n.id for n in again.root.iter()] == [n.id for n in m.root.iter()]
    assert again.root.find(scan.id).children[0].children[0].type == "fly-to"  # type: ignore[union-attr]


@pytest.mark.parametrize("path", sorted(SPECS.glob("scan_and_search*.yaml")), ids=lambda p: p.name)
def test_shipped_missions_load(path: Path) -> None:
    m = load_mission(path)
    assert [n.type for n in m.root.children] == ["take-off", "scan-ground", "fly-to", "land"]


def test_unknown_node_type() -> None:
    err = error_of("mission: m\ntree:\n  type: S\n  children:\n    - {type: take-off}\n    - {type: jump}\n")
    assert err.line == 6 and err.field == "tree.children[1].type"
    assert "unknown task type 'jump' (known: S, C, IF, WHILE, take-off" in err.reason
    assert str(err).startswith("m.yaml:6: tree.children[1].type: unknown task type 'jump'")


def test_unknown_keys_at_top_and_in_a_node() -> None:
    err = error_of("mission: m\nmision: x\ntree: {type: take-off}\n")
    assert err.line == 2 and err.field == "mision" and "unknown field" in err.reason
    err = error_of("mission: m\ntree:\n  type: take-off\n  children: []\n")
    assert err.line == 4 and err.field == "tree.children"
    err = error_of("mission: m\ntree:\n  type: S\n  params: {}\n  children: [{type: land}]\n")
    assert err.line == 4 and err.field == "tree.params"


def test_unknown_parameter_of_task_type() -> None:
    err = error_of("mission: m\ntree:\n  type: fly-to\n  params:\n    position: [58, 15, 2]\n"
                   "    altitude: 3\n")
    assert err.line == 6 and err.field == "tree.params.altitude"
    assert "unknown parameter of fly-to (known: position" in err.reason


def test_missing_required_parameter() -> None:
    err = error_of("mission: m\ntree:\n  type: S\n  children:\n    - type: fly-to\n"
                   "      params: {speed: fast}\n")
    assert err.line == 6 and err.field == "tree.children[0].params.position"
    assert "missing required parameter of fly-to" in err.reason
    err = error_of("mission: m\ntree:\n  type: wait\n")
    assert err.field == "tree.params.duration" and err.line == 3


def test_bad_geopoints_name_the_line_of_the_vertex() -> None:
    err = error_of("mission: m\ntree:\n  type: fly-to\n  params: {position: [58, 15]}\n")
    assert err.line == 4 and err.field == "tree.params.position" and "[lat, lon, alt]" in err.reason
    err = error_of("mission: m\ntree:\n  type: fly-to\n  params: {position: [95, 15, 2]}\n")
    assert "latitude 95 out of range" in err.reason
    text = ("mission: m\ntree:\n  type: scan-ground\n  params:\n    area:\n      - [58.0, 15.0]\n"
            "      - [58.0, 195.0]\n      - [58.1, 15.0]\n")
    err = error_of(text)
    assert err.line == 7 and err.field == "tree.params.area" and "geopoint 1: longitude 195" in err.reason


def test_control_node_without_children() -> None:
    err = error_of("mission: m\ntree:\n  type: S\n  children: []\n")
    assert err.line == 4 and "at least one child" in err.reason
    err = error_of("mission: m\ntree:\n  type: C\n")
    assert err.line == 3 and err.field == "tree" and "needs children" in err.reason
    err = error_of("mission: m\ntree:\n  type: WHILE\n  condition: visible(?x)\n")
    assert "needs a body" in err.reason


def test_if_while_without_or_with_bad_condition() -> None:
    err = error_of("mission: m\ntree:\n  type: IF\n  then: {type: land}\n")
    assert err.line == 3 and err.field == "tree" and "needs a condition" in err.reason
    err = error_of("mission: m\ntree:\n  type: WHILE\n  condition: 'visible(?x) object(?x, person)'\n"
                   "  body: {type: hover}\n")
    assert err.line == 4 and err.field == "tree.condition"
    assert "column" in err.reason  # the BeliefError's text


def test_duplicate_ids_name_both_lines() -> None:
    text = ("mission: m\ntree:\n  type: S\n  children:\n    - {type: take-off, id: a}\n"
            "    - type: land\n      id: a\n")
    err = error_of(text)
    assert err.line == 7 and err.field == "tree.children[1].id"
    assert "duplicate node id 'a' (first at line 5)" in err.reason


def test_constraint_values_in_yaml() -> None:
    m = mission_from_yaml("mission: m\ntree:\n  type: fly-to\n  params:\n    position: [58, 15, 2]\n"
                          "    commanded_speed: {interval: [1, 3]}\n", "m.yaml")
    assert m.root.params["commanded_speed"] == Interval(1, 3)
    err = error_of("mission: m\ntree:\n  type: fly-to\n  params:\n    position: [58, 15, 2]\n"
                   "    commanded_speed: 'speed < 3'\n")
    assert err.line == 6 and "use <=, >= or ==" in err.reason


def test_json_body_errors_have_the_field() -> None:
    with pytest.raises(ConfigError) as exc:
        mission_from_dict({"mission": "m", "tree": {"type": "S", "children": [{"type": "jump"}]}})
    assert exc.value.field == "tree.children[0].type" and exc.value.line is None
    with pytest.raises(ConfigError, match="missing required field 'mission'"):
        mission_from_dict({"tree": {"type": "land"}})
    with pytest.raises(ConfigError, match="expected a mapping"):
        mission_from_dict([1, 2])


def test_load_mission_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="cannot read file"):
        load_mission(tmp_path / "none.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("mission: m\ntree: {type: take-off, params: {altitude: 3}}\n")
    with pytest.raises(ConfigError) as exc:
        load_mission(bad)
    assert exc.value.file == str(bad) and exc.value.line == 2
