"""The queue's API for the layers above and "stopped if allowed" during a take-off.

Ids unique for the life of the process, command events to wait on or subscribe to, atomic batches,
in-flight retarget (seed 000 Sec. IV-D) with a continuous stream, the deferred stop of a climbing
take-off, a failed command in the status, and the reference following the vehicle while idle.
Simulated time (:class:`FlightSim`), no MAVLink.
"""

from __future__ import annotations

import math
import threading

import pytest

from companion.flight import (
    CommandError,
    CommandStatus,
    EndCondition,
    Envelope,
    EventKind,
    FlightCommand,
    HeadingChannel,
    HeadingMode,
    HorizontalChannel,
    HorizontalMode,
    QueueError,
    QueueState,
    QueueStateError,
    Retarget,
    VehicleState,
    VerticalChannel,
    VerticalMode,
)
from companion.flight.simulate import FlightSim, step_violations
from harness.flight_sim import LIMITS, airborne, index_is, make_sim, takeoff, waypoint


def kinds(sim: FlightSim, command_id: int) -> list[EventKind]:
    return [e.kind for e in sim.queue.events.since(0) if e.command_id == command_id]


def pos_cmd(n: float, e: float, alt: float, speed: float = 4.0) -> FlightCommand:
    return FlightCommand(
        HorizontalChannel(HorizontalMode.POS, north=n, east=e, speed=speed),
        VerticalChannel(VerticalMode.POS, altitude=alt),
        HeadingChannel(HeadingMode.POS, heading=0.0),
        EndCondition(e_h=True, e_v=True),
    )


# --- ids and events ----------------------------------------------------------------------------------------
def test_each_command_has_a_unique_id_and_a_life_of_events() -> None:
    sim = make_sim()
    q = sim.queue
    first, second = q.add_commands([takeoff(5.0), waypoint(10.0, 0.0, 5.0)])
    assert second > first
    waiter_result = []
    waiter = threading.Thread(target=lambda: waiter_result.append(q.events.wait_for(second, timeout_s=30)))
    waiter.start()
    q.run()
    sim.run_until(index_is(2), 40)
    waiter.join(30)
    assert [e.kind for e in waiter_result] == [EventKind.FINISHED]
    assert waiter_result[0].index == 1 and waiter_result[0].generation == 0
    assert kinds(sim, first) == [EventKind.ADDED, EventKind.STARTED, EventKind.FINISHED]
    assert kinds(sim, second) == [EventKind.ADDED, EventKind.STARTED, EventKind.FINISHED]
    # already happened: answered at once; never happening: None at the deadline
    assert q.events.wait_for(first, timeout_s=0).kind is EventKind.FINISHED  # type: ignore[union-attr]
    assert q.events.wait_for(first, {EventKind.FAILED}, timeout_s=0.05) is None
    seqs = [e.seq for e in q.events.since(0)]
    assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)


def test_reset_cancels_and_ids_never_repeat_across_generations() -> None:
    sim = make_sim(takeoff(5.0), waypoint(40.0, 0.0, 5.0), waypoint(0.0, 0.0, 5.0))
    airborne(sim)
    ids_before = [e.id for e in sim.queue.entries]
    sim.run_for(2.0)
    sim.queue.reset()
    assert kinds(sim, ids_before[1])[-1] is EventKind.CANCELLED
    assert kinds(sim, ids_before[2]) == [EventKind.ADDED, EventKind.CANCELLED]
    assert kinds(sim, ids_before[0])[-1] is EventKind.FINISHED  # finished before: not cancelled
    new = sim.queue.add_command(waypoint(0.0, 0.0, 5.0))
    st = sim.queue.status()
    assert st.generation == 1 and st.current_command_index == 0 and st.current_command_id == new
    assert new not in ids_before


def test_subscribers_see_every_event_in_order_and_may_call_the_queue() -> None:
    sim = make_sim()
    q = sim.queue
    seen: list[tuple[EventKind, int]] = []

    def on_event(e) -> None:
        seen.append((e.kind, len(q.commands)))  # a verb from inside the callback must not deadlock

    unsubscribe = q.events.subscribe(on_event)
    q.add_commands([takeoff(5.0), waypoint(5.0, 0.0, 5.0), waypoint(0.0, 0.0, 5.0)])
    # a batch is appended at once: every ADDED event already sees all three commands
    assert seen == [(EventKind.ADDED, 3)] * 3
    q.run()
    sim.run_until(index_is(3), 60)
    assert [k for k, _ in seen].count(EventKind.FINISHED) == 3
    unsubscribe()
    q.reset()
    assert [k for k, _ in seen].count(EventKind.RESET) == 0


