"""Flight commands to and from plain dicts, JSON and YAML (the ground service sends them).

The dict form mirrors :mod:`companion.flight.commands` field for field; parameters a mode does not
use are omitted, enums are written by name (frames and modifiers by value)::

    horizontal: {mode: POS, north: 10, east: 5, speed: 3, speed_modified_by: [vertical]}
    vertical:   {mode: POS, altitude: 10, frame: relative}
    heading:    {mode: POINT, north: 0, east: 0}
    end:        {e_h: true, e_v: true}

``end`` is required; a missing channel means DNU. Every error is a
:class:`taskflight_common.yamlio.ConfigError` whose message is ``file:line: field: reason`` (for JSON and
dicts the file is ``<json>`` / ``<input>`` and the line is the JSON syntax error's line, if any);
validation errors of :class:`~companion.flight.commands.CommandError` are reported the same way
with the line of the offending field when the input came from YAML.
"""

from __future__ import annotations

import json
from dataclasses import fields
from pathlib import Path
from typing import Any

import yaml

from taskflight_common.yamlio import ConfigError, Fields, load_yaml, load_yaml_text

from .commands import (
    CommandError,
    EndCondition,
    FlightCommand,
    HeadingChannel,
    HorizontalChannel,
    VerticalChannel,
)

_CHANNELS: dict[str, type] = {"horizontal": HorizontalChannel, "vertical": VerticalChannel,
                              "heading": HeadingChannel}
_BOOL_FIELDS = {"take_off", "allow_landing", "stop_at_heading", "use_sign"}
_STR_FIELDS = {"mode", "frame"}


# --- to plain data ---------------------------------------------------------------------------------
def _channel_to_dict(channel: Any) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for f in fields(channel):
        value = getattr(channel, f.name)
        if f.name == "mode":
            out["mode"] = value.name
        elif f.name in ("take_off", "allow_landing"):
            if value:
                out[f.name] = True
        elif f.name == "speed_modified_by":
            if value:
                out[f.name] = [m.value for m in value]
        elif value is None:
            continue
        elif f.name == "frame":
            out[f.name] = value.value
        else:
            out[f.name] = value
    return out


def command_to_dict(command: FlightCommand) -> dict[str, Any]:
    """Plain-data form (JSON/YAML-ready) of a command."""
    end = command.end
    flags = ("e_h", "e_v", "e_hd", "e_any", "e_user")
    end_dict: dict[str, Any] = {name: True for name in flags if getattr(end, name)}
    if end.e_wait is not None:
        end_dict["e_wait"] = end.e_wait
    return {"horizontal": _channel_to_dict(command.horizontal),
            "vertical": _channel_to_dict(command.vertical),
            "heading": _channel_to_dict(command.heading), "end": end_dict}


# --- from plain data -------------------------------------------------------------------------------
def _line_of(data: Any, dotted: str, fallback: int | None) -> int | None:
    """Line of a dotted field inside YAML-loaded data (best effort)."""
    node, line = data, fallback
    for part in dotted.split("."):
        if isinstance(node, dict) and part in node:
            if hasattr(node, "line_of"):
                line = node.line_of(part) or line
            node = node[part]
        else:
            break
    return line


def _channel_from_fields(f: Fields, cls: type) -> Any:
    names = [x.name for x in fields(cls)]
    f.unknown(names)
    kwargs: dict[str, Any] = {"mode": f.string("mode")}
    for name in names:
        if name == "mode" or not f.has(name):
            continue
        if f.raw(name) is None:
            continue
        if name in _BOOL_FIELDS:
            kwargs[name] = f.boolean(name)
        elif name in _STR_FIELDS:
            kwargs[name] = f.string(name)
        elif name == "speed_modified_by":
            raw = f.raw(name)
            if isinstance(raw, str):
                raw = [raw]
            if not isinstance(raw, list) or not all(isinstance(x, str) for x in raw):
                raise f.error(name, "expected a list of channel names (vertical, heading)")
            kwargs[name] = tuple(raw)
        else:
            kwargs[name] = f.number(name)
    return cls(**kwargs)


def command_from_dict(data: Any, *, file: str | None = None, prefix: str = "",
                      line: int | None = None) -> FlightCommand:
    """Build and validate a command from plain data; errors are :class:`ConfigError`."""
    root = Fields(data, prefix, getattr(data, "file", None) or file, line)
    root.unknown(["horizontal", "vertical", "heading", "end"])
    try:
        parts: dict[str, Any] = {}
        for name, cls in _CHANNELS.items():
            if root.has(name):
                parts[name] = _channel_from_fields(root.sub(name), cls)
        end = root.sub("end")
        end.unknown(["e_h", "e_v", "e_hd", "e_any", "e_user", "e_wait"])
        parts["end"] = EndCondition(
            **{k: end.boolean(k) for k in ("e_h", "e_v", "e_hd", "e_any", "e_user") if end.has(k)},
            e_wait=end.number("e_wait") if end.raw("e_wait", None) is not None else None)
        return FlightCommand(**parts)
    except CommandError as exc:
        dotted = exc.field
        path = f"{prefix}.{dotted}" if prefix else dotted
        raise ConfigError(root.file, _line_of(data, dotted, root.line()), path, exc.reason) from exc


# --- JSON --------------------------------------------------------------------------------------------
def command_to_json(command: FlightCommand) -> str:
    return json.dumps(command_to_dict(command), allow_nan=False)


def _json_load(text: str, file: str) -> Any:
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise ConfigError(file, exc.lineno, None, f"JSON syntax error: {exc.msg}") from exc


def command_from_json(text: str, file: str = "<json>") -> FlightCommand:
    return command_from_dict(_json_load(text, file), file=file)


def commands_to_json(commands: list[FlightCommand]) -> str:
    return json.dumps({"commands": [command_to_dict(c) for c in commands]}, allow_nan=False)


def commands_from_json(text: str, file: str = "<json>") -> list[FlightCommand]:
    return _commands_from_data(_json_load(text, file), file)


# --- YAML --------------------------------------------------------------------------------------------
def commands_to_yaml(commands: list[FlightCommand]) -> str:
    return yaml.safe_dump({"commands": [command_to_dict(c) for c in commands]}, sort_keys=False)


def command_from_yaml(text: str, file: str = "<input>") -> FlightCommand:
    return command_from_dict(load_yaml_text(text, file), file=file)


def commands_from_yaml(text: str, file: str = "<input>") -> list[FlightCommand]:
    """A YAML document holding a list of commands, or a mapping ``{commands: [...]}``."""
    return _commands_from_data(load_yaml_text(text, file), file)


def load_commands(path: str | Path) -> list[FlightCommand]:
    """Read a YAML file of commands (see :func:`commands_from_yaml`)."""
    return _commands_from_data(load_yaml(path), str(path))


def _commands_from_data(data: Any, file: str) -> list[FlightCommand]:
    prefix = ""
    if isinstance(data, dict):
        root = Fields(data, "", file)
        root.unknown(["commands"])
        items = root.raw("commands")
        prefix = "commands"
        if not isinstance(items, list):
            raise root.error("commands", "expected a list of flight commands")
    elif isinstance(data, list):
        items = data
    else:
        raise ConfigError(getattr(data, "file", None) or file, None, None,
                          "expected a list of flight commands or a mapping with 'commands'")
    out = []
    for i, item in enumerate(items):
        line = items.line_of(i) if hasattr(items, "line_of") else None
        out.append(command_from_dict(item, file=file, prefix=f"{prefix}[{i}]", line=line))
    return out
