"""Named parameters of the autopilot model (ArduCopter names where ArduCopter has one).

Gains, envelope limits, failsafe settings and the system id are parameters. Modules read their values
from the :class:`ParamStore` and may subscribe to changes; the MAVLink layer exposes the same store
(PARAM_REQUEST_LIST / READ / SET) and persists it per instance. A rejected ``set`` leaves the value
unchanged and raises :class:`ParamError` saying why.

Every value a module sees is the flown value, as in ArduCopter, which loads its saved parameters from
storage (``AP_Param::load_all``) before any library reads them:

* the saved file may be attached before the pieces declare their parameters (the vehicle does so): a
  saved value is applied when its parameter is declared, so whatever a module copies in its constructor
  is already the saved value;
* a file attached later, and every :meth:`ParamStore.set`, go through the change subscriptions, so a
  module that copies a value (the controller's gain vector) follows it;
* the airframe's values are *defaults* (:meth:`ParamStore.set_default`, ArduPilot's defaults file):
  a saved value wins over them.
"""

from __future__ import annotations

import json
import logging
import math
import os
import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import SupportsFloat

log = logging.getLogger(__name__)

PARAM_INT = "int"
PARAM_FLOAT = "float"
#: words a doc puts in parentheses that are not units
_NOT_UNITS = frozenset({"stored", "down"})


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
    values: tuple[float, ...] = ()
    """The only values allowed (ArduPilot's ``@Values`` where the model flies only some); empty: any
    value in [lo, hi]."""

    def __post_init__(self) -> None:
        if len(self.name) > 16:
            raise ValueError(f"parameter name '{self.name}' is longer than MAVLink's 16 characters")
        if not (self.lo <= self.default <= self.hi):
            raise ValueError(f"parameter {self.name}: default {self.default} outside [{self.lo}, {self.hi}]")
        if self.values and self.default not in self.values:
            raise ValueError(f"parameter {self.name}: default {self.default} not one of {self.values}")
        if math.isnan(self.value):
            self.value = float(self.default)


