"""In-flight retarget of the running flight command (seed 000 Sec. IV-D).

Seed 000 Sec. IV-D: "the target parameters P_t of a flight command can be changed during its
execution"; the setpoint generator then moves P_d towards the new P_t within the envelope limits,
so the stream stays continuous. :func:`retargeted` builds the command as it reads after the change
(validated like any command); the queue swaps it into the running execution.

What can change, and in which modes (anything else is refused with :class:`RetargetError`):

* ``north``, ``east`` (m, local NED, absolute): horizontal POS. A missing one keeps the target's.
* ``altitude`` (m up, absolute): vertical POS or WITH_HOR.
* ``speed`` (m/s): horizontal POS, EXT_POS, KEEP_DISTANCE (``end_speed`` is capped to it).
* ``heading`` (degrees, absolute): heading POS.

Changed position channels become absolute; the others keep their frame and resolved targets.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from .commands import (
    FlightCommand,
    Frame,
    HeadingMode,
    HorizontalMode,
    VerticalMode,
)
from .execution import CommandExecution


class RetargetError(ValueError):
    """A retarget that does not fit the running command; nothing changed."""


@dataclass(frozen=True)
class Retarget:
    """The new values (None: unchanged)."""

    north: float | None = None
    east: float | None = None
    altitude: float | None = None
    speed: float | None = None
    heading: float | None = None

    def is_empty(self) -> bool:
        return all(v is None for v in (self.north, self.east, self.altitude, self.speed, self.heading))

    def describe(self) -> str:
        return ", ".join(f"{k}={v:g}" for k, v in (("north", self.north), ("east", self.east),
                                                   ("altitude", self.altitude), ("speed", self.speed),
                                                   ("heading", self.heading)) if v is not None)


def retargeted(command: FlightCommand, execution: CommandExecution, change: Retarget
               ) -> tuple[FlightCommand, frozenset[str]]:
    """The command after ``change`` and the channels whose targets changed ("h", "v", "hd")."""
    if change.is_empty():
        raise RetargetError("retarget: nothing to change (give north/east, altitude, speed or heading)")
    h, v, hd = command.horizontal, command.vertical, command.heading
    changed: set[str] = set()
    if change.north is not None or change.east is not None:
        if h.mode is not HorizontalMode.POS or execution.h_target is None:
            raise RetargetError(f"retarget: a new position needs horizontal mode POS, not {h.mode.name}")
        north = change.north if change.north is not None else float(execution.h_target[0])
        east = change.east if change.east is not None else float(execution.h_target[1])
        h = replace(h, north=north, east=east, frame=Frame.ABSOLUTE)
        changed.add("h")
    if change.speed is not None:
        if h.mode not in (HorizontalMode.POS, HorizontalMode.EXT_POS, HorizontalMode.KEEP_DISTANCE):
            raise RetargetError(f"retarget: horizontal mode {h.mode.name} has no speed")
        end_speed = min(h.end_speed, change.speed) if h.end_speed is not None else None
        h = replace(h, speed=change.speed, end_speed=end_speed)
        changed.add("h_speed")
    if change.altitude is not None:
        if v.mode is VerticalMode.POS:
            v = replace(v, altitude=change.altitude, frame=Frame.ABSOLUTE)
        elif v.mode is VerticalMode.WITH_HOR:
            v = replace(v, altitude=change.altitude)
        else:
            raise RetargetError(f"retarget: a new altitude needs vertical mode POS or WITH_HOR, "
                                f"not {v.mode.name}")
        changed.add("v")
    if change.heading is not None:
        if hd.mode is not HeadingMode.POS:
            raise RetargetError(f"retarget: a new heading needs heading mode POS, not {hd.mode.name}")
        hd = replace(hd, heading=change.heading, frame=Frame.ABSOLUTE)
        changed.add("hd")
    return FlightCommand(h, v, hd, command.end), frozenset(changed)
