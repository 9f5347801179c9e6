"""KEEP_MOVING (seed 001 Sec. 5.1.2): move at a constant ``velocity`` (north, east, up) m/s until stopped."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from companion.flight import (
    EndCondition,
    FlightCommand,
    HeadingChannel,
    HeadingMode,
    HorizontalChannel,
    HorizontalMode,
    VerticalChannel,
    VerticalMode,
)

from ..controller import FlightBehavior, Termination, TerminationCause, register
from ..services import VelocitySource
from ._common import need_flying


@register
class KeepMoving(FlightBehavior):
    """Situation: flying. The ``velocity_source`` process streams the velocity as ``ext_vel`` samples;
    the command flies both motion channels from that stream (the link streams velocity targets). It
    has no goal (and no plan, hence no time-out unless the catalog gives a fixed one): it runs until
    another behavior replaces it or the envelope stops it (``wrong_progress``: the limit is reached
    and the vehicle no longer moves)."""

    behavior = "KEEP_MOVING"
    measured_goal = False

    def situation(self, params: Mapping[str, Any]) -> str | None:
        return need_flying(self)

    def commands(self, params: Mapping[str, Any]) -> list[FlightCommand]:
        source = self.ctx.processes.get("velocity_source")
        assert isinstance(source, VelocitySource)
        source.set_velocity(tuple(params["velocity"]))
        return [FlightCommand(HorizontalChannel(HorizontalMode.EXT_VEL),
                              VerticalChannel(VerticalMode.EXT_VEL),
                              HeadingChannel(HeadingMode.DNU), EndCondition(e_user=True))]

    def performance(self, now_s: float) -> Termination | None:
        ended = super().performance(now_s)
        if ended is not None:
            return ended
        status = self.ctx.queue.status()
        vehicle = self.ctx.vehicle()
        if status.limit_reached and vehicle is not None and self.active_time(now_s) > 1.0 \
                and sum(v * v for v in vehicle.v) ** 0.5 < 0.2:
            return Termination(TerminationCause.WRONG_PROGRESS,
                               "stopped at the edge of the operational envelope")
        return None
