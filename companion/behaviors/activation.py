"""Behavior activation requests and the coordinator's format check (seed 001 Sec. 5.1.1, Sec. 6.2.2).

An activation is ``a = <requester, behavior, {param: value}>`` (:class:`ActivationRequest`); its text
form, as an operator writes it, is the behavior's name followed by ``parameter: value`` pairs::

    TAKE_OFF
    ROTATE angle: 45°
    GO_TO_POINT coordinate: (1.0, 2.5, 7.0)
    FOLLOW_PATH path: ((0, 0, 5), (10, 0, 5), (10, 10, 5))
    REQUEST_OPERATOR_ASSISTANCE message: "is the frame in view?"

Values: numbers (a trailing ``°`` is allowed and ignored), tuples ``( ... )`` (nested for
sequences), symbols (``fast``, ``yes``) and double-quoted text. Coordinates are local metres (north,
east, up) from home; angles degrees. :func:`parse_activation` and :func:`format_activation` convert
both ways; :func:`check_format` is the coordinator's "checking behavior activation format" service:
name, arguments, values, dimensions and allowed ranges against the catalog's descriptor and, given
the queue's :class:`~companion.flight.limits.Limits`, against the flight envelope (a ``speed`` of 20
under a 5 m/s limit is refused, never clamped silently: :func:`~.timeouts.envelope_refusal`), with an
:class:`ActivationError` that says which and why.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from .catalog import BehaviorCatalog, ParameterDescriptor

if TYPE_CHECKING:
    from companion.flight.limits import Limits


class ActivationError(ValueError):
    """A malformed activation: ``field`` names the part (``behavior``, ``coordinate``, ``text``)."""

    def __init__(self, field: str, reason: str) -> None:
        self.field = field
        self.reason = reason
        super().__init__(f"{field}: {reason}")


@dataclass(frozen=True)
class ActivationRequest:
    """``<requester, behavior, {param: value}>`` (Sec. 5.1.1)."""

    requester: str
    behavior: str
    params: Mapping[str, Any] = field(default_factory=dict)

    @property
    def text(self) -> str:
        return format_activation(self.behavior, self.params)


# --- the text form -----------------------------------------------------------------------------------
_TOKEN = re.compile(r"""
    (?P<ws>\s+)
  | (?P<number>[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)(?P<deg>°|deg\b)?
  | (?P<string>"(?:[^"\\]|\\.)*")
  | (?P<name>[A-Za-z_][A-Za-z0-9_]*)
  | (?P<punct>[(),:\[\]])
