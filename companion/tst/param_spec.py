"""One input parameter of a leaf task type: its name, kind, meaning and check (seed 000 Fig. 12a-14a).

A :class:`ParamSpec` is a row of the paper's parameter tables. :meth:`ParamSpec.normalize` turns what a
mission file wrote into a checked value, or into a constraint (:mod:`companion.tst.params`) when the
parameter is free. The kinds, and how each is written: ``geopoint`` ``[lat, lon, alt]``, ``area``
``[[lat, lon], ...]``, ``waypoints`` (a list of ``[lat, lon]`` or ``[lat, lon, alt]``), ``float``,
``bool``, ``string`` and ``qualitative`` (one of ``options``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from companion.tst.params import (
    Interval,
    LinearRelation,
    ParamError,
    Qualitative,
    check_area,
    check_geopoint,
    check_geopoints,
    parse_constraint,
)

__all__ = ["KINDS", "ParamSpec"]


def _bool(spec: ParamSpec, value: Any) -> Any:
    if not isinstance(value, bool):
        raise ParamError(f"expected true or false, got {value!r}")
    return value


def _string(spec: ParamSpec, value: Any) -> Any:
    if not isinstance(value, str):
        raise ParamError(f"expected a string, got {value!r}")
    return value


def _qualitative(spec: ParamSpec, value: Any) -> Any:
    if not isinstance(value, str) or value not in spec.options:
        raise ParamError(f"expected one of {', '.join(spec.options)}; got {value!r}")
    return value


def _float(spec: ParamSpec, value: Any) -> Any:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ParamError(f"expected a number{f' ({spec.unit})' if spec.unit else ''}, got {value!r}")
    number = float(value)
    if number != number or number in (float("inf"), float("-inf")):
        raise ParamError("must be finite")
    if spec.minimum is not None and number < spec.minimum:
        raise ParamError(f"must be >= {spec.minimum:g}{spec.unit_text}, got {number:g}")
    return number


#: Parameter kinds: how a value of each is checked.
_CHECKS: dict[str, Callable[[ParamSpec, Any], Any]] = {
    "geopoint": lambda _s, v: check_geopoint(v, 3),
    "area": lambda _s, v: check_area(v),
    "waypoints": lambda _s, v: check_geopoints(v, sizes=(2, 3), minimum=1),
    "float": _float,
    "bool": _bool,
    "string": _string,
    "qualitative": _qualitative,
}
#: Parameter kinds that may hold a constraint (a free parameter, Sec. III).
_CONSTRAINABLE = ("float", "qualitative")
KINDS = tuple(_CHECKS)


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

    def __post_init__(self) -> None:
        if self.kind not in _CHECKS:
            raise ValueError(f"parameter {self.name}: unknown kind {self.kind!r} (known: {', '.join(KINDS)})")

    @property
    def unit_text(self) -> str:
        return f" {self.unit}" if self.unit else ""

    def normalize(self, value: Any) -> Any:
        """The checked value, or the constraint when the parameter is free; raises :class:`ParamError`."""
        try:
            if self.kind in _CONSTRAINABLE:
                constraint = parse_constraint(value)
                if constraint is not None:
                    return self._check_constraint(constraint)
            return _CHECKS[self.kind](self, value)
        except ParamError as exc:
            raise ParamError(exc.reason, self.name, exc.index) from None

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
            raise ParamError(f"interval {c} goes below the minimum {self.minimum:g}{self.unit_text}")
        if isinstance(c, LinearRelation) and self.name not in c.names:
            raise ParamError(f"relation {c.text!r} does not mention {self.name}")
        return c
