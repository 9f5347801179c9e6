"""YAML loading that keeps line numbers, and configuration errors that name file, line and field.

Every configuration file of the project (airframes, module lists, missions, catalogs) is read through
:func:`load_yaml`; a problem is reported as a :class:`ConfigError` whose message reads
``file:line: field: reason`` so the user can go straight to the offending line.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import yaml


class ConfigError(ValueError):
    """A configuration file is malformed; carries the file, the 1-based line and the field path."""

    def __init__(self, file: str | Path | None, line: int | None, field: str | None, reason: str) -> None:
        self.file = str(file) if file is not None else "<input>"
        self.line = line
        self.field = field
        self.reason = reason
        where = self.file if line is None else f"{self.file}:{line}"
        what = f" {field}:" if field else ""
        super().__init__(f"{where}:{what} {reason}")


class LineDict(dict):
    """A mapping read from YAML that remembers on which line each key stood (``line_of``)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.lines: dict[Any, int] = {}
        self.start_line: int | None = None
        self.file: str | None = None

    def line_of(self, key: Any) -> int | None:
        return self.lines.get(key, self.start_line)


class LineList(list):
    """A sequence read from YAML that remembers the line of each item."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.lines: list[int] = []
        self.start_line: int | None = None
        self.file: str | None = None

    def line_of(self, index: int) -> int | None:
        return self.lines[index] if 0 <= index < len(self.lines) else self.start_line


def _make_loader(file: str) -> type[yaml.SafeLoader]:
    class _Loader(yaml.SafeLoader):
        pass

    def construct_mapping(loader: yaml.SafeLoader, node: yaml.MappingNode) -> LineDict:
        loader.flatten_mapping(node)
        out = LineDict()
        out.start_line = node.start_mark.line + 1
        out.file = file
        for key_node, value_node in node.value:
            key = loader.construct_object(key_node, deep=True)
            try:
                hash(key)
            except TypeError as exc:
                raise ConfigError(file, key_node.start_mark.line + 1, None, "unhashable mapping key") from exc
            if key in out:
                raise ConfigError(file, key_node.start_mark.line + 1, str(key), "duplicate key")
            out[key] = loader.construct_object(value_node, deep=True)
            out.lines[key] = key_node.start_mark.line + 1
        return out

    def construct_sequence(loader: yaml.SafeLoader, node: yaml.SequenceNode) -> LineList:
        out = LineList(loader.construct_object(child, deep=True) for child in node.value)
        out.lines = [child.start_mark.line + 1 for child in node.value]
        out.start_line = node.start_mark.line + 1
        out.file = file
        return out

    _Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, construct_mapping)
    _Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_SEQUENCE_TAG, construct_sequence)
    return _Loader


def load_yaml_text(text: str, file: str = "<input>") -> Any:
    """Parse YAML text; syntax errors become :class:`ConfigError` with the line of the problem."""
    try:
        return yaml.load(text, Loader=_make_loader(file))  # a SafeLoader subclass
    except ConfigError:
        raise
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = mark.line + 1 if mark is not None else None
        raise ConfigError(file, line, None, f"YAML syntax error: {exc.problem or exc}") from exc
    except yaml.YAMLError as exc:
        raise ConfigError(file, None, None, f"YAML error: {exc}") from exc


def load_yaml(path: str | Path) -> Any:
    """Read and parse a YAML file, keeping line numbers (see :class:`LineDict`)."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(p, None, None, f"cannot read file: {exc.strerror or exc}") from exc
    return load_yaml_text(text, str(p))