def test_a_batch_with_one_bad_command_adds_nothing() -> None:
    sim = make_sim(envelope=Envelope([(-50.0, -50.0), (50.0, -50.0), (50.0, 50.0), (-50.0, 50.0)]))
    q = sim.queue
    with pytest.raises(CommandError, match=r"commands\[1\]\.horizontal\.north"):
        q.add_commands([takeoff(5.0), waypoint(80.0, 0.0, 5.0), waypoint(0.0, 0.0, 5.0)])
    assert q.commands == () and q.events.since(0) == []
    assert q.add_commands([]) == [] and q.events.since(0) == []


def test_pause_and_resume_events_carry_the_interrupted_command() -> None:
    sim = make_sim(takeoff(5.0), waypoint(30.0, 0.0, 5.0))
    airborne(sim)
    wp = sim.queue.entries[1].id
    sim.run_for(1.0)
    sim.queue.pause_direct()
    sim.run_for(1.0)
    sim.queue.user_confirm()
    sim.run_for(0.5)
    sim.queue.stop()
    sim.queue.run()
    assert kinds(sim, wp) == [EventKind.ADDED, EventKind.STARTED, EventKind.PAUSED, EventKind.RESUMED,
                              EventKind.STOPPED, EventKind.RESUMED]


# --- retarget ----------------------------------------------------------------------------------------------
def test_retarget_in_flight_changes_the_goal_with_a_continuous_stream() -> None:
    sim = make_sim(takeoff(5.0), pos_cmd(40.0, 0.0, 5.0))
    airborne(sim)
    cid = sim.queue.status().current_command_id
    assert cid is not None
    sim.run_for(3.0)  # flying north at speed
    assert sim.last.v[0] > 3.0
    new = sim.queue.retarget(cid, Retarget(north=10.0, east=20.0, altitude=8.0, heading=90.0))
    assert (new.horizontal.north, new.horizontal.east, new.vertical.altitude, new.heading.heading) == (
        10.0, 20.0, 8.0, 90.0)
    assert sim.queue.commands[1] == new  # the list shows what is flown
    sim.run_until(index_is(2), 40)
    assert sim.last.p == pytest.approx((10.0, 20.0, -8.0), abs=1e-6)
    assert math.degrees(sim.last.yaw) == pytest.approx(90.0, abs=0.5)
    assert step_violations(sim.setpoints, LIMITS) == []
    assert EventKind.RETARGETED in kinds(sim, cid)


def test_retarget_speed_slows_the_running_command() -> None:
    sim = make_sim(takeoff(5.0), waypoint(60.0, 0.0, 5.0, speed=4.0))
    airborne(sim)
    sim.run_for(4.0)
    cid = sim.queue.status().current_command_id
    sim.queue.retarget(cid, Retarget(speed=1.5))  # type: ignore[arg-type]
    sim.run_for(4.0)
    assert math.hypot(*sim.last.v[:2]) == pytest.approx(1.5, abs=1e-3)
    sim.run_until(index_is(2), 60)
    assert sim.last.p == (60.0, 0.0, -5.0)
    assert step_violations(sim.setpoints, LIMITS) == []


def test_a_retarget_that_does_not_fit_changes_nothing() -> None:
    box = Envelope([(-50.0, -50.0), (50.0, -50.0), (50.0, 50.0), (-50.0, 50.0)])
    sim = make_sim(takeoff(5.0), pos_cmd(30.0, 0.0, 5.0), envelope=box)
    airborne(sim)
    running = sim.queue.status().current_command_id
    assert running is not None
    before = (sim.queue.commands, sim.queue.status())
    cases = [
        (running + 1000, Retarget(north=1.0), QueueStateError, "not executing"),
        (running, Retarget(), QueueError, "nothing to change"),
        (running, Retarget(north=90.0), CommandError, "outside the operational envelope"),
        (running, Retarget(speed=-1.0), CommandError, "horizontal.speed"),
    ]
    for cid, change, exc, text in cases:
        with pytest.raises(exc, match=text):
            sim.queue.retarget(cid, change)
    assert (sim.queue.commands, sim.queue.status()) == before
    sim.run_until(index_is(2), 30)
    assert sim.last.p[:2] == (30.0, 0.0)


