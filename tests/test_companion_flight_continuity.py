"""Continuity of the streamed reference through a flight with every kind of switch (seed 000 Sec. IV-D):
next command, pause_direct, joystick break-in, stale stream, pause_after_current, stop, reset, landing.
Every setpoint is recorded; the step bounds |dv| <= a_max*dt and |dp| <= v_max*dt must never break."""

from __future__ import annotations

import math
import random

from companion.flight import (
    CommandQueue,
    EndCondition,
    Envelope,
    FlightCommand,
    HeadingChannel,
    HeadingMode,
    HorizontalChannel,
    HorizontalMode,
    Limits,
    QueueState,
    VerticalChannel,
    VerticalMode,
)
from companion.flight.simulate import FlightSim, step_violations

LIMITS = Limits(
    horizontal_speed=6,
    horizontal_acceleration=3,
    horizontal_jerk=6,
    vertical_speed=2.5,
    vertical_acceleration=2,
    vertical_jerk=4,
    yaw_rate=60,
)


def _mission() -> list[FlightCommand]:
    return [
        FlightCommand(
            vertical=VerticalChannel(VerticalMode.POS, altitude=5, take_off=True), end=EndCondition(e_v=True)
        ),
        FlightCommand(
            HorizontalChannel(
                HorizontalMode.POS, north=30, east=0, speed=6, end_speed=2, speed_modified_by=["vertical"]
            ),
            VerticalChannel(VerticalMode.POS, altitude=9, speed=1),
            end=EndCondition(e_h=True, e_v=True),
        ),
        FlightCommand(
            HorizontalChannel(HorizontalMode.POS, north=30, east=25, speed=5),
            VerticalChannel(VerticalMode.WITH_HOR, altitude=6),
            HeadingChannel(HeadingMode.FLIGHT_DIR),
            EndCondition(e_h=True, e_v=True),
        ),
        FlightCommand(
            HorizontalChannel(HorizontalMode.EXT_VEL),
            VerticalChannel(VerticalMode.EXT_VEL),
            HeadingChannel(HeadingMode.EXT_VEL),
            EndCondition(e_user=True),
        ),
        FlightCommand(
            heading=HeadingChannel(HeadingMode.POS, heading=180, frame="relative", rate=-45, use_sign=True),
            end=EndCondition(e_hd=True),
        ),
        FlightCommand(
            heading=HeadingChannel(HeadingMode.POINT, north=0, east=0), end=EndCondition(e_hd=True)
        ),
        FlightCommand(end=EndCondition(e_wait=3.0)),
        FlightCommand(
            HorizontalChannel(HorizontalMode.POS, north=0, east=0, speed=6, speed_modified_by=["heading"]),
            VerticalChannel(VerticalMode.POS, altitude=5),
            HeadingChannel(HeadingMode.FLIGHT_DIR, offset=0),
            EndCondition(e_h=True, e_v=True),
        ),
    ]


def test_no_step_bound_is_ever_broken_through_all_switches() -> None:
    env = Envelope.box(-50, 50, -50, 50, altitude_floor=1.0, altitude_ceiling=30.0)
    queue = CommandQueue(LIMITS, env)
    for c in _mission():
        queue.add_command(c)
    sim = FlightSim(queue, dt=0.05)
    rng = random.Random(4)
    joystick: dict[str, tuple[float, float, float, float] | None] = {"v": None}

    def jitter_and_feed(s: FlightSim) -> None:
        s.dt = rng.choice((0.02, 0.03, 0.05, 0.05, 0.07))  # 14..50 Hz, irregular
        if joystick["v"] is not None:
            s.queue.push_external("ext_vel", joystick["v"], 0.25, s.t)

    sim.on_tick.append(jitter_and_feed)

    def index_is(i: int):
        return lambda s: s.queue.status().current_command_index >= i

    sim.tick()
    queue.run()
    sim.run_until(index_is(1), 20)  # take-off
    sim.run_for(2.5)
    queue.pause_direct()  # break in while accelerating
    sim.run_for(2.0)
    queue.run()  # resume
    sim.run_until(index_is(2), 60)  # arrives with end speed 2, next leg starts moving
    sim.run_for(2.0)
    queue.pause_direct("joystick")  # operator takes over mid-leg
    joystick["v"] = (-2.0, 3.0, -0.5, 30.0)
    sim.run_for(3.0)
    queue.user_confirm()  # hands back while moving
    joystick["v"] = None
    sim.run_until(index_is(3), 60)
    joystick["v"] = (4.0, -2.0, 0.8, -40.0)  # the ExtVel command
    sim.run_for(2.0)
    joystick["v"] = None  # stream goes stale: velocity to zero
    sim.run_for(1.5)
    joystick["v"] = (0.0, 5.0, 0.0, 0.0)
    sim.run_for(2.0)
    queue.user_confirm()  # next command starts from a moving reference
    joystick["v"] = None
    sim.run_for(0.5)
    queue.pause_after_current()
    sim.run_until(
        lambda s: s.queue.status().queue_status is QueueState.WAITING_FOR_BEHAVIOR_AND_CONTINUING, 30
    )
    sim.run_for(1.0)
    queue.user_confirm()
    sim.run_until(index_is(6), 30)  # point
    sim.run_for(1.0)
    queue.stop()  # stop during the wait
    sim.run_for(1.0)
    queue.run()
    sim.run_until(index_is(7), 30)
    sim.run_for(3.0)
    queue.reset()  # reset on the way home
    sim.run_for(3.0)
    queue.add_command(
        FlightCommand(
            vertical=VerticalChannel(VerticalMode.POS, altitude=0, allow_landing=True, speed=1.5),
            end=EndCondition(e_v=True),
        )
    )
    queue.run()
    sim.run_until(index_is(1), 30)  # landed

    assert -sim.p[2] <= 0.02
    assert len(sim.setpoints) > 1000
    assert any(sp.land_now for sp in sim.setpoints)
    violations = step_violations(sim.setpoints, LIMITS)
    assert violations == [], violations[:5]
    # the planner itself stays within the bounds almost always; the guard only trims corner cases
    assert queue.guard_interventions <= len(sim.setpoints) // 100


def test_the_checker_does_detect_a_jump() -> None:
    queue = CommandQueue(LIMITS)
    sim = FlightSim(queue, dt=0.05)
    sim.run_for(1.0)
    sp = sim.setpoints[-1]
    jumped = sp.__class__(
        **{
            **sp.__dict__,
            "t_s": sp.t_s + 0.05,
            "p": (sp.p[0] + 1.0, sp.p[1], sp.p[2]),
            "yaw": sp.yaw + math.radians(10),
        }
    )
    found = {v.quantity for v in step_violations([*sim.setpoints, jumped], LIMITS)}
    assert found == {"dp_h", "dyaw"}
