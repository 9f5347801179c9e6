"""The TST execution system and the executors (seed 000 Sec. III, VI, VII) over the behaviors layer.

A real queue, executive layer and behaviors with the kinematic vehicle of :mod:`behaviors_support`;
plans are given by hand (delegation has its own tests).
"""

from __future__ import annotations

from typing import Any

import pytest

from companion.flight.simulate import jerk_violations, step_violations
from companion.sensing.scenario import Scenario
from companion.tst.execution import TstExecutionSystem
from companion.tst.plan import NodePlan
from companion.tst.spec import mission_from_yaml
from companion.tst.status import ExecutionRequestError
from harness.behaviors import World

AREA = "[[-35.363243, 149.165186], [-35.363243, 149.165274], [-35.363171, 149.165274]]"
SCAN_MISSION = f"""
mission: scan
tree:
  type: S
  children:
    - {{type: take-off, id: to}}
    - {{type: scan-ground, id: scan, params: {{area: {AREA}, data_uuid: s1}}}}
    - {{type: fly-to, id: fly, params: {{position: [-35.36, 149.16, 3], fly_straight_line_flag: true}}}}
    - {{type: land, id: land}}
"""
SQUARE = [(5.0, 0.0, 3.0), (5.0, 5.0, 3.0), (10.0, 5.0, 3.0), (10.0, 10.0, 3.0), (5.0, 10.0, 3.0)]


class Mission:
    def __init__(self, text: str, plans: list[NodePlan], world: World | None = None) -> None:
        self.w = world or World()
        self.events: list[tuple[float, str, dict[str, Any]]] = []
        self.ts = TstExecutionSystem(self.w.layer,
                                     mark=lambda e, **f: self.events.append((self.w.sim.t, e, f)))
        self.w.layer.cycle_listeners.append(self.ts.tick)
        self.ts.load(mission_from_yaml(text, "m.yaml"), {p.node_id: p for p in plans})

    def node(self, node_id: str) -> dict[str, Any]:
        def find(n: dict[str, Any]) -> dict[str, Any] | None:
            if n["id"] == node_id:
                return n
            return next((f for c in n.get("children", []) if (f := find(c)) is not None), None)
        found = find(self.ts.status()["tree"])
        assert found is not None
        return found

    def kinds(self) -> list[str]:
        return [e for _, e, _ in self.events]

    def run_until_done(self, timeout_s: float = 120.0) -> str:
        self.w.run_until(lambda: not self.ts.running, timeout_s, "the mission's end")
        return self.ts.status()["state"]


def scan_plans() -> list[NodePlan]:
    return [NodePlan("to", "take-off", altitude_m=3.0),
            NodePlan("scan", "scan-ground", waypoints_neu=list(SQUARE), speed_m_s=2.0,
                     extra={"data_uuid": "s1"}),
            NodePlan("fly", "fly-to", position_neu=(0.0, 15.0, 4.0), speed_m_s=3.0),
            NodePlan("land", "land")]


def test_scan_and_search_with_break_in_resume_and_enough() -> None:
    m = Mission(SCAN_MISSION, scan_plans())
    m.ts.start()
    m.w.run_until(lambda: m.ts.active_node() == "scan", 30, "the scan")
    m.w.run_until(lambda: m.node("scan")["progress"]["waypoint"] == 3, 30, "waypoint 3")
    m.ts.pause()  # break-in: the operator's joystick
    assert m.node("scan")["status"]["paused"] and m.w.queue.routine_id == "joystick"
    before = m.w.pos_neu
    for _ in range(30):
        m.w.queue.push_external("ext_vel", (0.0, -1.5, 0.0, 0.0), 0.5)
        m.w.run(0.1)
    assert m.w.pos_neu[1] < before[1] - 2.0  # flown by the operator
    m.ts.continue_()  # resume: the scan goes on toward the waypoint it was flying to
    m.w.run_until(lambda: m.node("scan")["progress"]["waypoint"] == 4, 30, "waypoint 4 after the resume")
    assert abs(m.w.pos_neu[0] - 10) < 0.1 and abs(m.w.pos_neu[1] - 5) < 0.1  # waypoint 3 was reached
    m.ts.pause()
    m.w.run(1.0)
    m.ts.enough()  # enough during the break-in: the scan ends, the mission goes on
    scan = m.node("scan")
    assert scan["state"] == "succeeded" and scan["progress"]["skipped"] == [3, 4]
    assert m.run_until_done() == "succeeded"
    assert abs(m.w.pos_neu[0]) < 0.1 and abs(m.w.pos_neu[1] - 15) < 0.1 and m.w.pos_neu[2] < 0.05
    assert m.kinds().count("node_paused") == 2 and "node_enoughed" in m.kinds()
    # continuous from take-off to landing through both break-ins (seed 000 Sec. IV-D, VII): the step bounds
    # are the ones the generator's guard clamps every step to, so alone they would pass whatever the planner
    # did; the guard never had to act, and the jerk limits, which only the planner keeps, held as well
    setpoints, limits = m.w.sim.setpoints, m.w.queue.limits
    assert m.w.queue.guard_interventions == 0
    assert step_violations(setpoints, limits) == [] and jerk_violations(setpoints, limits) == []