class ParamStore:
    """Ordered parameter table with range/type checks, change subscriptions and JSON persistence."""

    def __init__(self) -> None:
        self._defs: dict[str, ParamDef] = {}
        self._subs: list[tuple[str, Callable[[str, float], None]]] = []
        self._path: Path | None = None
        self._pending: dict[str, object] = {}
        """Saved values of parameters not declared yet (applied by :meth:`define`)."""
        self._loaded: set[str] = set()
        """Parameters whose value came from the saved file (an airframe default does not override)."""

    # --- definition ----------------------------------------------------------------------------
    def define(self, name: str, default: float, lo: float, hi: float, kind: str = PARAM_FLOAT,
               doc: str = "", values: tuple[float, ...] = ()) -> None:
        """Declare a parameter; declaring it again keeps the current value (idempotent). ``values``: the
        only values allowed (a set to refuse anything else, saying which are allowed and why in ``doc``)."""
        if name in self._defs:
            return
        self._defs[name] = ParamDef(name, float(default), float(lo), float(hi), kind, doc,
                                    values=tuple(float(v) for v in values))
        if name in self._pending:
            self._load_value(name, self._pending.pop(name))

    def set_default(self, name: str, value: float) -> float:
        """Make ``value`` the default of ``name`` (an airframe's value; ArduPilot's defaults file); the
        current value follows unless a saved value was loaded. Returns the current value."""
        d = self.definition(name)
        v = self._check(d, value)
        d.default = v
        if name not in self._loaded:
            self._apply(d, v)
        return d.value

    # --- access --------------------------------------------------------------------------------
    def __contains__(self, name: str) -> bool:
        return name in self._defs

    def __len__(self) -> int:
        return len(self._defs)

    def __iter__(self) -> Iterator[ParamDef]:
        return iter(self._defs.values())

    def names(self) -> list[str]:
        return list(self._defs)

    def metadata(self) -> dict[str, dict[str, object]]:
        """Every parameter's range and meaning, by name, as the guard of parameter writes reads it
        (``mission_specs/params_model.yaml``, written by :mod:`autopilot_model.param_table`): ``min``,
        ``max``, ``units`` (the doc's first parenthesis), ``description``, ``integer`` and ``values``."""
        out: dict[str, dict[str, object]] = {}
        for d in self._defs.values():
            m = re.search(r"\(([^(),\s]{1,12})[),]", d.doc)  # the doc's first "(unit)" or "(unit, ..."
            units = m.group(1) if m and m.group(1) not in _NOT_UNITS and "_" not in m.group(1) else ""
            entry: dict[str, object] = {"min": d.lo, "max": d.hi, "units": units, "description": d.doc,
                                        "integer": d.kind == PARAM_INT}
            if d.values:
                entry["values"] = list(d.values)
            out[d.name] = entry
        return out

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
        v = self._check(d, value)
        if self._apply(d, v):
            self._save()
        return v

    @staticmethod
    def _check(d: ParamDef, value: object) -> float:
        """``value`` as ``d`` stores it, or :class:`ParamError`."""
        name = d.name
        try:
            if not isinstance(value, SupportsFloat | str):
                raise TypeError(type(value).__name__)
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
        if d.values and v not in d.values:
            allowed = ", ".join(f"{a:g}" for a in d.values)
            raise ParamError(f"{name}: {v:g} not supported (allowed: {allowed}; {d.doc})")
        return v

    def _apply(self, d: ParamDef, v: float) -> bool:
        """Store a checked value and tell the subscribers; returns whether it changed."""
        if v == d.value:
            return False
        d.value = v
        for prefix, cb in list(self._subs):
            if d.name.startswith(prefix):
                cb(d.name, v)
        return True

    def subscribe(self, prefix: str, callback: Callable[[str, float], None]) -> None:
        """Call ``callback(name, value)`` whenever a parameter whose name starts with ``prefix`` changes."""
        self._subs.append((prefix, callback))

    # --- persistence ---------------------------------------------------------------------------
    def attach_file(self, path: str | Path) -> None:
        """Load saved values from ``path``, then save every later change there.

        A saved value of a declared parameter is applied at once (subscribers are told, as for
        :meth:`set`); one of a parameter not declared yet is applied when it is declared. Invalid
        entries are logged and skipped (the default is kept); see :meth:`unknown_saved` for names no
        piece declared."""
        self._path = Path(path)
        if not self._path.exists():
            return
        try:
            saved = json.loads(self._path.read_text(encoding="utf-8"))
            if not isinstance(saved, dict):
                raise ValueError("not a JSON object")
        except (OSError, ValueError) as exc:
            log.warning("ignoring unreadable parameter file %s: %s", self._path, exc)
            return
        for name, value in saved.items():
            if name in self._defs:
                self._load_value(name, value)
            else:
                self._pending[str(name)] = value

    def unknown_saved(self) -> list[str]:
        """Saved names that no piece has declared (kept in the file, not applied)."""
        return sorted(self._pending)

    def _load_value(self, name: str, value: object) -> None:
        d = self._defs[name]
        try:
            v = self._check(d, value)
        except ParamError as exc:
            log.warning("%s: parameter %s: %s; default kept", self._path, name, exc)
            return
        self._loaded.add(name)
        self._apply(d, v)

    def _save(self) -> None:
        if self._path is None:
            return
        changed: dict[str, object] = dict(self._pending)
        changed.update({d.name: d.value for d in self._defs.values() if d.value != d.default})
        tmp = self._path.with_suffix(".tmp")
        self._path.parent.mkdir(parents=True, exist_ok=True)
        tmp.write_text(json.dumps(changed, indent=1, sort_keys=True), encoding="utf-8")
        os.replace(tmp, self._path)
