"""The behavior catalog (Fig. 5), activation requests (Sec. 5.1.1) and the process manager (Sec. 6.2.3)."""

from __future__ import annotations

import pytest

from companion.behaviors.activation import (
    ActivationError,
    ActivationRequest,
    check_format,
    format_activation,
    parse_activation,
    request_from,
)
from companion.behaviors.catalog import catalog_from_yaml, load_catalog
from companion.behaviors.processes import ExecutionProcess, ProcessError, ProcessManager
from taskflight_common.yamlio import ConfigError

GOOD = """\
behavior_descriptors:
- behavior: A
  category: goal_based
  parameters:
  - parameter: x
    type: number
    allowed_values: [0, 10]
- behavior: B
  category: recurrent
  default: yes
- behavior: C
  category: goal_based
compatibility_conditions:
- mutually_exclusive: [A, C]
- active: [B]
  before: [A]
"""


def test_bundled_catalog_loads() -> None:
    c = load_catalog()
    assert {"TAKE_OFF", "LAND", "KEEP_HOVERING", "GO_TO_POINT", "ROTATE", "KEEP_MOVING", "FOLLOW_PATH",
            "FOLLOW_EXTERNAL_VELOCITY", "REQUEST_OPERATOR_ASSISTANCE", "SELF_LOCALIZE"} <= set(c.names())
    assert c.incompatible("LAND", "GO_TO_POINT") and c.incompatible("LAND", "REQUEST_OPERATOR_ASSISTANCE")
    assert c.required_before("GO_TO_POINT") == {"SELF_LOCALIZE"}
    assert [d.behavior for d in c.defaults()] == ["SELF_LOCALIZE", "KEEP_HOVERING", "WATCH_GROUND"]
    assert c.priority("emergency") > c.priority("operator") > c.priority("mission") > c.priority("default")
    goto = c.get("GO_TO_POINT")
    assert goto.timeout_s is None and goto.timeout_plan == {"factor": 1.5, "margin_s": 20.0}
    assert goto.goal["tolerance_m"] == 1.0 and c.get("ROTATE").goal["tolerance_deg"] == 10.0
    moving = c.get("KEEP_MOVING")
    assert moving.timeout_s is None and not moving.timeout_plan  # no goal, no plan


@pytest.mark.parametrize(("text", "where"), [
    (GOOD.replace("  category: recurrent", "  category: recurrent\n  colour: red"),
     "c.yaml:10: behavior_descriptors[1].colour"),
    (GOOD.replace("    type: number\n", ""),
     "c.yaml:5: behavior_descriptors[0].parameters[0]: parameter 'x' has no type"),
    (GOOD.replace("type: number", "type: vector"), "c.yaml:6: behavior_descriptors[0].parameters[0].type"),
    (GOOD.replace("[0, 10]", "[10, 0]"), "c.yaml:7: behavior_descriptors[0].parameters[0].allowed_values"),
    (GOOD.replace("[A, C]", "[A, D]"),
     "c.yaml:14: compatibility_conditions[0].mutually_exclusive[1]: unknown behavior 'D'"),
    (GOOD + "- active: [A]\n  before: [B]\n", "c.yaml:17: compatibility_conditions: precedence loop"),
    (GOOD.replace("category: goal_based\n  parameters", "category: goalbased\n  parameters"),
     "c.yaml:3: behavior_descriptors[0].category"),
    (GOOD.replace("- behavior: C", "- behavior: A"), "behavior_descriptors[2].behavior: A described twice"),
    (GOOD + "- wanted: [A]\n", "c.yaml:17: compatibility_conditions[2]: expected 'mutually_exclusive'"),
    ("behavior_descriptors: [\n", "c.yaml:2: YAML syntax error"),
    (GOOD.replace("  category: recurrent", "  category: recurrent\n  timeout: 30"),
     "c.yaml:10: behavior_descriptors[1].timeout: a recurrent behavior has no goal"),
    (GOOD.replace("  category: goal_based\n  parameters", "  category: goal_based\n  timeout: {factor: 0.5}\n"
                  "  parameters"), "behavior_descriptors[0].timeout: factor must be at least 1"),
    (GOOD.replace("  category: goal_based\n  parameters", "  category: goal_based\n  goal: {tolerance: 1}\n"
                  "  parameters"), "behavior_descriptors[0].goal.tolerance"),
])
def test_bad_catalog_names_file_line_field(text: str, where: str) -> None:
    with pytest.raises(ConfigError) as exc:
        catalog_from_yaml(text, "c.yaml")
    assert where in str(exc.value)


