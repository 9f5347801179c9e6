"""Predefined pause routines for ``pause_direct`` / ``pause_after_current`` (seed 000 Sec. V).

"A behavior in this context is a predefined sequence of one or more flight commands which is used
for a number of typical behaviors such as joystick control (ExtVel). After this predefined
routine is finished, the execution resumes with the next command on the list."

Built in (:func:`default_catalog`):

* ``hover`` (the default): all channels DNU (hold where the reference is), ends on user_confirm.
* ``joystick``: all channels ExtVel from the ``ext_vel`` stream, ends on user_confirm.

A catalog can also be read from YAML (errors name file, line and field)::

    pause_routines:
      - id: look_around
        description: turn once, then go on
        commands:
          - {heading: {mode: POS, heading: 359, frame: relative, rate: 30, use_sign: true}, end: {e_hd: true}}
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from taskflight_common.yamlio import ConfigError, Fields, load_yaml, load_yaml_text

from .codec import command_from_dict
from .commands import (
    EndCondition,
    FlightCommand,
    HeadingChannel,
    HeadingMode,
    HorizontalChannel,
    HorizontalMode,
    VerticalChannel,
    VerticalMode,
)

DEFAULT_ROUTINE = "hover"


@dataclass(frozen=True)
class PauseRoutine:
    """A named, non-empty sequence of flight commands run during a pause."""

    id: str
    commands: tuple[FlightCommand, ...]
    description: str = ""

    def __post_init__(self) -> None:
        if not self.id or not isinstance(self.id, str):
            raise ValueError("routine id must be a non-empty string")
        if not self.commands:
            raise ValueError(f"routine {self.id!r} has no commands")


class PauseRoutineCatalog:
    """Pause routines by id; immutable once built."""

    def __init__(self, pause_routines: Iterable[PauseRoutine]) -> None:
        self._by_id: dict[str, PauseRoutine] = {}
        for b in pause_routines:
            if b.id in self._by_id:
                raise ValueError(f"routine {b.id!r} defined twice")
            self._by_id[b.id] = b

    def get(self, routine_id: str) -> PauseRoutine:
        try:
            return self._by_id[routine_id]
        except KeyError:
            raise KeyError(f"unknown routine {routine_id!r} (known: {', '.join(sorted(self._by_id))})") \
                from None

    def __contains__(self, routine_id: object) -> bool:
        return routine_id in self._by_id

    def ids(self) -> list[str]:
        return sorted(self._by_id)

    def merged(self, other: PauseRoutineCatalog) -> PauseRoutineCatalog:
        """This catalog with ``other``'s pause_routines added or replacing same-id ones."""
        merged = dict(self._by_id)
        merged.update(other._by_id)
        return PauseRoutineCatalog(merged.values())


def hover_command() -> FlightCommand:
    """Hold where the reference is until user_confirm."""
    return FlightCommand(HorizontalChannel(HorizontalMode.DNU), VerticalChannel(VerticalMode.DNU),
                         HeadingChannel(HeadingMode.DNU), EndCondition(e_user=True))


def joystick_command() -> FlightCommand:
    """All channels from the ``ext_vel`` stream until user_confirm."""
    return FlightCommand(HorizontalChannel(HorizontalMode.EXT_VEL), VerticalChannel(VerticalMode.EXT_VEL),
                         HeadingChannel(HeadingMode.EXT_VEL), EndCondition(e_user=True))


def default_catalog() -> PauseRoutineCatalog:
    return PauseRoutineCatalog([
        PauseRoutine("hover", (hover_command(),), "hold position until user_confirm"),
        PauseRoutine("joystick", (joystick_command(),),
                       "all channels ExtVel (ext_vel stream) until user_confirm"),
    ])


def catalog_from_data(data: Any, file: str | None = None) -> PauseRoutineCatalog:
    root = Fields(data, "", file)
    root.unknown(["pause_routines"])
    items = root.raw("pause_routines")
    if not isinstance(items, list) or not items:
        raise root.error("pause_routines", "expected a non-empty list of pause_routines")
    out: list[PauseRoutine] = []
    seen: set[str] = set()
    for i, item in enumerate(items):
        line = items.line_of(i) if hasattr(items, "line_of") else None
        f = Fields(item, f"pause_routines[{i}]", root.file, line)
        f.unknown(["id", "description", "commands"])
        bid = f.string("id")
        if not bid:
            raise f.error("id", "must not be empty")
        if bid in seen:
            raise f.error("id", f"routine {bid!r} defined twice")
        seen.add(bid)
        cmds = f.raw("commands")
        if not isinstance(cmds, list) or not cmds:
            raise f.error("commands", "expected a non-empty list of flight commands")
        commands = tuple(command_from_dict(c, file=root.file, prefix=f"{f.path('commands')}[{j}]",
                                           line=cmds.line_of(j) if hasattr(cmds, "line_of") else None)
                         for j, c in enumerate(cmds))
        out.append(PauseRoutine(bid, commands, f.string("description", "")))
    return PauseRoutineCatalog(out)


def load_catalog(path: str | Path) -> PauseRoutineCatalog:
    """Read a routine catalog from YAML, on top of the built-in one (same ids replace)."""
    return default_catalog().merged(catalog_from_data(load_yaml(path), str(path)))


def catalog_from_yaml(text: str, file: str = "<input>") -> PauseRoutineCatalog:
    data = load_yaml_text(text, file)
    if data is None:
        raise ConfigError(file, None, None, "empty routine catalog")
    return default_catalog().merged(catalog_from_data(data, file))