def test_retarget_refuses_a_channel_without_that_target() -> None:
    sim = make_sim(takeoff(5.0), waypoint(30.0, 0.0, 5.0))
    airborne(sim)
    cid = sim.queue.status().current_command_id
    with pytest.raises(QueueError, match="needs heading mode POS, not DNU"):
        sim.queue.retarget(cid, Retarget(heading=45.0))  # type: ignore[arg-type]


# --- "stopped if allowed" during the take-off ---------------------------------------------------------------
def test_stop_before_the_take_off_leaves_the_ground_is_immediate() -> None:
    sim = make_sim(takeoff(5.0))
    sim.queue.run()  # the take-off's execution exists but has not advanced (the link holds its time)
    sim.queue.stop()
    st = sim.queue.status()
    assert st.queue_status is QueueState.STOPPED and st.deferred is None
    sim.run_for(3.0)
    assert sim.last.p == (0.0, 0.0, 0.0) and not sim.last.take_off


@pytest.mark.parametrize("verb", ["stop", "pause_direct", "reset"])
def test_a_climbing_take_off_is_stopped_only_once_it_is_high_enough(verb: str) -> None:
    sim = make_sim(takeoff(5.0))
    q = sim.queue
    q.run()
    sim.run_until(lambda s: -s.last.p[2] > 0.2, 10)
    getattr(q, verb)()
    st = q.status()
    assert st.deferred == verb and st.queue_status is QueueState.RUNNING
    assert q.events.since(0)[-1].kind is EventKind.DEFERRED
    sim.run_until(lambda s: s.queue.status().deferred is None, 10)
    carried_out_at = -sim.last.p[2]
    assert carried_out_at >= q.takeoff_min_hold_m
    sim.run_for(5.0)
    rest = -sim.last.p[2]
    # it comes to rest from the climb: at most the vertical limit and still accelerating upwards,
    # braked within a_max and the jerk limit (ramp the acceleration down, then up the other way)
    v, a, j = LIMITS.vertical_speed, LIMITS.vertical_acceleration, LIMITS.vertical_jerk
    braking = v * v / (2 * a) + 2 * v * a / j
    assert carried_out_at <= rest <= carried_out_at + braking and sim.last.v == (0.0, 0.0, 0.0)
    assert rest < 4.5  # well short of the take-off's 5 m
    st = q.status()
    expected = {"stop": QueueState.STOPPED, "pause_direct": QueueState.WAITING_FOR_BEHAVIOR_AND_CONTINUING,
                "reset": QueueState.STOPPED}[verb]
    assert st.queue_status is expected
    assert (q.commands == ()) == (verb == "reset")


def test_run_cancels_a_deferred_stop() -> None:
    sim = make_sim(takeoff(5.0))
    sim.queue.run()
    sim.run_until(lambda s: -s.last.p[2] > 0.2, 10)
    sim.queue.stop()
    sim.queue.run()
    assert sim.queue.status().deferred is None
    sim.run_until(index_is(1), 20)
    assert sim.last.p == (0.0, 0.0, -5.0)


# --- replace_commands: how behaviors switch maneuvers ----------------------------------------------------
def test_replace_commands_switches_in_flight_without_a_jump() -> None:
    sim = make_sim(takeoff(5.0), waypoint(30.0, 0.0, 5.0))
    q = sim.queue
    airborne(sim)
    sim.run_for(3.0)  # flying north at speed
    old = q.entries[1].id
    ids = q.replace_commands([waypoint(0.0, 10.0, 6.0)])
    st = q.status()
    assert st.queue_status is QueueState.RUNNING
    assert st.current_command_id == ids[0] and st.current_command_index == 0
    kinds = [(e.kind, e.command_id) for e in q.events.since(0)[-5:]]
    assert (EventKind.CANCELLED, old) in kinds and (EventKind.ADDED, ids[0]) in kinds
    sim.run_until(index_is(1), 30)
    assert sim.last.p == (0.0, 10.0, -6.0)
    assert step_violations(sim.setpoints, LIMITS) == []
    with pytest.raises(CommandError):
        q.replace_commands([waypoint(1.0, 1.0, 5.0), FlightCommand(end=EndCondition(e_wait=-1))])
    assert q.entries[0].id == ids[0]  # a bad list changes nothing
    with pytest.raises(QueueError):
        q.replace_commands([])


