"""The behavior coordinator (seed 001 Sec. 6.1.2, 6.2.2, Fig. 6) over a real queue and kinematic vehicle."""

from __future__ import annotations

import pytest

from companion.behaviors.coordinator import BehaviorCoordinator
from companion.flight import Envelope
from companion.flight.simulate import step_violations
from harness.behaviors import World, catalog_with


def test_fig6_two_requesters_default_hovering_and_priority() -> None:
    w = World()
    assert w.active() == {"SELF_LOCALIZE": "default", "WATCH_GROUND": "default"}  # recurrent defaults
    assert w.activate("TAKE_OFF altitude: 5").accepted
    assert w.wait_ended("TAKE_OFF", 30).cause.value == "goal_achieved"
    w.run_until(lambda: "KEEP_HOVERING" in w.active(), 2.0, "KEEP_HOVERING started by default")
    assert w.active()["KEEP_HOVERING"] == "default"

    r = w.activate("GO_TO_POINT coordinate: (10, 0, 5)")
    assert r.accepted and r.stopped == ("KEEP_HOVERING",)
    assert w.ended("KEEP_HOVERING").cause.value == "interrupted"  # ended by default, as Fig. 6
    w.run(1.0)
    land = w.activate("LAND", "emergency")
    assert land.accepted and land.stopped == ("GO_TO_POINT",)
    assert w.ended("GO_TO_POINT").cause.value == "interrupted"
    again = w.activate("GO_TO_POINT coordinate: (10, 0, 5)")
    assert not again.accepted
    assert "LAND" in again.reason and "emergency" in again.reason
    assert w.active() == {"SELF_LOCALIZE": "default", "WATCH_GROUND": "default", "LAND": "emergency"}
    assert w.wait_ended("LAND", 30).cause.value == "goal_achieved"
    w.run(1.0)
    assert w.active() == {"SELF_LOCALIZE": "default", "WATCH_GROUND": "default"}  # landed: no KEEP_HOVERING
    assert step_violations(w.sim.setpoints, w.queue.limits) == []
    events = [(r["event"], r.get("behavior")) for r in w.layer.log.records if r["type"] == "behavior"]
    assert events[:5] == [("started", "SELF_LOCALIZE"), ("started", "WATCH_GROUND"), ("started", "TAKE_OFF"),
                          ("terminated", "TAKE_OFF"), ("started", "KEEP_HOVERING")]


def test_situation_conditions_from_beliefs() -> None:
    w = World()
    r = w.activate("LAND")
    assert not r.accepted and "flight_state(self, flying)" in r.reason
    r = w.activate("GO_TO_POINT coordinate: (1, 0, 5)")
    assert not r.accepted and r.reason.startswith("situation:")
    w.take_off()
    r = w.activate("TAKE_OFF")
    assert not r.accepted and "landed" in r.reason
    assert w.active() == {"SELF_LOCALIZE": "default", "WATCH_GROUND": "default", "KEEP_HOVERING": "default"}


def test_precedence_needs_self_localize_and_protects_it() -> None:
    w = World()
    w.localized = False
    w.run(2.0)
    assert w.ended("SELF_LOCALIZE").cause.value == "wrong_progress"
    r = w.activate("TAKE_OFF")
    assert not r.accepted and "SELF_LOCALIZE" in r.reason and r.reason.startswith("precedence")
    w.localized = True
    w.run_until(lambda: "SELF_LOCALIZE" in w.active(), 2.0, "SELF_LOCALIZE back by default")
    w.take_off()
    r = w.coordinator.inhibit("SELF_LOCALIZE", "emergency")
    assert not r.accepted and "KEEP_HOVERING" in r.reason
    assert "SELF_LOCALIZE" in w.active()


def test_inhibit_priority_and_defaults() -> None:
    w = World()
    w.take_off()
    assert w.activate("GO_TO_POINT coordinate: (20, 0, 5)", "operator").accepted
    r = w.coordinator.inhibit("GO_TO_POINT", "mission")
    assert not r.accepted and "operator" in r.reason
    r = w.coordinator.inhibit("GO_TO_POINT", "operator")
    assert r.accepted and r.started_defaults == ("KEEP_HOVERING",)
    assert w.ended("GO_TO_POINT").cause.value == "interrupted"
    w.run(6.0)
    assert w.pos_neu[0] < 15  # stopped, smoothly
    assert not w.coordinator.inhibit("GO_TO_POINT", "operator").accepted
    assert step_violations(w.sim.setpoints, w.queue.limits) == []