def test_requests_the_flags_forbid_are_refused_and_change_nothing() -> None:
    m = Mission(SCAN_MISSION, scan_plans())
    with pytest.raises(ExecutionRequestError, match="no mission is running"):
        m.ts.pause()
    m.ts.start()
    with pytest.raises(ExecutionRequestError, match="can_be_paused is false"):
        m.ts.pause()  # take-off: none of the three (Fig. 4)
    with pytest.raises(ExecutionRequestError, match="cannot be enoughed"):
        m.ts.enough()
    assert m.node("to")["state"] == "executing"
    m.w.run_until(lambda: m.ts.active_node() == "scan", 30, "the scan")
    with pytest.raises(ExecutionRequestError, match="not paused"):
        m.ts.continue_()
    with pytest.raises(ExecutionRequestError, match="already running"):
        m.ts.start()
    m.w.run_until(lambda: m.ts.active_node() == "fly", 60, "the fly-to")
    with pytest.raises(ExecutionRequestError, match="cannot be enoughed"):
        m.ts.enough()  # fly-to: abort and pause only
    m.ts.abort("test")
    assert m.ts.status()["state"] == "aborted" and m.node("fly")["status"]["aborted"]
    m.w.run(1.0)
    assert "KEEP_HOVERING" in m.w.active()  # the behaviors hold the vehicle
    assert m.node("land")["state"] == "idle"


def test_a_failing_node_fails_the_sequence_with_its_reason() -> None:
    text = SCAN_MISSION.replace("data_uuid: s1", "data_uuid: s2")
    plans = scan_plans()
    plans[1] = NodePlan("scan", "scan-ground", waypoints_neu=[(5.0, 0.0, 3.0), (80.0, 0.0, 3.0)])
    from companion.flight import Envelope

    m = Mission(text, plans, World(envelope=Envelope.box(-20, 20, -20, 20)))
    m.ts.start()
    assert m.run_until_done() == "failed"
    st = m.ts.status()
    assert "scan" in st["fail_reason"] and "wrong_progress" in st["fail_reason"]
    assert m.node("fly")["state"] == "idle"  # never started


WHILE_IF = """
mission: search
tree:
  type: S
  children:
    - {type: take-off, id: to}
    - type: WHILE
      id: search
      condition: "not visible(?x), object(?x, person)"
      body: {type: scan-ground, id: scan, params: {area: AREA, repeat_flag: true}}
    - type: IF
      id: found
      condition: "visible(?x), object(?x, person)"
      then:
        type: S
        id: inspect
        children:
          - {type: hover, id: over, params: {over: "?x", duration: 2}}
          - {type: request-operator-assistance, id: ask, params: {message: "person found"}}
    - {type: land, id: land}
""".replace("AREA", AREA)


def test_while_and_if_over_camera_beliefs() -> None:
    plans = [NodePlan("to", "take-off", altitude_m=3.0),
             NodePlan("scan", "scan-ground", waypoints_neu=list(SQUARE), speed_m_s=2.0),
             NodePlan("over", "hover", duration_s=2.0), NodePlan("ask", "request-operator-assistance"),
             NodePlan("land", "land")]
    # a person beside the third leg of the scan, seen by the simulated downward camera (60 degrees)
    scenario = Scenario.from_text("objects: [{id: 7, class: person, position: [10.8, 8.0]}]", "s.yaml")
    m = Mission(WHILE_IF, plans, World(scenario=scenario))
    m.ts.start()
    m.w.run_until(lambda: m.ts.active_node() in ("over", "ask"), 90, "the loop ended, the IF took its branch")
    assert m.node("search")["progress"]["iteration"] == 1
    assert m.node("scan")["state"] == "succeeded"  # enoughed by the WHILE once the person was seen
    assert m.node("scan")["progress"]["waypoint"] == 4  # on the third leg
    assert m.node("found")["progress"]["branch"] == "then"
    assert [d.object_id for d in m.w.layer.camera.detections] == [7]
    m.w.run_until(lambda: m.ts.active_node() == "ask", 30, "above the person, asking")
    assert abs(m.w.pos_neu[0] - 10.8) < 0.1 and abs(m.w.pos_neu[1] - 8) < 0.1
    assert m.w.beliefs.holds("waiting_for(self, operator)")
    m.w.queue.user_confirm()  # the operator answers
    assert m.run_until_done() == "succeeded"
    assert m.w.pos_neu[2] < 0.05 and abs(m.w.pos_neu[0] - 10.8) < 0.1


