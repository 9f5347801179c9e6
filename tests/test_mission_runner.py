"""MissionRunner logic against a kinematic stand-in vehicle (the real vehicle is in the UDP tests)."""

from __future__ import annotations

import math

import pytest

from autopilot_model.modules.mission import (
    COMPLETE,
    RUNNING,
    WAITING,
    MissionItem,
    MissionStore,
    item_to_ned,
)
from harness.kinematic import HOME, IN_AIR, ON_GROUND, TAKEOFF, Recorder, geo


def item(seq: int, cmd: int, n: float = 0, e: float = 0, z: float = 0, frame: int = 6, p1: float = 0,
         p2: float = 0, here: bool = False) -> MissionItem:
    x, y = (0, 0) if here else geo(n, e)
    return MissionItem(seq=seq, frame=frame, command=cmd, param1=p1, param2=p2, x=x, y=y, z=z)


HOME_ITEM = MissionItem(seq=0, frame=0, command=16, x=round(HOME[0] * 1e7), y=round(HOME[1] * 1e7), z=HOME[2])


def reached_msgs(ep: Recorder) -> list[int]:
    return [m.seq for m in ep.sent if m.get_type() == "MISSION_ITEM_REACHED"]


def test_flies_plan_and_lands(mission_rig):
    v, store, ep, runner = mission_rig
    store.replace(0, [HOME_ITEM, item(1, 22, z=10, here=True), item(2, 16, 30, 0, 10),
                      item(3, 178, p2=8), item(4, 16, 30, 20, 15, p1=3, p2=0.5), item(5, 21, here=True)])
    v.nav.arm()
    assert runner.start() == (True, "")
    assert runner.state == WAITING
    v.run(1, runner.update)
    assert v.nav.target is None  # waits for MISSION_START on the ground
    assert runner.mission_start() == (True, "")
    assert runner.state == RUNNING
    visited = []

    def watch() -> None:
        runner.update()
        if store.current not in [c for c, _ in visited]:
            visited.append((store.current, v.state.position_ned))

    v.run(60, watch)
    assert runner.finished and runner.state == COMPLETE
    # every verified command is reached, the DO_CHANGE_SPEED too (ArduCopter's verify_command); one
    # MISSION_ITEM_REACHED per cycle: waypoint 2 is overtaken by item 3, verified in the same cycle
    assert runner.reached == [1, 2, 3, 4, 5]
    assert reached_msgs(ep) == [1, 3, 4, 5]
    assert "Reached command #2" in ep.texts and "Mission complete" in ep.texts
    assert not v.nav.armed and v.nav.landed_state == ON_GROUND
    n, e, d = v.state.position_ned
    assert math.hypot(n - 30, e - 20) < 0.6 and abs(d) < 1e-6
    # DO_CHANGE_SPEED applied to the following leg
    assert v.nav.speeds[-1] == 8
    # the take-off reached 10 m, waypoint 2 was reached within the default 2 m radius
    cur = dict(visited)
    assert abs(cur[2][2] + 10) < 0.3


def test_hold_time_is_waited(mission_rig):
    v, store, _, runner = mission_rig
    store.replace(0, [HOME_ITEM, item(1, 22, z=5, here=True), item(2, 16, 5, 0, 5, p1=4, p2=0.1)])
    v.nav.arm()
    runner.start()
    runner.mission_start()
    t_reached = None
    while not runner.finished and v.t < 30:
        v.run(0.02, runner.update)
        if t_reached is None and math.dist(v.state.position_ned, (5, 0, -5)) < 0.1:
            t_reached = v.t
    assert runner.finished and t_reached is not None
    assert v.t - t_reached >= 4.0 - 0.05
    assert v.nav.armed and v.nav.landed_state == IN_AIR  # ends holding in the air


def test_missing_takeoff_and_empty_mission(mission_rig):
    v, store, _, runner = mission_rig
    store.replace(0, [HOME_ITEM, item(1, 16, 5, 0, 5)])
    v.nav.arm()
    ok, why = runner.start()
    assert not ok and "Takeoff" in why
    store.clear(0)
    assert runner.mission_start()[0] is False


def test_start_requested_while_disarmed_waits_for_arming(mission_rig):
    v, store, _, runner = mission_rig
    store.replace(0, [HOME_ITEM, item(1, 22, z=5, here=True)])
    runner.start()
    assert runner.mission_start() == (True, "")
    v.run(1, runner.update)
    assert runner.state == WAITING
    v.nav.arm()
    v.run(0.1, runner.update)
    assert runner.state == RUNNING and v.nav.landed_state == TAKEOFF


def test_rtl_item_climbs_returns_and_lands(mission_rig):
    v, store, _, runner = mission_rig
    v.params.set("RTL_ALT", 2000)
    store.replace(0, [HOME_ITEM, item(1, 22, z=8, here=True), item(2, 16, 40, -10, 8), item(3, 20)])
    v.nav.arm()
    runner.start()
    runner.mission_start()
    max_alt = [0.0]

    def watch() -> None:
        runner.update()
        if store.current == 3:
            max_alt[0] = max(max_alt[0], -v.state.position_ned[2])

    v.run(60, watch)
    assert runner.finished and not v.nav.armed
    assert math.hypot(*v.state.position_ned[:2]) < 2.1
    assert abs(max_alt[0] - 20.0) < 0.1