def test_same_requester_replaces_its_behavior_and_rejections_change_nothing() -> None:
    w = World()
    w.take_off()
    a = w.activate("GO_TO_POINT coordinate: (20, 0, 5)")
    before = w.coordinator.active()
    for bad in ("GO_TO_POINT coordinate: (1, 2)", "FLY_AWAY", "ROTATE angle 4", "GO_TO_POINT speed: 2",
                "GO_TO_POINT coordinate: (5000, 0, 5)"):
        r = w.activate(bad)
        assert not r.accepted and r.reason.startswith("format:"), (bad, r.reason)
    assert w.coordinator.active() == before
    b = w.activate("GO_TO_POINT coordinate: (0, 10, 5)")
    assert b.accepted and b.stopped == ("GO_TO_POINT",) and b.activation_id != a.activation_id
    replaced = w.ended("GO_TO_POINT")
    assert replaced.activation_id == a.activation_id and replaced.cause.value == "interrupted"
    assert w.wait_ended("GO_TO_POINT", 30).cause.value == "goal_achieved"
    assert abs(w.pos_neu[1] - 10) < 0.2 and abs(w.pos_neu[0]) < 0.2


def test_time_out_from_catalog() -> None:
    planned = "  timeout: {factor: 1.5, margin_s: 20}    # distance over the speed allowed"
    w = World(catalog_with({planned: "  timeout: 3  #"}))  # a fixed limit, shorter than the flight
    w.take_off()
    assert w.activate("GO_TO_POINT coordinate: (60, 0, 5)").accepted
    e = w.wait_ended("GO_TO_POINT", 10)
    assert e.cause.value == "time_out"
    assert 2.9 <= e.ended_at - e.started_at <= 3.3
    w.run_until(lambda: "KEEP_HOVERING" in w.active(), 1.0)
    w.run(5.0)
    assert w.pos_neu[0] < 40  # it came to rest, it did not carry on to 60 m


def test_wrong_progress_when_the_vehicle_does_not_follow() -> None:
    w = World()
    w.take_off()
    w.frozen = True  # the measured position no longer changes (e.g. held by a fence or wind)
    assert w.activate("GO_TO_POINT coordinate: (40, 0, 5)").accepted
    e = w.wait_ended("GO_TO_POINT", 20)
    assert e.cause.value == "wrong_progress" and "no progress" in e.detail
    assert 9.5 <= e.ended_at - e.started_at <= 11.0  # the catalog's no_progress_s: 10


def test_unreachable_point_ends_at_once() -> None:
    l_shape = Envelope([(-10, -10), (50, -10), (50, 10), (10, 10), (10, 50), (-10, 50)])
    w = World(envelope=l_shape)
    w.take_off()
    r = w.activate("GO_TO_POINT coordinate: (40, 40, 5)")  # outside the L
    assert r.accepted
    e = w.wait_ended("GO_TO_POINT", 1.0)
    assert e.cause.value == "wrong_progress" and "outside" in e.detail
    e2 = (w.activate("GO_TO_POINT coordinate: (40, 0, 5)"), w.wait_ended("GO_TO_POINT", 30))[1]
    assert e2.cause.value == "goal_achieved"
    w.activate("GO_TO_POINT coordinate: (0, 40, 5)")  # inside, but the straight line leaves the L
    e3 = w.wait_ended("GO_TO_POINT", 1.0)
    assert e3.cause.value == "wrong_progress" and "straight line" in e3.detail
    assert "KEEP_HOVERING" in w.active()