def test_concurrent_node_runs_a_wait_beside_an_operator_request() -> None:
    text = """
mission: c
tree:
  type: S
  children:
    - {type: take-off, id: to}
    - type: C
      id: both
      children:
        - {type: wait, id: w, params: {duration: 3}}
        - {type: request-operator-assistance, id: ask, params: {message: "ready?"}}
    - {type: land, id: land}
"""
    m = Mission(text, [NodePlan("to", "take-off", altitude_m=3.0), NodePlan("w", "wait", duration_s=3.0),
                       NodePlan("ask", "request-operator-assistance"), NodePlan("land", "land")])
    m.ts.start()
    m.w.run_until(lambda: m.node("both")["state"] == "executing", 30, "the C node")
    assert m.node("w")["state"] == "executing" and m.node("ask")["state"] == "executing"  # together
    m.w.run(5.0)  # the request pauses the wait's command: E_Wait does not run out meanwhile
    assert m.node("w")["state"] == "executing"
    m.w.queue.user_confirm()
    m.w.run_until(lambda: m.node("both")["state"] == "succeeded", 10, "both children done")
    assert m.node("ask")["state"] == "succeeded" and m.node("w")["state"] == "succeeded"
    assert m.run_until_done() == "succeeded"


def test_each_executor_queues_the_flight_commands_of_fig_11_to_14() -> None:
    """Each leaf, run alone on a flying vehicle, puts seed 000's flight commands on the queue."""
    from companion.flight import HeadingMode as Hd
    from companion.flight import HorizontalMode as H
    from companion.flight import VerticalMode as V

    cases: list[tuple[str, NodePlan, list[tuple[Any, ...]]]] = [
        ("{type: fly-to, id: x, params: {position: [-35.36, 149.16, 3], fly_straight_line_flag: true}}",
         NodePlan("x", "fly-to", position_neu=(5.0, 1.0, 4.0), straight_line=True),
         [(H.POS, V.WITH_HOR, Hd.DNU, ("e_h", "e_v"))]),  # Fig. 12b, I
        ("{type: fly-to, id: x, params: {position: [-35.36, 149.16, 3]}}",
         NodePlan("x", "fly-to", position_neu=(5.0, 1.0, 4.0), straight_line=False),
         [(H.POS, V.POS, Hd.DNU, ("e_h", "e_v"))]),  # Fig. 12b, II
        ("{type: land, id: x, params: {position: [-35.36, 149.16, 0]}}",
         NodePlan("x", "land", position_neu=(4.0, 2.0, 0.0)),
         [(H.POS, V.WITH_HOR, Hd.DNU, ("e_h", "e_v")), (H.DNU, V.POS, Hd.DNU, ("e_v",))]),  # Fig. 13b
        ("{type: land, id: x}", NodePlan("x", "land"), [(H.DNU, V.POS, Hd.DNU, ("e_v",))]),
        ("{type: wait, id: x, params: {duration: 2}}", NodePlan("x", "wait", duration_s=2.0),
         [(H.DNU, V.DNU, Hd.DNU, ("e_wait",))]),  # Sec. VI-D
        (f"{{type: scan-ground, id: x, params: {{area: {AREA}}}}}",
         NodePlan("x", "scan-ground", waypoints_neu=[(3.0, 0.0, 3.0), (3.0, 3.0, 3.0)]),
         [(H.POS, V.WITH_HOR, Hd.DNU, ("e_h", "e_v"))] * 2),  # Fig. 14b, I
        ("{type: external-velocity, id: x}", NodePlan("x", "external-velocity"),
         [(H.EXT_VEL, V.EXT_VEL, Hd.EXT_VEL, ("e_user",))]),  # Sec. VI-F
    ]
    for leaf, plan, expected in cases:
        w = World()
        w.take_off(3.0)
        m = Mission(f"mission: one\ntree: {leaf}\n", [plan], w)
        m.ts.start()
        got = []
        for c in w.queue.commands:
            ends = tuple(k for k in ("e_h", "e_v", "e_hd", "e_user") if getattr(c.end, k))
            ends += ("e_wait",) if c.end.e_wait is not None else ()
            got.append((c.horizontal.mode, c.vertical.mode, c.heading.mode, ends))
        assert got == expected, leaf
        if plan.task == "land":
            assert w.queue.commands[-1].vertical.allow_landing


def test_a_node_waits_for_the_behavior_it_needs_fig5_waiting() -> None:
    """Before the autopilot's estimate is healthy SELF_LOCALIZE is not active and TAKE_OFF is refused by
    precedence: the take-off node waits (Fig. 5 ``waiting``) and runs once the estimate is healthy."""
    w = World()
    w.localized = False
    w.run(2.0)
    assert "SELF_LOCALIZE" not in w.active()
    m = Mission(SCAN_MISSION, scan_plans(), w)
    m.ts.start()
    assert m.node("to")["status"]["waiting"] and m.node("to")["state"] == "waiting"
    w.run(1.0)
    assert m.node("to")["state"] == "waiting"
    w.localized = True
    w.run_until(lambda: m.node("to")["state"] == "executing", 3.0, "the take-off running")
    w.run_until(lambda: m.ts.active_node() == "scan", 30, "the scan")
    assert "node_waiting" in m.kinds()


def test_a_wait_condition_that_never_holds_fails_the_node() -> None:
    w = World()
    w.localized = False
    m = Mission(SCAN_MISSION, scan_plans(), w)
    m.ts.start()
    assert m.run_until_done(60) == "failed"  # after the wait limit
    assert "precedence" in m.ts.status()["fail_reason"] and "SELF_LOCALIZE" in m.ts.status()["fail_reason"]
