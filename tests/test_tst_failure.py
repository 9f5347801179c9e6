"""Missions that fail safely and can be followed: retries, on_failure, resume, the event stream.

A real queue, executive layer and behaviors with the kinematic vehicle of :mod:`harness.behaviors`;
plans by hand (delegation has its own tests). The test leaf type ``guarded-fly-to``
(:mod:`harness.guarded_leaf`) fails at its start while the belief ``clearance(self, granted)`` does not
hold (a precondition the operator can fix), so a node fails for a reason the test controls.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from typing import Any

import pytest

from companion.tst.events import EventStream
from companion.tst.execution import TstExecutionSystem
from companion.tst.plan import NodePlan
from companion.tst.resume import ResumeError, remainder
from companion.tst.spec import mission_from_yaml, mission_to_dict
from companion.tst.status import ExecutionRequestError
from harness.behaviors import World
from harness.guarded_leaf import CLEARANCE, GuardedFlyTo, guarded_leaf
from taskflight_common.yamlio import ConfigError


@pytest.fixture
def guarded() -> Iterator[GuardedFlyTo]:
    with guarded_leaf() as leaf:
        yield leaf


def mission_text(on_failure: str = "land", retries: int = 2, parent_retries: int = 0) -> str:
    return f"""
mission: guarded
on_failure: {on_failure}
tree:
  type: S
  id: root
  children:
    - {{type: take-off, id: up}}
    - type: S
      id: leg
      retries: {parent_retries}
      children:
        - {{type: guarded-fly-to, id: go, retries: {retries},
            params: {{position: [-35.36, 149.16, 3], fly_straight_line_flag: true}}}}
    - {{type: land, id: down}}