def test_set_current_jumps_and_resume_after_leaving_auto(mission_rig):
    v, store, _, runner = mission_rig
    store.replace(0, [HOME_ITEM, item(1, 22, z=5, here=True), item(2, 16, 50, 0, 5), item(3, 16, 0, 50, 5)])
    v.nav.arm()
    runner.start()
    runner.mission_start()
    v.run(3, runner.update)
    assert store.current == 2
    assert store.set_current(3)
    assert v.nav.target == pytest.approx(item_to_ned(store.item(3), HOME, HOME[2], (0, 0, 0)), abs=1e-6)
    runner.stop()
    assert runner.state != RUNNING and not store.running
    assert runner.start() == (True, "")  # in the air: resumes item 3 at once
    assert runner.state == RUNNING and store.current == 3


def test_item_to_ned_frames():
    lat, lon = geo(100.0, -50.0)
    rel = MissionItem(seq=1, frame=6, command=16, x=lat, y=lon, z=20.0)
    n, e, d = item_to_ned(rel, HOME, HOME[2] + 3.0, (0, 0, 0))
    assert (n, e) == pytest.approx((100.0, -50.0), abs=0.01) and d == pytest.approx(-23.0)
    absolute = MissionItem(seq=1, frame=0, command=16, x=lat, y=lon, z=HOME[2] + 20.0)
    assert item_to_ned(absolute, HOME, HOME[2] + 3.0, (0, 0, 0))[2] == pytest.approx(-20.0)
    here = MissionItem(seq=1, frame=3, command=16, x=0, y=0, z=0.0)
    assert item_to_ned(here, HOME, HOME[2], (1.0, 2.0, -7.0)) == (1.0, 2.0, -7.0)


def test_auto_refused_without_plan_and_restart_after_completion(mission_rig):
    v, store, _, runner = mission_rig
    assert runner.start() == (False, "Auto: no mission")
    store.replace(0, [HOME_ITEM, item(1, 22, z=5, here=True), item(2, 16, 10, 0, 5)])
    v.nav.arm()
    runner.start()
    runner.mission_start()
    v.run(20, runner.update)
    assert runner.finished and store.current == 2 and v.nav.armed  # holding at the end
    runner.stop()
    v.nav.goto((0.0, 0.0, -5.0))
    v.run(5)
    assert runner.start() == (True, "")  # back in AUTO after completion: from the beginning
    assert store.current == 1 and runner.state == RUNNING


def test_do_jump_walk_counts_and_resets():
    """AP_Mission::get_next_cmd: a DO_JUMP is taken param2 times (counted only by the navigation walk),
    then passed and its counter reset; -1 jumps forever; a jump to item 0 or past the end ends the walk."""
    from autopilot_model.modules.mission_do import next_cmd

    store = MissionStore()
    store.replace(0, [HOME_ITEM, item(1, 22, z=5, here=True), item(2, 16, 5, 0, 5), item(3, 177, p1=2, p2=2),
                      item(4, 16, 0, 5, 5)])
    jumps: dict[int, int] = {}
    said: list[str] = []
    assert next_cmd(store, 3, jumps, increment=False).seq == 2 and jumps == {}
    assert next_cmd(store, 3, jumps, increment=True, say=said.append).seq == 2
    assert next_cmd(store, 3, jumps, increment=True, say=said.append).seq == 2
    assert said == ["Mission: 3 Jump 1/2", "Mission: 3 Jump 2/2"]
    assert next_cmd(store, 3, jumps, increment=True).seq == 4 and jumps[3] == 0
    store.replace(0, [HOME_ITEM, item(1, 16, 5, 0, 5), item(2, 177, p1=1, p2=-1)])
    for _ in range(100):
        assert next_cmd(store, 2, jumps, increment=True).seq == 1
    store.replace(0, [HOME_ITEM, item(1, 16, 5, 0, 5), item(2, 177, p1=0, p2=1)])
    assert next_cmd(store, 2, jumps, increment=True) is None


def test_condition_delay_holds_back_the_do_commands_after_it_not_the_navigation(mission_rig):
    v, store, _, runner = mission_rig
    store.replace(0, [HOME_ITEM, item(1, 22, z=5, here=True), item(2, 112, p1=3), item(3, 178, p2=2),
                      item(4, 16, 40, 0, 5)])
    v.nav.arm()
    runner.start()
    runner.mission_start()
    t_wp = t_speed = None
    while v.t < 60 and not runner.finished:
        v.run(0.02, runner.update)
        if t_wp is None and store.current == 4:
            t_wp = v.t
        if t_speed is None and 3 in runner.reached:
            t_speed = v.t
    assert t_wp is not None and t_speed is not None
    assert 2.9 <= t_speed - t_wp <= 3.2  # the speed change waited for the delay, the leg did not
    assert runner.reached == [1, 2, 3, 4] and v.nav.speeds[-1] == 2