def test_rotate_follow_path_keep_moving() -> None:
    w = World()
    w.take_off()
    assert w.activate("ROTATE angle: 90").accepted
    assert w.wait_ended("ROTATE", 10).cause.value == "goal_achieved"
    assert abs(w.sim.yaw - 1.5708) < 0.02
    assert w.activate("ROTATE relative_angle: -45").accepted
    assert w.wait_ended("ROTATE", 10).cause.value == "goal_achieved"
    assert abs(w.sim.yaw - 0.7854) < 0.02
    r = w.activate("ROTATE angle: 10 relative_angle: 10")
    assert not r.accepted and "exactly one" in r.reason
    assert w.activate("FOLLOW_PATH path: ((5, 0, 5), (5, 5, 6), (0, 5, 5)) speed: 3").accepted
    assert w.wait_ended("FOLLOW_PATH", 40).cause.value == "goal_achieved"
    assert max(abs(a - b) for a, b in zip(w.pos_neu, (0, 5, 5), strict=True)) < 0.1
    assert w.activate("KEEP_MOVING velocity: (1, 0, 0)").accepted
    w.run(5.0)
    assert 0.99 < w.sim.state().v[0] <= 1.01
    assert w.activate("KEEP_HOVERING", "mission").accepted
    assert w.ended("KEEP_MOVING").cause.value == "interrupted"
    w.run(3.0)
    assert abs(w.sim.state().v[0]) < 0.01
    assert not w.layer.processes.get("velocity_source").running
    assert step_violations(w.sim.setpoints, w.queue.limits) == []


def test_operator_assistance_pauses_and_resumes_fig7() -> None:
    w = World()
    w.take_off()
    assert w.activate("GO_TO_POINT coordinate: (20, 0, 5)").accepted
    w.run(2.0)
    r = w.activate('REQUEST_OPERATOR_ASSISTANCE message: "is the frame visible?"')
    assert r.accepted and r.stopped == ()
    assert w.beliefs.holds("waiting_for(self, operator)")
    assert w.beliefs.consult("operator_message(self, ?m)") == [{"m": "is the frame visible?"}]
    w.run(15.0)
    held = w.pos_neu[0]
    w.run(2.0)
    assert abs(w.pos_neu[0] - held) < 0.01 and "GO_TO_POINT" in w.active()  # paused, not timed out
    assert w.queue.status().confirmation_required_status
    w.queue.user_confirm()
    assert w.wait_ended("REQUEST_OPERATOR_ASSISTANCE", 1.0).cause.value == "goal_achieved"
    assert not w.beliefs.holds("waiting_for(self, operator)")
    e = w.wait_ended("GO_TO_POINT", 30)
    assert e.cause.value == "goal_achieved" and abs(w.pos_neu[0] - 20) < 0.1
    assert step_violations(w.sim.setpoints, w.queue.limits) == []


def test_external_velocity_joystick_until_confirmed() -> None:
    from companion.behaviors.processes import ProcessError

    w = World()
    w.take_off()
    with pytest.raises(ProcessError, match="not running"):
        w.layer.joystick.push((1.0, 0, 0, 0))
    assert w.activate("FOLLOW_EXTERNAL_VELOCITY", "operator").accepted
    for _ in range(40):
        w.layer.joystick.push((0.0, 2.0, 0.0, 0.0))
        w.run(0.1)
    assert w.sim.state().v[1] > 1.5
    w.run(2.0)  # the joystick went silent: the vehicle stops
    assert abs(w.sim.state().v[1]) < 0.01
    w.queue.user_confirm()
    assert w.wait_ended("FOLLOW_EXTERNAL_VELOCITY", 1.0).cause.value == "goal_achieved"
    w.run_until(lambda: "KEEP_HOVERING" in w.active(), 1.0)


def test_process_manager_delayed_stop_in_a_flight() -> None:
    w = World()
    w.take_off()
    w.activate("GO_TO_POINT coordinate: (5, 0, 5)")
    w.wait_ended("GO_TO_POINT", 20)
    w.activate("FOLLOW_PATH path: ((5, 5, 5), (0, 0, 5))")
    w.wait_ended("FOLLOW_PATH", 30)
    trace = [(e.process, e.event) for e in w.layer.processes.trace]
    assert trace.count(("motion_controller", "start")) == 1  # shared by the flight behaviors: kept running
    assert ("trajectory_planner", "stop") in trace  # stopped once KEEP_HOVERING took over
    assert w.layer.processes.references()["motion_controller"] == 1


def test_a_catalog_behavior_without_controller_is_refused() -> None:
    from companion.behaviors.catalog import catalog_from_yaml
    from companion.behaviors.controller import BehaviorContext

    cat = catalog_from_yaml("behavior_descriptors:\n- behavior: DANCE\n  category: goal_based\n", "c.yaml")
    w = World()
    ctx = BehaviorContext(w.queue, w.beliefs, w.layer.processes, lambda: 0.0, lambda: None)
    with pytest.raises(ValueError, match="DANCE has no execution controller"):
        BehaviorCoordinator(cat, ctx)