""", re.VERBOSE)


def _tokens(text: str) -> list[tuple[str, Any, int]]:
    out: list[tuple[str, Any, int]] = []
    pos = 0
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if m is None:
            raise ActivationError("text", f"column {pos + 1}: unexpected character {text[pos]!r}")
        kind = m.lastgroup if m.lastgroup != "deg" else "number"
        if kind == "number":
            raw = m.group("number")
            value: Any = float(raw) if any(c in raw for c in ".eE") else int(raw)
            out.append(("number", value, pos + 1))
        elif kind == "string":
            out.append(("string", bytes(m.group("string")[1:-1], "utf-8").decode("unicode_escape"), pos + 1))
        elif kind == "name":
            out.append(("name", m.group("name"), pos + 1))
        elif kind == "punct":
            out.append((m.group("punct"), m.group("punct"), pos + 1))
        pos = m.end()
    return out


class _Parser:
    def __init__(self, text: str) -> None:
        self.toks = _tokens(text)
        self.i = 0

    def peek(self) -> tuple[str, Any, int] | None:
        return self.toks[self.i] if self.i < len(self.toks) else None

    def take(self, kind: str | None = None, what: str = "") -> tuple[str, Any, int]:
        tok = self.peek()
        if tok is None:
            raise ActivationError("text", f"unexpected end: expected {what or kind}")
        if kind is not None and tok[0] != kind:
            raise ActivationError("text", f"column {tok[2]}: expected {what or kind}, got {tok[1]!r}")
        self.i += 1
        return tok

    def value(self) -> Any:
        tok = self.take(None, "a value")
        kind, val, col = tok
        if kind in ("number", "string", "name"):
            return val
        if kind in ("(", "["):
            close = ")" if kind == "(" else "]"
            items: list[Any] = []
            while True:
                nxt = self.peek()
                if nxt is not None and nxt[0] == close:
                    self.i += 1
                    return tuple(items)
                items.append(self.value())
                nxt = self.take(None, f"',' or '{close}'")
                if nxt[0] == close:
                    return tuple(items)
                if nxt[0] != ",":
                    raise ActivationError("text",
                                          f"column {nxt[2]}: expected ',' or '{close}', got {nxt[1]!r}")
        raise ActivationError("text", f"column {col}: expected a value, got {val!r}")


def parse_activation(text: str, requester: str = "operator") -> ActivationRequest:
    """The text form to a request (syntax only; :func:`check_format` checks it against the catalog)."""
    if not isinstance(text, str) or not text.strip():
        raise ActivationError("text", "empty activation (expected e.g. 'GO_TO_POINT coordinate: (1, 2, 5)')")
    p = _Parser(text)
    name = p.take("name", "a behavior name")[1]
    params: dict[str, Any] = {}
    while p.peek() is not None:
        key_tok = p.take("name", "a parameter name")
        p.take(":", f"':' after {key_tok[1]}")
        if key_tok[1] in params:
            raise ActivationError(key_tok[1], "given twice")
        params[key_tok[1]] = p.value()
        nxt = p.peek()
        if nxt is not None and nxt[0] == ",":  # tolerate "a: 1, b: 2"
            p.i += 1
    return ActivationRequest(requester, name, params)


def _format_value(value: Any) -> str:
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, str):
        return value if value.isidentifier() else '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, tuple | list):
        return "(" + ", ".join(_format_value(v) for v in value) + ")"
    return str(value)


def format_activation(behavior: str, params: Mapping[str, Any] | None = None) -> str:
    """The text form of an activation (inverse of :func:`parse_activation`)."""
    parts = [behavior] + [f"{k}: {_format_value(v)}" for k, v in (params or {}).items()]
    return " ".join(parts)


# --- the format check --------------------------------------------------------------------------------
def _scalar(p: ParameterDescriptor, value: Any, where: str) -> Any:
    if p.type in ("number", "integer"):
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
            raise ActivationError(where, f"expected a number, got {value!r}")
        if p.type == "integer":
            if float(value) != int(value):
                raise ActivationError(where, f"expected an integer, got {value!r}")
            value = int(value)
        else:
            value = float(value)
        r = p.range
        if r is not None and not r[0] <= value <= r[1]:
            raise ActivationError(where, f"{value:g} is outside the allowed range [{r[0]:g}, {r[1]:g}]")
        return value
    if p.type == "boolean":
        if isinstance(value, bool):
            return value
        if value in ("yes", "true"):
            return True
        if value in ("no", "false"):
            return False
        raise ActivationError(where, f"expected yes or no, got {value!r}")
    if p.type == "symbol":
        if not isinstance(value, str) or not value.isidentifier():
            raise ActivationError(where, f"expected a symbol, got {value!r}")
        if p.allowed_values is not None and value not in p.allowed_values:
            raise ActivationError(where, f"{value!r} is not allowed (one of {', '.join(p.allowed_values)})")
        return value
    if not isinstance(value, str):
        raise ActivationError(where, f"expected text, got {value!r}")
    return value


def _one(p: ParameterDescriptor, value: Any, where: str) -> Any:
    if p.dimensions == 1:
        if isinstance(value, tuple | list):
            raise ActivationError(where, f"expected one value, got {len(value)}")
        return _scalar(p, value, where)
    if not isinstance(value, tuple | list):
        raise ActivationError(where, f"expected {p.dimensions} values like (1, 2, 3), got {value!r}")
    if len(value) != p.dimensions:
        raise ActivationError(where, f"expected {p.dimensions} values, got {len(value)}")
    return tuple(_scalar(p, v, where) for v in value)


def check_value(p: ParameterDescriptor, value: Any) -> Any:
    """A value checked against its descriptor (type, dimensions, allowed values); normalised."""
    if p.sequence:
        if not isinstance(value, tuple | list) or not value:
            raise ActivationError(p.name, "expected a non-empty list of values like ((1, 2, 3), (4, 5, 6))")
        return tuple(_one(p, v, f"{p.name}[{i}]") for i, v in enumerate(value))
    return _one(p, value, p.name)


def check_format(catalog: BehaviorCatalog, request: ActivationRequest, limits: Limits | None = None
                 ) -> dict[str, Any]:
    """Sec. 6.2.2 "checking behavior activation format": the request's parameters, checked and with
    defaults filled in; :class:`ActivationError` naming the part and the reason otherwise. With
    ``limits`` (the queue's), a parameter the flight envelope cannot honour is refused too."""
    if request.behavior not in catalog:
        raise ActivationError("behavior", f"unknown behavior {request.behavior!r} "
                                          f"(known: {', '.join(sorted(catalog.names()))})")
    if request.requester not in catalog.requester_priority:
        raise ActivationError("requester", f"unknown requester {request.requester!r} "
                                           f"(known: {', '.join(catalog.requester_priority)})")
    desc = catalog.get(request.behavior)
    out: dict[str, Any] = {}
    for name in request.params:
        if desc.parameter(name) is None:
            known = ", ".join(p.name for p in desc.parameters) or "none"
            raise ActivationError(name, f"{request.behavior} has no parameter {name!r} (parameters: {known})")
    for p in desc.parameters:
        if p.name in request.params:
            out[p.name] = check_value(p, request.params[p.name])
        elif p.required:
            raise ActivationError(p.name, f"missing: {request.behavior} needs {p.describe()}")
        elif p.default is not None:
            out[p.name] = p.default
    if limits is not None:
        from .timeouts import envelope_refusal

        refused = envelope_refusal(out, limits)
        if refused is not None:
            raise ActivationError(*refused)
    return out


def request_from(value: Any, requester: str | None = None) -> ActivationRequest:
    """A request from its text form or a structured ``{behavior, params, requester}`` mapping."""
    if isinstance(value, ActivationRequest):
        return value
    if isinstance(value, str):
        return parse_activation(value, requester or "operator")
    if isinstance(value, Mapping):
        behavior = value.get("behavior")
        if not isinstance(behavior, str) or not behavior:
            raise ActivationError("behavior", "expected a behavior name")
        params = value.get("params") or {}
        if not isinstance(params, Mapping):
            raise ActivationError("params", "expected a mapping of parameter: value")
        return ActivationRequest(str(value.get("requester") or requester or "operator"), behavior,
                                 {str(k): _tupled(v) for k, v in params.items()})
    raise ActivationError("request", f"expected text or a mapping, got {type(value).__name__}")


def _tupled(value: Any) -> Any:
    """JSON lists to tuples (the text form's tuples)."""
    if isinstance(value, list | tuple):
        return tuple(_tupled(v) for v in value)
    return value