"""


PLANS = [NodePlan("up", "take-off", altitude_m=3.0),
         NodePlan("go", "guarded-fly-to", position_neu=(6.0, 0.0, 3.0), speed_m_s=2.0),
         NodePlan("down", "land")]


class Run:
    def __init__(self, text: str) -> None:
        self.w = World()
        self.ts = TstExecutionSystem(self.w.layer)
        self.w.layer.cycle_listeners.append(self.ts.tick)
        self.ts.load(mission_from_yaml(text, "m.yaml"), {p.node_id: p for p in PLANS})

    def events(self, kind: str, node: str | None = None) -> list[dict[str, Any]]:
        return [e for e in self.ts.events.since(0)
                if e["event"] == kind and (node is None or e.get("node") == node)]


# --- the format ------------------------------------------------------------------------------------------
@pytest.mark.parametrize(("bad", "where"), [
    ("on_failure: lnd", "m.yaml:3: on_failure: must be one of hover, land, rtl"),
    ("retries: -1", "m.yaml:11: tree.children[1].retries: must be >= 0"),
    ("retries: many", "m.yaml:11: tree.children[1].retries: expected an integer"),
    ("retries: 11", "m.yaml:11: tree.children[1].retries: must be <= 10"),
])
def test_bad_failure_fields_name_file_line_and_field(guarded: GuardedFlyTo, bad: str, where: str) -> None:
    text = mission_text(parent_retries=0)
    text = text.replace("on_failure: land", bad) if bad.startswith("on_failure") else \
        text.replace("retries: 0", bad)
    with pytest.raises(ConfigError) as exc:
        mission_from_yaml(text, "m.yaml")
    assert str(exc.value).startswith(where), str(exc.value)


def test_failure_fields_round_trip(guarded: GuardedFlyTo) -> None:
    m = mission_from_yaml(mission_text("rtl", 3, 1), "m.yaml")
    assert m.on_failure == "rtl" and m.root.find("go").retries == 3  # type: ignore[union-attr]
    again = mission_from_yaml(__import__("yaml").safe_dump(mission_to_dict(m)), "again.yaml")
    assert again.on_failure == "rtl" and again.root.find("leg").retries == 1  # type: ignore[union-attr]
    default = mission_from_yaml(mission_text().replace("on_failure: land\n", ""), "m.yaml")
    assert default.on_failure == "hover" and "on_failure" not in mission_to_dict(default)


# --- retries and the policy ------------------------------------------------------------------------------
def test_a_failing_node_is_tried_again_then_the_mission_lands(guarded: GuardedFlyTo) -> None:
    r = Run(mission_text("land", retries=2))
    r.ts.start()
    r.w.run_until(lambda: not r.ts.running, 60, "the mission's end")
    failed = r.events("node_finished", "go")
    assert [e["state"] for e in failed] == ["failed"] * 3, failed
    assert all("no clearance" in e["reason"] for e in failed)
    assert [e["attempt"] for e in r.events("node_retry", "go")] == [2, 3]
    st = r.ts.status()
    assert st["state"] == "failed" and "no clearance" in st["fail_reason"] and st["failed_node"] == "go"
    go = next(c for c in next(c for c in st["tree"]["children"] if c["id"] == "leg")["children"])
    assert go["retries"] == 2 and go["attempt"] == 3
    (policy,) = r.events("on_failure")
    assert policy["policy"] == "land" and policy["applied"] and policy["behavior"] == "LAND"
    r.w.run_until(lambda: r.ts.status()["failure_policy"]["outcome"] != "active", 60, "LAND's end")
    assert r.w.pos_neu[2] < 0.05 and r.ts.status()["failure_policy"]["outcome"] == "goal_achieved"
    assert r.ts.status()["tree"]["children"][2]["state"] == "idle"  # the mission's own land never ran


def test_a_retried_parent_gives_its_children_their_retries_back(guarded: GuardedFlyTo) -> None:
    r = Run(mission_text("hover", retries=1, parent_retries=1))
    r.ts.start()
    r.w.run_until(lambda: not r.ts.running, 60, "the mission's end")
    assert len(r.events("node_finished", "go")) == 4  # (1 + 1 retry) for each of the 2 runs of "leg"
    assert [e["node"] for e in r.events("node_retry")] == ["go", "leg", "go"]
    (policy,) = r.events("on_failure")
    assert policy["policy"] == "hover" and policy["behavior"] == "KEEP_HOVERING"
    r.w.run(2.0)
    assert r.w.coordinator.is_active("KEEP_HOVERING") and r.w.pos_neu[2] > 2.5  # still in the air


def test_a_node_that_succeeds_on_a_retry_goes_on(guarded: GuardedFlyTo) -> None:
    r = Run(mission_text("land", retries=5))
    r.ts.start()
    r.w.run_until(lambda: len(r.events("node_retry", "go")) >= 1, 60, "a retry")
    assert r.ts.status()["tree"]["children"][1]["children"][0]["retry_at"] > r.w.sim.t  # held 1 s first
    r.w.beliefs.add(CLEARANCE)  # the operator fixes the cause before the next attempt
    r.w.run_until(lambda: not r.ts.running, 120, "the mission's end")
    assert r.ts.status()["state"] == "succeeded" and not r.events("on_failure")
    assert len(r.events("node_finished", "go")) == 2 and abs(r.w.pos_neu[0] - 6.0) < 0.2


def fly_to_mission() -> Run:
    r = Run(mission_text("land").replace("guarded-fly-to", "fly-to"))
    r.ts.plans["go"] = NodePlan("go", "fly-to", position_neu=(15.0, 0.0, 3.0), speed_m_s=1.0)
    r.ts.start()
    r.w.run_until(lambda: r.ts.active_node() == "go", 30, "the fly-to")
    r.w.run(2.0)
    return r


def test_abort_applies_the_missions_policy() -> None:
    r = fly_to_mission()
    r.ts.abort()
    assert r.ts.status()["state"] == "aborted" and r.ts.failed_node() == "go"
    (policy,) = r.events("on_failure")
    assert policy["policy"] == "land" and policy["applied"] and "aborted: operator" in policy["cause"]
    r.w.run_until(lambda: r.w.beliefs.holds("flight_state(self, landed)"), 60, "landed")
    assert r.w.pos_neu[0] < 10.0  # landed on the way, not at the fly-to's point


def test_abort_with_the_policy_asked_for() -> None:
    r = fly_to_mission()
    with pytest.raises(ExecutionRequestError, match="on_failure"):
        r.ts.abort("operator", "teleport")
    assert r.ts.running and not r.events("on_failure")  # a bad request changed nothing
    r.ts.abort("operator", "hover")
    assert r.ts.status()["state"] == "aborted" and r.events("on_failure")[0]["policy"] == "hover"
    r.w.run(3.0)
    assert r.w.pos_neu[2] > 2.5 and r.w.coordinator.is_active("KEEP_HOVERING")


def test_policy_refused_by_a_higher_requester_says_why(guarded: GuardedFlyTo) -> None:
    r = Run(mission_text("land", retries=0))
    r.ts.start()
    r.w.run_until(lambda: r.ts.active_node() == "go" or not r.ts.running, 30, "the guarded node")
    r.w.run_until(lambda: not r.ts.running, 30, "the end")
    # the vehicle is landed already when asked again: the record says LAND was refused and why
    r.w.run_until(lambda: r.w.beliefs.holds("flight_state(self, landed)"), 60, "landed")
    record = r.ts.apply_policy("land", "test")
    assert not record["applied"] and "flight_state" in record["reason"]


def test_a_waiting_node_says_what_it_waits_for(guarded: GuardedFlyTo) -> None:
    r = Run(mission_text("hover"))
    r.w.localized = False  # the estimate is not healthy: SELF_LOCALIZE stops, TAKE_OFF must wait
    r.w.run_until(lambda: not r.w.coordinator.is_active("SELF_LOCALIZE"), 10, "SELF_LOCALIZE stopped")
    r.ts.start()
    r.w.run(0.5)
    st = r.ts.status()
    assert st["waiting"] and st["waiting"][0]["node"] == "up", st
    text = st["waiting"][0]["for"]
    assert text.startswith("waiting: TAKE_OFF needs SELF_LOCALIZE active first"), text
    assert "position estimate is not healthy" in text, text
    up = st["tree"]["children"][0]
    assert up["state"] == "waiting" and up["waiting_for"] == text
    (waiting,) = r.events("node_waiting", "up")
    assert waiting["waiting_for"] == text


# --- resume: the rest of the tree ------------------------------------------------------------------------
TREE = """
mission: rest
on_failure: land
tree:
  type: S
  id: root
  children:
    - {type: take-off, id: a}
    - type: C
      id: both
      children:
        - {type: wait, id: b1, params: {duration: 1}}
        - {type: wait, id: b2, params: {duration: 1}, retries: 2}
    - type: IF
      id: if
      condition: "visible(?x)"
      then: {type: wait, id: t, params: {duration: 1}}
      else: {type: wait, id: e, params: {duration: 1}}
    - type: WHILE
      id: loop
      condition: "visible(?x)"
      body: {type: wait, id: w, params: {duration: 1}}
    - {type: land, id: z}
