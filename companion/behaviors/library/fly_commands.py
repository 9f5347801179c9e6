"""FLY_COMMANDS: fly a caller's flight commands (seed 000 Sec. IV-V, the QAPI's command list) as a behavior
of the executive layer (seed 001 Sec. 6.1.2), so that the queue has one writer, the coordinator."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from companion.flight import FlightCommand
from companion.flight.codec import commands_from_json

from ..controller import FlightBehavior, StartError, register


@register
class FlyCommands(FlightBehavior):
    """The control surface's ``POST /commands`` and ``taskflight companion --commands FILE`` with the
    executive layer on. ``commands``: the flight commands as JSON (the flight codec's format,
    :mod:`companion.flight.codec`); ``hold``: queued, not run (the queue waits for ``POST /run``).
    Situation: none beyond the queue being ours (a take-off from the ground is a flight command like
    any other). Goal: every command finished (:meth:`~.BehaviorCoordinator.fly_commands` appends later
    commands of the same requester to it); a failed command ends it ``wrong_progress``, cancelled ones
    (``reset``, a behavior of a higher requester) ``interrupted``. No time-out: a command list may wait for
    the operator (E_User) as long as it says."""

    behavior = "FLY_COMMANDS"

    def commands(self, params: Mapping[str, Any]) -> list[FlightCommand]:
        try:
            commands = commands_from_json(str(params["commands"]), file="commands")
        except ValueError as exc:
            raise StartError(f"commands: {exc}") from None
        if not commands:
            raise StartError("commands: no flight commands")
        return commands

    def on_start(self, params: Mapping[str, Any]) -> None:
        super().on_start(params)
        if params.get("hold"):
            self.ctx.queue.stop()
