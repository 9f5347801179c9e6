"""The leaf task types of a TST and their parameters, as seed 000 Sec. VI, Fig. 11a-14a list them.

``TASK_TYPES`` maps a task type name to a :class:`TaskType`, whose :meth:`TaskType.validate` turns the
parameters written in a mission into checked, normalized values (defaults filled in) or constraints.

Paper names are kept. Two spellings differ in the paper itself and are settled here: Fig. 12a's
``commanded-speed`` is ``commanded_speed`` (the hyphenated form is accepted as an alias) and Fig. 14a's
``generate_scan_specs_flag`` is used (the text also writes ``generate_scan_spec_flag``, accepted too).

Where the paper is silent we chose, and say so in the parameter's ``meaning``:

* wait: the duration's name (``duration``, s) — Sec. VI-D only says "the amount of time to wait";
* external-velocity: Sec. VI-F lists no parameter; ``source`` (the external feed, default ``joystick``)
  is ours;
* scan-ground ``loiter_mode``: Fig. 14a gives no values; ours are ``pass`` (fly through the waypoint) and
  ``stop`` (come to rest at it);
* hover and request-operator-assistance are not in the paper: they serve the behaviors layer (the WHILE/IF
  mission of "scan until a person is seen, then hover over it and ask the operator").
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from companion.tst.params import (
    Interval,
    LinearRelation,
    ParamError,
    Qualitative,
    check_area,
    check_geopoint,
    check_geopoints,
    is_free,
    parse_constraint,
)

#: Parameter kinds: how a value is written and checked.
KINDS = ("geopoint", "area", "waypoints", "float", "bool", "string", "qualitative")


@dataclass(frozen=True)
class ParamSpec:
    """One input parameter of a task type (a row of Fig. 12a, 13a or 14a)."""

    name: str
    kind: str
    meaning: str
    required: bool = False
    default: Any = None
    unit: str | None = None
    options: tuple[str, ...] = ()  #: the allowed qualitative values (kind ``qualitative``)
    minimum: float | None = None   #: lowest allowed number (kind ``float``)

    def normalize(self, value: Any) -> Any:
        """The checked value, or the constraint when the parameter is free; raises :class:`ParamError`."""
        try:
            return self._normalize(value)
        except ParamError as exc:
            raise ParamError(exc.reason, self.name, exc.index) from None

    def _normalize(self, value: Any) -> Any:
        if self.kind in ("float", "qualitative"):
            constraint = parse_constraint(value)
            if constraint is not None:
                return self._check_constraint(constraint)
        if self.kind == "geopoint":
            return check_geopoint(value, 3)
        if self.kind == "area":
            return check_area(value)
        if self.kind == "waypoints":
            return check_geopoints(value, sizes=(2, 3), minimum=1)
        if self.kind == "bool":
            if not isinstance(value, bool):
                raise ParamError(f"expected true or false, got {value!r}")
            return value
        if self.kind == "string":
            if not isinstance(value, str):
                raise ParamError(f"expected a string, got {value!r}")
            return value
        if self.kind == "qualitative":
            if not isinstance(value, str) or value not in self.options:
                raise ParamError(f"expected one of {', '.join(self.options)}; got {value!r}")
            return value
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ParamError(f"expected a number{f' ({self.unit})' if self.unit else ''}, got {value!r}")
        number = float(value)
        if number != number or number in (float("inf"), float("-inf")):
            raise ParamError("must be finite")
        if self.minimum is not None and number < self.minimum:
            raise ParamError(f"must be >= {self.minimum:g}{self._unit()}, got {number:g}")
        return number

    def _check_constraint(self, c: Interval | Qualitative | LinearRelation) -> Any:
        if isinstance(c, Qualitative):
            if self.kind != "qualitative":
                raise ParamError(f"qualitative values ({c}) given for a number")
            bad = [o for o in c.options if o not in self.options]
            if bad:
                raise ParamError(f"unknown value {bad[0]!r} (allowed: {', '.join(self.options)})")
            return c
        if self.kind != "float":
            raise ParamError(f"{'an interval' if isinstance(c, Interval) else 'a relation'} given for a "
                             f"qualitative parameter (allowed: {', '.join(self.options)})")
        if isinstance(c, Interval) and self.minimum is not None and c.lo < self.minimum:
            raise ParamError(f"interval {c} goes below the minimum {self.minimum:g}{self._unit()}")
        if isinstance(c, LinearRelation) and self.name not in c.names:
            raise ParamError(f"relation {c.text!r} does not mention {self.name}")
        return c

    def _unit(self) -> str:
        return f" {self.unit}" if self.unit else ""


@dataclass(frozen=True)
class TaskType:
    """A leaf task type: its parameters and the rules that relate them (``check``)."""

    name: str
    figure: str
    doc: str
    params: tuple[ParamSpec, ...] = ()
    aliases: Mapping[str, str] = field(default_factory=dict)
    check: Callable[[dict[str, Any]], None] | None = None

    def param(self, name: str) -> ParamSpec | None:
        for p in self.params:
            if p.name == name:
                return p
        return None

    @property
    def param_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.params)

    def validate(self, raw: Mapping[str, Any] | None) -> dict[str, Any]:
        """Checked parameters with defaults filled in; raises :class:`ParamError` naming the parameter."""
        raw = dict(raw or {})
        out: dict[str, Any] = {}
        for key, value in raw.items():
            name = self.aliases.get(key, key) if isinstance(key, str) else key
            spec = self.param(name) if isinstance(name, str) else None
            if spec is None:
                known = ", ".join(self.param_names) or "none"
                raise ParamError(f"unknown parameter of {self.name} (known: {known})", str(key))
            if name in out:
                raise ParamError(f"given twice (as {key} and {name})", str(key))
            out[name] = spec.normalize(value)
        for spec in self.params:
            if spec.name in out:
                continue
            if spec.required:
                raise ParamError(f"missing required parameter of {self.name}", spec.name)
            if spec.default is not None:
                out[spec.name] = spec.default
        if self.check is not None:
            self.check(out)
        return out


def _fly_to_check(p: dict[str, Any]) -> None:
    if "speed" in p and "commanded_speed" in p:
        raise ParamError("give speed or commanded_speed, not both (Fig. 12a: two ways)", "commanded_speed")
    _follow_ground_check(p)


def _follow_ground_check(p: dict[str, Any]) -> None:
    if p.get("follow_ground_flag") is True and "follow_ground_altitude" not in p:
        raise ParamError("required when follow_ground_flag is true", "follow_ground_altitude")
    if p.get("follow_ground_flag") is not True and "follow_ground_altitude" in p:
        raise ParamError("only meaningful when follow_ground_flag is true", "follow_ground_altitude")


def _land_check(p: dict[str, Any]) -> None:
    flag = p.get("land_at_current_position_flag")
    if flag is None:
        p["land_at_current_position_flag"] = "position" not in p
    elif flag is False and "position" not in p:
        raise ParamError("required when land_at_current_position_flag is false", "position")
    elif flag is True and "position" in p:
        raise ParamError("given, but land_at_current_position_flag is true", "position")


def _hover_check(p: dict[str, Any]) -> None:
    over = p.get("over")
    if over is not None and not (isinstance(over, str) and over.startswith("?") and over[1:].isidentifier()):
        raise ParamError("expected a condition's variable such as ?x", "over")
    if over is not None and "position" in p:
        raise ParamError("give position or over, not both", "over")


_WAYPOINT_ONLY = ("waypoints", "loiter_mode", "segment_flag", "any_order_flag")


def _scan_ground_check(p: dict[str, Any]) -> None:
    if p.get("waypoints_scan_flag"):
        if "waypoints" not in p:
            raise ParamError("required when waypoints_scan_flag is true", "waypoints")
        if "area" in p:
            raise ParamError("given, but waypoints_scan_flag is true (the waypoints are scanned)", "area")
        p.setdefault("loiter_mode", "pass")
        p.setdefault("segment_flag", False)
        p.setdefault("any_order_flag", False)
    else:
        if "area" not in p:
            raise ParamError("missing required parameter of scan-ground (or set waypoints_scan_flag)", "area")
        for name in _WAYPOINT_ONLY:
            if name in p:
                raise ParamError("only with waypoints_scan_flag: true (Fig. 14a, *)", name)
    _follow_ground_check(p)


_FOLLOW_GROUND = (
    ParamSpec("follow_ground_flag", "bool", "Ground relative flight.", default=False),
    ParamSpec("follow_ground_altitude", "float", "Distance to the ground if follow_ground_flag is true.",
              unit="m", minimum=0.0),
)

TAKE_OFF = TaskType(
    "take-off", "Fig. 11",
    "Make the platform airborne; no input parameters (the altitude is the platform's: 2 m indoor, "
    "5 m outdoor).")

FLY_TO = TaskType(
    "fly-to", "Fig. 12a", "Bring the platform to a specified location.",
    (
        ParamSpec("position", "geopoint", "Geographical location of the target position.", required=True),
        ParamSpec("commanded_speed", "float", "Wanted speed in m/s.", unit="m/s", minimum=0.0),
        ParamSpec("speed", "qualitative", 'Qualitative specification: "slow", "standard", "fast".',
                  options=("slow", "standard", "fast")),
        *_FOLLOW_GROUND,
        ParamSpec("fly_straight_line_flag", "bool", "Enforce straight line flight to the target position.",
                  default=False),
    ),
    aliases={"commanded-speed": "commanded_speed"},
    check=_fly_to_check,
)

LAND = TaskType(
    "land", "Fig. 13a", "Land at the current or a specified location.",
    (
        ParamSpec("position", "geopoint", "Geographical location of the landing."),
        ParamSpec("land_at_current_position_flag", "bool",
                  "Use position or current location (ours: defaults to true exactly when no position "
                  "is given)."),
    ),
    check=_land_check,
)

WAIT = TaskType(
    "wait", "Sec. VI-D", "A timed period of inactivity (all channels DNU, E_Wait).",
    (ParamSpec("duration", "float", "The amount of time to wait (the name is ours).", required=True, unit="s",
               minimum=0.0),),
)

SCAN_GROUND = TaskType(
    "scan-ground", "Fig. 14a", "Fly a scanning pattern over an area or along waypoints.",
    (
        ParamSpec("area", "area", "Specification of the area to scan."),
        ParamSpec("waypoints_scan_flag", "bool", "If true scan flying the waypoints instead of area scan.",
                  default=False),
        ParamSpec("waypoints", "waypoints", "A list of waypoints ([lat, lon] or [lat, lon, alt])."),
        ParamSpec("loiter_mode", "qualitative", "Behavior at a waypoint (values ours: pass, stop).",
                  options=("pass", "stop")),
        ParamSpec("segment_flag", "bool", "Interpret the waypoints as a sequence of straight line segments."),
        ParamSpec("any_order_flag", "bool", "If true fly segments or waypoints in any order."),
        ParamSpec("speed", "qualitative", '"fast", "standard", "slow", unspecified.',
                  options=("fast", "standard", "slow", "unspecified"), default="unspecified"),
        ParamSpec("altitude", "qualitative", '"high", "standard", "low", unspecified.',
                  options=("high", "standard", "low", "unspecified"), default="unspecified"),
        *_FOLLOW_GROUND,
        ParamSpec("repeat_flag", "bool",
                  "If this is true we are in patrol mode and repeat the scan of the area.", default=False),
        ParamSpec("sensor_type", "qualitative", '"artva", "laser", "camera".',
                  options=("artva", "laser", "camera"), default="camera"),
        ParamSpec("data_uuid", "string", "Used to identify the result of the scan."),
        ParamSpec("generate_scan_specs_flag", "bool", "If true generate scan specs and put in queue.",
                  default=False),
    ),
    aliases={"generate_scan_spec_flag": "generate_scan_specs_flag"},
    check=_scan_ground_check,
)

EXTERNAL_VELOCITY = TaskType(
    "external-velocity", "Sec. VI-F",
    "Fly with velocities (and yaw rate) from an external source; all channels ExtVel, ended by E_User.",
    (ParamSpec("source", "string", "The external velocity feed (ours; the paper lists no parameter).",
               default="joystick"),),
)

HOVER = TaskType(
    "hover", "ours (behaviors layer)", "Stay in place for a duration, or until enough is requested.",
    (
        ParamSpec("duration", "float", "Seconds to stay; absent: until enough.", unit="s", minimum=0.0),
        ParamSpec("position", "geopoint", "Where to hover; absent: where the platform is."),
        ParamSpec("over", "string", "Hover above the object bound to this variable by the enclosing IF or "
                  "WHILE condition (e.g. ?x, with position(?x, ...) in the beliefs; ours)."),
    ),
    check=lambda p: _hover_check(p),
)

REQUEST_OPERATOR_ASSISTANCE = TaskType(
    "request-operator-assistance", "ours (behaviors layer)",
    "Ask the operator for assistance (REQUEST_OPERATOR_ASSISTANCE) and wait for the answer.",
    (ParamSpec("message", "string", "What the operator is asked.", required=True),),
)

#: Every leaf task type by name.
TASK_TYPES: dict[str, TaskType] = {t.name: t for t in (
    TAKE_OFF, FLY_TO, LAND, WAIT, SCAN_GROUND, EXTERNAL_VELOCITY, HOVER, REQUEST_OPERATOR_ASSISTANCE)}


def free_params(params: Mapping[str, Any]) -> dict[str, Any]:
    """The parameters that hold a constraint rather than a value (Sec. III: free parameters)."""
    return {name: value for name, value in params.items() if is_free(value)}
