"""The autopilot parameters an operator may write, with their ranges: the guard of every parameter write.

Seed 003 Sec. II gives the operator "inflight gain tuning for low-level controllers"; a tuning station
(QGroundControl, Mission Planner) writes only parameters it has metadata for, inside their documented
range. Two tables are bundled:

* ``params_arducopter.yaml``: ArduCopter's tunable parameters with the ranges of ArduPilot's parameter
  documentation (rate and angle controllers, position controller, waypoint navigation, loiter, RTL, fence,
  battery and GCS failsafes ...);
* ``params_model.yaml``: every parameter of the autopilot model with the range the model itself enforces
  (:meth:`autopilot_model.params.ParamStore.metadata`; ``python -m autopilot_model.param_table``
  regenerates it and ``tests/test_param_guard.py`` fails when it is stale).

:meth:`ParamTable.check` is the one rule the ground service and the companion both apply: the name must be
in the table, the value a finite number inside ``[min, max]`` (a whole number where the table says
``integer``, one of ``values`` where it lists them), and, while the vehicle flies, within
:data:`MAX_IN_FLIGHT_CHANGE` of the current value (relative) unless the operator forces it. A refusal is a
:class:`ParamWriteError` naming the request's field (``name``, ``value`` or ``force``); nothing is written.
"""

from __future__ import annotations

import functools
import json
import math
from dataclasses import dataclass, field
from typing import Any

import yaml

from mission_specs import bundled

#: the largest relative change of a value accepted while the vehicle is in flight without ``force``
MAX_IN_FLIGHT_CHANGE = 0.5
#: the bundled tables by the autopilot they describe
TABLE_FILES = {"arducopter": "params_arducopter.yaml", "model": "params_model.yaml"}


class ParamWriteError(ValueError):
    """A parameter write refused before anything was sent; ``field`` is the request's field at fault."""

    def __init__(self, field_name: str, message: str) -> None:
        super().__init__(f"{field_name}: {message}")
        self.field = field_name
        self.reason = message


@dataclass(frozen=True)
class ParamSpec:
    """One writable parameter: its range, units and meaning."""

    name: str
    min: float
    max: float
    units: str = ""
    description: str = ""
    integer: bool = False
    values: tuple[float, ...] = field(default_factory=tuple)

    def as_dict(self) -> dict[str, Any]:
        return {"name": self.name, "min": self.min, "max": self.max, "units": self.units,
                "description": self.description, "integer": self.integer, "values": list(self.values)}


@dataclass(frozen=True)
class ParamTable:
    """The writable parameters of one autopilot (``autopilot``: ``arducopter`` or ``model``)."""

    autopilot: str
    params: dict[str, ParamSpec]

    def __contains__(self, name: object) -> bool:
        return name in self.params

    def spec(self, name: str) -> ParamSpec:
        try:
            return self.params[name]
        except KeyError:
            raise ParamWriteError("name", f"{name} is not a parameter this station writes on "
                                  f"{self.autopilot} (not in its table of tunable parameters)") from None

    def check(self, name: str, value: object, old: float | None = None, in_flight: bool = False,
              force: bool = False) -> float:
        """``value`` as a float when a write of ``name`` is acceptable, else :class:`ParamWriteError`."""
        spec = self.spec(name)
        v = check_number(value)
        check_range(spec, v)
        if in_flight and not force and old is not None:
            check_change(spec, old, v)
        return v


def check_number(value: object) -> float:
    """A finite number (not a bool, not an empty or non-numeric string)."""
    if isinstance(value, bool) or value is None or (isinstance(value, str) and not value.strip()):
        raise ParamWriteError("value", "a number is required (the value is empty)")
    try:
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ParamWriteError("value", f"not a number: {value!r}") from None
    if not math.isfinite(v):
        raise ParamWriteError("value", "must be a finite number")
    return v


def check_range(spec: ParamSpec, v: float) -> None:
    """``v`` inside ``spec``'s range, whole where it must be, one of its values where it lists them."""
    unit = f" {spec.units}" if spec.units else ""
    if v < spec.min or v > spec.max:
        raise ParamWriteError("value", f"{spec.name} = {v:g} is out of range "
                              f"[{spec.min:g}, {spec.max:g}]{unit}")
    if spec.integer and v != round(v):
        raise ParamWriteError("value", f"{spec.name} takes whole numbers, not {v:g}")
    if spec.values and not any(math.isclose(v, a, abs_tol=1e-9) for a in spec.values):
        allowed = ", ".join(f"{a:g}" for a in spec.values)
        raise ParamWriteError("value", f"{spec.name} = {v:g} is not one of its values ({allowed})")


def check_change(spec: ParamSpec, old: float, v: float) -> None:
    """In flight: at most :data:`MAX_IN_FLIGHT_CHANGE` of ``old`` (from 0, any change is unbounded)."""
    if math.isclose(v, old, rel_tol=1e-6, abs_tol=1e-9):
        return
    limit = MAX_IN_FLIGHT_CHANGE * abs(old)
    if abs(v - old) > limit:
        pct = "an unbounded" if old == 0 else f"a {abs(v - old) / abs(old):.0%}"
        raise ParamWriteError("force", f"{spec.name}: {old:g} -> {v:g} is {pct} change in flight (at most "
                           f"{MAX_IN_FLIGHT_CHANGE:.0%} without force; the operator may force it)")


def _spec(name: str, e: dict[str, Any]) -> ParamSpec:
    lo, hi = float(e["min"]), float(e["max"])
    if not lo <= hi:
        raise ValueError(f"parameter table: {name}: min {lo} > max {hi}")
    return ParamSpec(name, lo, hi, str(e.get("units") or ""), str(e.get("description") or ""),
                     bool(e.get("integer", False)), tuple(float(x) for x in e.get("values") or ()))


@functools.cache
def table(autopilot: str) -> ParamTable:
    """The bundled table of ``autopilot`` (``arducopter`` or ``model``)."""
    try:
        path = bundled(TABLE_FILES[autopilot])
    except KeyError:
        raise ValueError(f"no parameter table for autopilot {autopilot!r} "
                         f"(tables: {', '.join(TABLE_FILES)})") from None
    text = path.read_text(encoding="utf-8")
    doc = json.loads(text) if path.suffix == ".json" else yaml.safe_load(text)
    return ParamTable(autopilot, {n: _spec(n, e) for n, e in doc["params"].items()})


def known(name: str) -> list[ParamSpec]:
    """``name``'s entries in every bundled table (empty: no table lists it)."""
    return [t.params[name] for t in map(table, TABLE_FILES) if name in t]


__all__ = [
    "MAX_IN_FLIGHT_CHANGE",
    "ParamSpec",
    "ParamTable",
    "ParamWriteError",
    "check_change",
    "check_number",
    "check_range",
    "known",
    "table",
]