def test_replace_commands_during_a_climbing_take_off_is_deferred_and_superseded() -> None:
    sim = make_sim(takeoff(5.0))
    q = sim.queue
    q.run()
    sim.run_until(lambda s: -s.last.p[2] > 0.2, 10)
    first = q.replace_commands([waypoint(5.0, 0.0, 3.0)])
    assert q.status().deferred == "replace" and q.events.since(0)[-1].kind is EventKind.DEFERRED
    second = q.replace_commands([waypoint(0.0, 5.0, 3.0)])
    assert q.events.wait_for(first[0], {EventKind.CANCELLED}, 0) is not None
    sim.run_until(lambda s: s.queue.status().deferred is None, 10)
    assert -sim.last.p[2] >= q.takeoff_min_hold_m and q.status().current_command_id == second[0]
    sim.run_until(index_is(1), 30)
    assert sim.last.p == (0.0, 5.0, -3.0)
    assert step_violations(sim.setpoints, LIMITS) == []


# --- failure and following the vehicle ----------------------------------------------------------------------
def test_a_failed_command_shows_in_the_status_and_run_tries_it_again() -> None:
    sim = make_sim(takeoff(5.0))
    q = sim.queue
    cid = q.add_command(waypoint(1.0, 0.0, 5.0))
    q.run()
    first = q.entries[0].id
    q.fail_current("take-off abandoned at step 'arm' after 3 attempts")
    st = q.status()
    assert st.current_command_status is CommandStatus.FAILED and st.queue_status is QueueState.STOPPED
    assert st.failure is not None and "arm" in st.failure
    assert kinds(sim, first)[-1] is EventKind.FAILED
    q.run()
    st = q.status()
    assert st.failure is None and st.current_command_status is CommandStatus.RUNNING
    sim.run_until(index_is(2), 30)
    assert kinds(sim, cid)[-1] is EventKind.FINISHED


def test_the_idle_reference_follows_the_vehicle_when_asked() -> None:
    sim = make_sim(takeoff(5.0))
    moved = VehicleState((3.0, 4.0, -2.0), (0.0, 0.0, 0.0), 1.0, False)
    sp = sim.queue.tick(sim.t + 0.05, moved, follow_vehicle=True)
    assert sp is not None and sp.p == (3.0, 4.0, -2.0) and sp.yaw == pytest.approx(1.0)
    sp = sim.queue.tick(sim.t + 0.10, VehicleState((9.0, 9.0, -2.0)), follow_vehicle=False)
    assert sp is not None and sp.p == (3.0, 4.0, -2.0)  # not asked: the reference holds


def test_a_position_command_after_velocity_only_starts_where_the_vehicle_is() -> None:
    """ExtVel streams no position: the reference's integrated one drifts from the vehicle's. The first
    position setpoint after it starts at the measured position, velocity kept (no step of the target)."""
    from companion.flight import CommandQueue, Limits, SetpointKind
    from companion.flight.simulate import step_violations

    q = CommandQueue(Limits())
    joystick = FlightCommand(HorizontalChannel(HorizontalMode.EXT_VEL), VerticalChannel(VerticalMode.EXT_VEL),
                             HeadingChannel(HeadingMode.DNU), EndCondition(e_user=True))
    hold = FlightCommand(end=EndCondition(e_wait=1.0))
    q.add_commands([joystick, hold])
    q.run()
    t, out = 0.0, []
    vehicle = VehicleState((0.0, 0.0, -5.0), (0.0, 0.0, 0.0), 0.0, False)
    for _ in range(40):  # 2 s at 1 m/s east; the vehicle lags 0.5 m behind the integrated reference
        q.push_external("ext_vel", (0.0, 1.0, 0.0, 0.0), 0.5, t)
        sp = q.tick(t, vehicle)
        out.append(sp)
        vehicle = VehicleState((0.0, max(0.0, sp.p[1] - 0.5), -5.0), sp.v, 0.0, False)
        t = round(t + 0.05, 6)
    assert out[-1].kind is SetpointKind.VELOCITY and out[-1].p[1] > 1.3  # the ramp up, then 1 m/s
    q.user_confirm()
    sp = q.tick(t, vehicle)
    assert sp.kind is SetpointKind.POSITION
    assert abs(sp.p[1] - (vehicle.p[1] + sp.v[1] * 0.05)) < 0.06  # from the vehicle, not the reference
    assert abs(sp.v[1] - out[-1].v[1]) < 0.2  # velocity continuous
    assert step_violations([*out, sp], q.limits) == []