class Fields:
    """Typed access to one YAML mapping, raising :class:`ConfigError` naming file, line and field.

    ``prefix`` is the dotted path of the mapping inside the file (``"motors"``, ``"modules[2]"``).
    """

    def __init__(self, data: Any, prefix: str = "", file: str | None = None, line: int | None = None) -> None:
        self.prefix = prefix
        self.file = getattr(data, "file", None) or file
        self._line = getattr(data, "start_line", None) or line
        if not isinstance(data, dict):
            raise ConfigError(self.file, self._line, prefix or None, f"expected a mapping, got {_kind(data)}")
        self.data = data

    def path(self, key: str) -> str:
        return f"{self.prefix}.{key}" if self.prefix else key

    def line(self, key: str | None = None) -> int | None:
        if key is not None and isinstance(self.data, LineDict):
            return self.data.line_of(key)
        return self._line

    def error(self, key: str | None, reason: str) -> ConfigError:
        field = self.path(key) if key else (self.prefix or None)
        return ConfigError(self.file, self.line(key), field, reason)

    def has(self, key: str) -> bool:
        return key in self.data

    def raw(self, key: str, default: Any = ...) -> Any:
        if key not in self.data:
            if default is ...:
                raise self.error(None, f"missing required field '{self.path(key)}'")
            return default
        return self.data[key]

    def number(self, key: str, default: Any = ..., *, lo: float | None = None,
               hi: float | None = None, positive: bool = False) -> float:
        value = self.raw(key, default)
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.error(key, f"expected a number, got {_kind(value)}")
        value = float(value)
        if not math.isfinite(value):
            raise self.error(key, "must be finite")
        if positive and value <= 0:
            raise self.error(key, f"must be > 0, got {value:g}")
        if lo is not None and value < lo:
            raise self.error(key, f"must be >= {lo:g}, got {value:g}")
        if hi is not None and value > hi:
            raise self.error(key, f"must be <= {hi:g}, got {value:g}")
        return value

    def integer(self, key: str, default: Any = ..., *, lo: int | None = None, hi: int | None = None) -> int:
        value = self.raw(key, default)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(key, f"expected an integer, got {_kind(value)}")
        if lo is not None and value < lo:
            raise self.error(key, f"must be >= {lo}, got {value}")
        if hi is not None and value > hi:
            raise self.error(key, f"must be <= {hi}, got {value}")
        return value

    def string(self, key: str, default: Any = ..., *, choices: Iterable[str] | None = None) -> str:
        value = self.raw(key, default)
        if not isinstance(value, str):
            raise self.error(key, f"expected a string, got {_kind(value)}")
        if choices is not None:
            allowed = list(choices)
            if value not in allowed:
                raise self.error(key, f"must be one of {', '.join(allowed)}; got '{value}'")
        return value

    def boolean(self, key: str, default: Any = ...) -> bool:
        value = self.raw(key, default)
        if not isinstance(value, bool):
            raise self.error(key, f"expected true or false, got {_kind(value)}")
        return value

    def vector(self, key: str, n: int, default: Any = ...) -> tuple[float, ...]:
        value = self.raw(key, default)
        if not isinstance(value, list | tuple) or len(value) != n:
            raise self.error(key, f"expected a list of {n} numbers")
        for item in value:
            if isinstance(item, bool) or not isinstance(item, int | float) or not math.isfinite(item):
                raise self.error(key, f"expected a list of {n} finite numbers")
        return tuple(float(v) for v in value)

    def sub(self, key: str, default: Any = ...) -> Fields:
        value = self.raw(key, default)
        return Fields(value, self.path(key), self.file, self.line(key))

    def unknown(self, allowed: Iterable[str]) -> None:
        """Reject keys that are not in ``allowed`` (a typo must not be silently ignored)."""
        allowed_set = set(allowed)
        for key in self.data:
            if key not in allowed_set:
                raise self.error(str(key), f"unknown field (allowed: {', '.join(sorted(allowed_set))})")


def _kind(value: Any) -> str:
    if value is None:
        return "nothing"
    if isinstance(value, bool):
        return f"boolean {value}"
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, list):
        return "a list"
    if isinstance(value, str):
        return f"string '{value}'"
    return f"{type(value).__name__} {value!r}"
