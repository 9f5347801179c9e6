"""The take-off's "stopped if allowed" rule of the QAPI (seed 000 Sec. V), as a part the queue owns.

"Stopped if allowed" during a take-off (Sec. V)
    A take-off that has not yet left the ground (its execution has not advanced: the link holds the
    queue's time while the autopilot arms and lifts off; the link marks the lift-off with
    ``CommandQueue.mark_takeoff_airborne``) stops at once; the link then cancels the take-off (nothing
    arms, or it disarms). Once climbing, it may not be stopped until its reference is ``min_hold_m``
    above where it started: ``stop``, ``pause_direct``, ``reset`` and ``replace_commands`` given in
    that window are *deferred* (status ``deferred``, a DEFERRED event) and carried out there, so the
    vehicle never hovers armed a few centimetres above the ground. ``run()`` cancels a deferred stop
    or pause; a later ``reset`` or ``replace_commands`` supersedes a deferred one (its commands are
    CANCELLED).

:class:`TakeoffStopRule` decides and remembers the deferred verb; the
:class:`~.queue.CommandQueue` owns one, calls it under its lock, and carries the verbs out (emits
the events, stops, resets): the rule reads the queue only through the arguments it is given.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from .qapi import QueuedCommand, QueueStateError

if TYPE_CHECKING:
    from .execution import CommandExecution
    from .pause_routines import PauseRoutine
    from .reference import Reference

#: A climbing take-off may not be stopped below this height above where it started (m).
TAKEOFF_MIN_HOLD_M = 1.0
#: Without word from the link, a take-off whose reference rose this much (m) has left the ground.
TAKEOFF_CLIMBING_M = 0.05

#: deferrable verbs that keep the command list (``run()`` cancels them) ...
_PAUSING = ("stop", "pause_direct")
#: ... and those that drop it (only another of these supersedes them)
_RESETTING = ("reset", "replace")


@dataclass(frozen=True)
class DeferredVerb:
    """A verb waiting until the take-off may stop."""

    verb: str  # "stop", "pause_direct", "reset" or "replace"
    routine: PauseRoutine | None = None  # pause_direct's pause routine
    entries: tuple[QueuedCommand, ...] = ()  # replace_commands' new list (no ADDED event yet)


class TakeoffStopRule:
    """When a verb must wait for the take-off, and which verb waits (module docstring)."""

    def __init__(self, min_hold_m: float = TAKEOFF_MIN_HOLD_M) -> None:
        self.min_hold_m = float(min_hold_m)
        self.deferred: DeferredVerb | None = None

    def unstoppable(self, execution: CommandExecution | None, ref: Reference | None) -> bool:
        """A climbing take-off still below its minimum hold height.

        ``execution``: the queue's own command executing (None when the queue is stopped or in a
        pause routine); ``ref``: the queue's reference. Climbing: the link said it lifted off
        (``execution.airborne``), or, with no link (a simulation), the reference has left the start
        altitude."""
        ex = execution
        if ex is None or not ex.command.vertical.take_off or ex.ended or ref is None:
            return False
        climbing = ex.airborne or ref.altitude - ex.start_altitude >= TAKEOFF_CLIMBING_M
        return climbing and ref.altitude < ex.start_altitude + self.min_hold_m

    def defer(self, verb: str, routine: PauseRoutine | None = None,
              entries: Sequence[QueuedCommand] = ()) -> list[QueuedCommand]:
        """Make ``verb`` the deferred one; returns the commands of a deferred ``replace`` it
        supersedes (the queue cancels them). :class:`QueueStateError` for a stop or pause while a
        reset or replace waits (nothing changes then)."""
        pending = self.deferred
        if pending is not None and pending.verb in _RESETTING and verb not in _RESETTING:
            raise QueueStateError(f"{verb}: a {pending.verb} is already deferred until the take-off may stop")
        superseded = list(pending.entries) if pending is not None and pending.verb == "replace" else []
        self.deferred = DeferredVerb(verb, routine, tuple(entries))
        return superseded

    def cancel_pause(self) -> str | None:
        """``run()``: forget a deferred stop or pause_direct; returns the verb forgotten."""
        if self.deferred is None or self.deferred.verb not in _PAUSING:
            return None
        verb, self.deferred = self.deferred.verb, None
        return verb

    def take(self) -> DeferredVerb | None:
        """The deferred verb, forgotten here (the queue carries it out or drops it)."""
        deferred, self.deferred = self.deferred, None
        return deferred
