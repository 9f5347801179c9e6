"""Shared by the companion flight tests on simulated time (no tests here): the limits they fly with
and the take-off that starts their flights."""

from __future__ import annotations

from companion.flight import (
    CommandQueue,
    EndCondition,
    Envelope,
    FlightCommand,
    HorizontalChannel,
    HorizontalMode,
    Limits,
    VerticalChannel,
    VerticalMode,
)
from companion.flight.simulate import FlightSim

LIMITS = Limits(
    horizontal_speed=5,
    horizontal_acceleration=2.5,
    horizontal_jerk=5,
    vertical_speed=2,
    vertical_acceleration=1.5,
    vertical_jerk=3,
    yaw_rate=90,
)


def takeoff(alt: float = 5.0) -> FlightCommand:
    return FlightCommand(
        vertical=VerticalChannel(VerticalMode.POS, altitude=alt, take_off=True), end=EndCondition(e_v=True)
    )


def waypoint(n: float, e: float, alt: float, speed: float = 4.0) -> FlightCommand:
    return FlightCommand(
        HorizontalChannel(HorizontalMode.POS, north=n, east=e, speed=speed),
        VerticalChannel(VerticalMode.WITH_HOR, altitude=alt),
        end=EndCondition(e_h=True, e_v=True),
    )


def make_sim(*commands: FlightCommand, envelope: Envelope | None = None, dt: float = 0.05) -> FlightSim:
    queue = CommandQueue(LIMITS, envelope)
    for c in commands:
        queue.add_command(c)
    sim = FlightSim(queue, dt=dt)
    sim.tick()  # the first tick starts the reference at the vehicle
    return sim


def index_is(i: int):
    return lambda sim: sim.queue.status().current_command_index >= i


def airborne(sim: FlightSim, alt: float = 5.0) -> None:
    sim.queue.run()
    sim.run_until(lambda s: s.queue.status().current_command_index >= 1 and s.last.p[2] == -alt, 30)
