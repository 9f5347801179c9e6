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
    E_Wait = ``duration`` (Fig. 7 / Sec. VI-D); goal achieved when it ends (no measured goal). Its
    plan is the duration (:mod:`..timeouts`); a catalog with a plain ``timeout`` number gives the
    margin beyond the duration."""

    behavior = "WAIT"
    measured_goal = False

    def situation(self, params: Mapping[str, Any]) -> str | None:
        if self.ctx.queue.status().queue_system_status.name == "OVERRIDDEN":
            return "the vehicle is controlled elsewhere (a pilot or ground station took it)"
        return None

    def commands(self, params: Mapping[str, Any]) -> list[FlightCommand]:
        return [hold(EndCondition(e_wait=float(params["duration"])))]

    def plan_time_limit(self, params: Mapping[str, Any]) -> float | None:
        if self.descriptor.timeout_plan:
            return super().plan_time_limit(params)
        return float(params["duration"]) + (self.descriptor.timeout_s or 10.0)