"""


def _ids(tree: dict[str, Any]) -> list[str]:
    out = [tree["id"]]
    for key in ("children",):
        for c in tree.get(key, []):
            out += _ids(c)
    for key in ("then", "else", "body"):
        if tree.get(key):
            out += _ids(tree[key])
    return out


def test_remainder_keeps_what_is_left_of_the_tree() -> None:
    m = mission_from_yaml(TREE, "t.yaml")
    outcome = {"a": "succeeded", "b1": "succeeded", "b2": "failed"}.get
    rest = remainder(m, "b2", outcome)
    assert rest.on_failure == "land" and rest.name == "rest"
    assert _ids(mission_to_dict(rest)["tree"]) == ["root", "both", "b2", "if", "t", "e", "loop", "w", "z"]
    assert rest.root.find("b2").retries == 2  # type: ignore[union-attr]
    rest = remainder(m, "both", {"b1": "failed"}.get)  # a C resumed as a whole
    assert _ids(mission_to_dict(rest)["tree"])[:4] == ["root", "both", "b1", "b2"]
    rest = remainder(m, "t", outcome)  # inside an IF: the branch, then what follows the IF
    assert _ids(mission_to_dict(rest)["tree"]) == ["root", "t", "loop", "w", "z"]
    with pytest.raises(ResumeError, match="inside the loop loop"):
        remainder(m, "w", outcome)
    with pytest.raises(ResumeError, match="no node 'nope'"):
        remainder(m, "nope", outcome)
    rest = remainder(m, "z", outcome, take_off={"type": "take-off"})
    assert _ids(mission_to_dict(rest)["tree"]) == ["resume", "resume-take-off", "root", "z"]


# --- the stream ----------------------------------------------------------------------------------------
def test_event_stream_long_poll() -> None:
    s = EventStream(lambda: 12.5)
    first = s.record("a", node="x")
    assert first == {"seq": 1, "t": 12.5, "event": "a", "node": "x"}
    assert [e["seq"] for e in s.since(0)] == [1] and s.since(1) == []
    t0 = time.monotonic()
    assert s.wait(1, 0.3) == []  # nothing new: waits for the deadline
    assert time.monotonic() - t0 >= 0.29
    got: list[list[dict[str, Any]]] = []
    reader = threading.Thread(target=lambda: got.append(s.wait(1, 30.0)))
    reader.start()
    time.sleep(0.1)
    s.record("b")
    reader.join(10)
    assert not reader.is_alive() and [e["event"] for e in got[0]] == ["b"]
    stop = threading.Event()
    stop.set()
    assert s.wait(2, 30.0, stop) == []  # a closing server ends the wait