def test_a_vehicle_taken_over_interrupts_and_refuses_flight_behaviors() -> None:
    w = World()
    w.take_off()
    assert w.activate("GO_TO_POINT coordinate: (20, 0, 5)").accepted
    w.run(1.0)
    w.queue.set_overridden(True)  # a pilot or ground station took the vehicle
    e = w.wait_ended("GO_TO_POINT", 1.0)
    assert e.cause.value == "interrupted" and "taken over" in e.detail
    w.run(1.0)
    assert "KEEP_HOVERING" not in w.active()
    r = w.activate("GO_TO_POINT coordinate: (0, 0, 5)")
    assert not r.accepted and "controlled elsewhere" in r.reason
    assert w.beliefs.holds("control(self, elsewhere)")
    w.queue.set_overridden(False)  # given back: hovering by default
    w.run_until(lambda: "KEEP_HOVERING" in w.active(), 2.0, "KEEP_HOVERING once given back")


def test_flight_commands_of_the_executors_fig_11_to_13() -> None:
    """The behaviors the TST executors ask for put seed 000's flight commands on the queue."""
    from companion.flight import HeadingMode, HorizontalMode, VerticalMode

    w = World()
    assert w.activate("WAIT duration: 2").accepted  # a wait on the ground (Sec. VI-D)
    (c,) = w.queue.commands
    assert (c.horizontal.mode, c.vertical.mode, c.heading.mode) == (HorizontalMode.DNU, VerticalMode.DNU,
                                                                     HeadingMode.DNU)
    assert c.end.e_wait == 2.0
    e = w.wait_ended("WAIT", 5)
    assert e.cause.value == "goal_achieved" and 1.9 <= e.ended_at - e.started_at <= 2.2
    w.take_off()
    assert w.activate("GO_TO_POINT coordinate: (10, 0, 8) straight_line: no").accepted
    (c,) = w.queue.commands
    assert c.vertical.mode is VerticalMode.POS and c.heading.mode is HeadingMode.DNU  # Fig. 12b, II
    assert c.end.e_h and c.end.e_v
    w.wait_ended("GO_TO_POINT", 30)
    assert w.activate("GO_TO_POINT coordinate: (0, 0, 6)").accepted
    assert w.queue.commands[0].vertical.mode is VerticalMode.WITH_HOR  # Fig. 12b, I
    w.wait_ended("GO_TO_POINT", 30)
    assert w.activate("LAND coordinate: (5, 5)").accepted  # Fig. 13b: fly there, then land
    fly, land = w.queue.commands
    assert (fly.horizontal.north, fly.horizontal.east, fly.vertical.altitude) == (5.0, 5.0, 6.0)
    assert land.vertical.allow_landing and land.horizontal.mode is HorizontalMode.DNU
    assert w.wait_ended("LAND", 60).cause.value == "goal_achieved"
    assert abs(w.pos_neu[0] - 5) < 0.1 and abs(w.pos_neu[1] - 5) < 0.1 and w.pos_neu[2] < 0.05


def test_operator_break_in_with_the_joystick() -> None:
    """Seed 000 Sec. VII: the operator breaks in and flies with the joystick; the flight resumes after."""
    w = World()
    w.take_off()
    assert w.activate("FOLLOW_PATH path: ((20, 0, 5), (20, 20, 5))").accepted
    w.run(3.0)
    r = w.activate("REQUEST_OPERATOR_ASSISTANCE control: joystick", "operator")
    assert r.accepted and w.queue.routine_id == "joystick"
    for _ in range(40):  # it was flying north at speed: braking and turning are acceleration-limited
        w.queue.push_external("ext_vel", (0.0, -2.0, 0.0, 0.0), 0.5)
        w.run(0.1)
    assert w.sim.state().v[1] < -1.5  # the operator flies west
    where = w.pos_neu
    assert w.coordinator.inhibit("REQUEST_OPERATOR_ASSISTANCE", "operator").accepted  # continue
    assert w.queue.routine_id is None
    assert w.wait_ended("FOLLOW_PATH", 60).cause.value == "goal_achieved"
    assert where[1] < -1.0 and abs(w.pos_neu[0] - 20) < 0.1 and abs(w.pos_neu[1] - 20) < 0.1
    assert step_violations(w.sim.setpoints, w.queue.limits) == []
