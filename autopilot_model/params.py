"""Named parameters of the autopilot model (ArduCopter names where ArduCopter has one).

Gains, envelope limits, failsafe settings and the system id are parameters. Modules read their values
from the :class:`ParamStore` and may subscribe to changes; the MAVLink layer exposes the same store
(PARAM_REQUEST_LIST / READ / SET) and persists it per instance. A rejected ``set`` leaves the value
unchanged and raises :class:`ParamError` saying why.
"""

from __future__ import annotations

import json
import logging
import math
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

log = logging.getLogger(__name__)

PARAM_INT = "int"
PARAM_FLOAT = "float"


class ParamError(ValueError):
    """A parameter could not be set; the stored value is unchanged."""


@dataclass
class ParamDef:
    """Definition and current value of one parameter."""

    name: str
    default: float
    lo: float
    hi: float
    kind: str = PARAM_FLOAT
    doc: str = ""
    value: float = math.nan

    def __post_init__(self) -> None:
        if len(self.name) > 16:
            raise ValueError(f"parameter name '{self.name}' is longer than MAVLink's 16 characters")
        if not (self.lo <= self.default <= self.hi):
            raise ValueError(f"parameter {self.name}: default {self.default} outside [{self.lo}, {self.hi}]")
        if math.isnan(self.value):
            self.value = float(self.default)


class ParamStore:
    """Ordered parameter table with range/type checks, change subscriptions and JSON persistence."""

    def __init__(self) -> None:
        self._defs: dict[str, ParamDef] = {}
        self._subs: list[tuple[str, Callable[[str, float], None]]] = []
        self._path: Path | None = None

    # --- definition ----------------------------------------------------------------------------
    def define(self, name: str, default: float, lo: float, hi: float, kind: str = PARAM_FLOAT,
               doc: str = "") -> None:
        """Declare a parameter; declaring it again keeps the current value (idempotent)."""
        if name in self._defs:
            return
        self._defs[name] = ParamDef(name, float(default), float(lo), float(hi), kind, doc)

    # --- access --------------------------------------------------------------------------------
    def __contains__(self, name: str) -> bool:
        return name in self._defs

    def __len__(self) -> int:
        return len(self._defs)

    def __iter__(self) -> Iterator[ParamDef]:
        return iter(self._defs.values())

    def names(self) -> list[str]:
        return list(self._defs)

    def index_of(self, name: str) -> int:
        return list(self._defs).index(name)

    def by_index(self, index: int) -> ParamDef:
        return list(self._defs.values())[index]

    def definition(self, name: str) -> ParamDef:
        try:
            return self._defs[name]
        except KeyError:
            raise ParamError(f"unknown parameter {name}") from None

    def get(self, name: str) -> float:
        return self.definition(name).value

    def __getitem__(self, name: str) -> float:
        return self.get(name)

    def set(self, name: str, value: float) -> float:
        """Set a parameter after checking type and range; returns the stored value."""
        d = self.definition(name)
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise ParamError(f"{name}: not a number: {value!r}") from None
        if not math.isfinite(v):
            raise ParamError(f"{name}: value must be finite")
        if d.kind == PARAM_INT:
            if abs(v - round(v)) > 1e-6:
                raise ParamError(f"{name}: must be an integer, got {v:g}")
            v = float(round(v))
        if v < d.lo or v > d.hi:
            raise ParamError(f"{name}: {v:g} out of range [{d.lo:g}, {d.hi:g}]")
        if v == d.value:
            return v
        d.value = v
        for prefix, cb in list(self._subs):
            if name.startswith(prefix):
                cb(name, v)
        self._save()
        return v

    def subscribe(self, prefix: str, callback: Callable[[str, float], None]) -> None:
        """Call ``callback(name, value)`` whenever a parameter whose name starts with ``prefix`` changes."""
        self._subs.append((prefix, callback))

    # --- persistence ---------------------------------------------------------------------------
    def attach_file(self, path: str | Path) -> None:
        """Load saved values from ``path`` (unknown or invalid entries are logged and skipped), then
        save every later change there."""
        self._path = Path(path)
        if self._path.exists():
            try:
                saved = json.loads(self._path.read_text(encoding="utf-8"))
            except (OSError, ValueError) as exc:
                log.warning("ignoring unreadable parameter file %s: %s", self._path, exc)
                saved = {}
            for name, value in saved.items():
                if name not in self._defs:
                    log.warning("%s: unknown parameter %s ignored", self._path, name)
                    continue
                try:
                    self._defs[name].value = float(value)
                    d = self._defs[name]
                    if not (d.lo <= d.value <= d.hi):
                        raise ParamError(f"{value} out of range")
                except (ParamError, TypeError, ValueError) as exc:
                    log.warning("%s: parameter %s: %s; default kept", self._path, name, exc)
                    self._defs[name].value = self._defs[name].default

    def _save(self) -> None:
        if self._path is None:
            return
        changed = {d.name: d.value for d in self._defs.values() if d.value != d.default}
        tmp = self._path.with_suffix(".tmp")
        self._path.parent.mkdir(parents=True, exist_ok=True)
        tmp.write_text(json.dumps(changed, indent=1, sort_keys=True), encoding="utf-8")
        os.replace(tmp, self._path)
