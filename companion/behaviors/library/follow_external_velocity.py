"""FOLLOW_EXTERNAL_VELOCITY: fly the operator's joystick (``ext_vel``) until the operator confirms."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from companion.flight import FlightCommand
from companion.flight.pause_routines import joystick_command

from ..controller import FlightBehavior, register
from ._common import need_flying


@register
class FollowExternalVelocity(FlightBehavior):
    """Situation: flying. Opens the ``joystick_feed``; all channels follow its samples (seed 000's
    ExtVel, Fig. 14's external-velocity executor); goal achieved when the operator confirms
    (``user_confirm``). A silent joystick stops the vehicle (the samples' validity runs out)."""

    behavior = "FOLLOW_EXTERNAL_VELOCITY"
    measured_goal = False

    def situation(self, params: Mapping[str, Any]) -> str | None:
        return need_flying(self)

    def commands(self, params: Mapping[str, Any]) -> list[FlightCommand]:
        return [joystick_command()]
