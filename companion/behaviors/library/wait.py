"""WAIT (seed 000 Sec. VI-D, the *wait* task): hold still for ``duration`` seconds."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from companion.flight import EndCondition, FlightCommand

from ..controller import FlightBehavior, register
from ._common import hold


@register
class Wait(FlightBehavior):
    """No situation condition (a wait on the ground is a wait too). One command: all channels DNU,
    E_Wait = ``duration`` (Fig. 7 / Sec. VI-D); goal achieved when it ends. The time-out of the
    catalog does not apply to more than the duration asked for plus its margin."""

    behavior = "WAIT"

    def situation(self, params: Mapping[str, Any]) -> str | None:
        if self.ctx.queue.status().queue_system_status.name == "OVERRIDDEN":
            return "the vehicle is controlled elsewhere (a pilot or ground station took it)"
        return None

    def commands(self, params: Mapping[str, Any]) -> list[FlightCommand]:
        return [hold(EndCondition(e_wait=float(params["duration"])))]

    def monitor(self, now_s: float) -> Any:
        ended = self.performance(now_s)
        if ended is not None or not self.active:
            return ended
        limit = float(self.params["duration"]) + (self.descriptor.timeout_s or 10.0)
        if self.active_time(now_s) > limit:
            from ..controller import Termination, TerminationCause

            return Termination(TerminationCause.TIME_OUT, f"not over after {limit:g} s")
        return None
