"""Shared by the companion flight tests on simulated time (no tests here): the limits they fly with
and the take-off that starts their flights."""

from __future__ import annotations

from companion.flight import EndCondition, FlightCommand, Limits, VerticalChannel, VerticalMode

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