def test_precedence_loop_over_three_behaviors() -> None:
    loop = GOOD + "- active: [A]\n  before: [C]\n- active: [C]\n  before: [B]\n"
    with pytest.raises(ConfigError, match=r"precedence loop: .*before.*before"):
        catalog_from_yaml(loop, "c.yaml")


def test_text_and_structured_forms_convert_both_ways() -> None:
    c = load_catalog()
    for text in ("TAKE_OFF", "ROTATE angle: 45", "GO_TO_POINT coordinate: (1, 2.5, 7)",
                 "FOLLOW_PATH path: ((0, 0, 5), (10, 0, 5)) speed: 2",
                 'REQUEST_OPERATOR_ASSISTANCE message: "look \\"here\\""'):
        req = parse_activation(text, "mission")
        assert format_activation(req.behavior, req.params) == text
        again = request_from({"behavior": req.behavior, "params": {k: list(v) if isinstance(v, tuple) else v
                                                                   for k, v in req.params.items()},
                              "requester": "mission"})
        assert check_format(c, again) == check_format(c, req)
    assert parse_activation("ROTATE angle: 45°").params == {"angle": 45}
    assert check_format(c, parse_activation("TAKE_OFF")) == {"altitude": 5.0}  # the catalog's default


@pytest.mark.parametrize(("text", "message"), [
    ("", "empty activation"),
    ("GO_TO_POINT coordinate: (1, 2", "unexpected end"),
    ("GO_TO_POINT coordinate (1, 2, 3)", "column 24: expected ':' after coordinate"),
    ("GO_TO_POINT coordinate: (1, 2, 3) coordinate: (1, 2, 3)", "coordinate: given twice"),
    ("GO_TO_POINT coordinate: (1; 2, 3)", "unexpected character ';'"),
    ("GO_TO_POINT coordinate: (1, 2)", "coordinate: expected 3 values, got 2"),
    ("GO_TO_POINT coordinate: (1, 2, 1001)", "outside the allowed range [-1000, 1000]"),
    ("GO_TO_POINT coordinate: (1, 2, up)", "expected a number"),
    ("GO_TO_POINT coordinate: 4", "expected 3 values like"),
    ("GO_TO_POINT coordinate: (1, 2, 3) height: 4", "GO_TO_POINT has no parameter 'height'"),
    ("GO_TO_POINT", "missing: GO_TO_POINT needs coordinate"),
    ("FLY", "unknown behavior 'FLY'"),
    ("ROTATE angle: (1, 2)", "angle: expected one value"),
    ("FOLLOW_PATH path: (1, 2, 3)", "path[0]: expected 3 values"),
])
def test_format_check_says_which_and_why(text: str, message: str) -> None:
    with pytest.raises(ActivationError) as exc:
        check_format(load_catalog(), parse_activation(text))
    assert message in str(exc.value)


def test_unknown_requester_is_refused() -> None:
    with pytest.raises(ActivationError, match="unknown requester 'pilot'"):
        check_format(load_catalog(), ActivationRequest("pilot", "TAKE_OFF"))


class _Proc(ExecutionProcess):
    def __init__(self, name: str, fail: bool = False) -> None:
        super().__init__()
        self.name = name
        self.fail = fail
        self.stops = 0

    def on_start(self) -> None:
        if self.fail:
            raise ProcessError(f"{self.name} cannot start")

    def on_stop(self) -> None:
        self.stops += 1


def test_reference_counts_and_delayed_stop() -> None:
    t = [0.0]
    log: list[dict] = []
    a, b, c = _Proc("motion"), _Proc("planner"), _Proc("camera", fail=True)
    pm = ProcessManager([a, b, c], lambda: t[0], sink=log.append)
    pm.request_start(["motion", "planner"], "GO_TO_POINT")
    t[0] = 9.0
    pm.release(["motion", "planner"], "GO_TO_POINT")  # informing unused: not stopped yet
    assert a.running and b.running
    pm.request_start(["motion"], "SEARCH_FRAME")
    assert pm.collect() == ["planner"]
    assert a.running and a.starts == 1 and a.stops == 0  # continuity: never restarted
    assert [(e["process"], e["event"], e["t"]) for e in log] == [
        ("motion", "start", 0.0), ("planner", "start", 0.0), ("planner", "stop", 9.0)]
    with pytest.raises(ProcessError, match="camera cannot start"):
        pm.request_start(["planner", "camera"], "TAKE_PHOTO")
    assert pm.references() == {"motion": 1, "planner": 0, "camera": 0}  # all or none
    assert not b.running
    with pytest.raises(ProcessError, match="unknown process 'lidar'"):
        pm.request_start(["lidar"], "X")
