"""TST parameters: a value or a constraint (seed 000 Sec. III).

"Each task in a TST is parameterized and parameters can either be specified directly or constrained
through a general constraint language, allowing a certain degree of freedom in setting parameters in
order to satisfy the overall requirements of a mission. For example, the flight velocity and altitude for
a particular task can be constrained to be within specific intervals." A parameter is *free* when it holds
a constraint rather than a value; the delegation's constraint solver later fixes it.

Constraints:

* :class:`Interval` ``[lo, hi]`` for a number (written ``{interval: [1.0, 3.0]}``);
* :class:`Qualitative` options for a qualitative parameter (``"slow | standard"`` or ``{one_of: [slow,
  standard]}``);
* :class:`LinearRelation` between parameters and platform quantities (``"duration <= endurance_left"``,
  ``"altitude >= 2 * min_altitude"``; a string with a comparison operator, or ``{relation: "..."}``).

Geopoints are ``[lat, lon, alt]`` (degrees, degrees, metres above home: MAVLink's GLOBAL_RELATIVE_ALT);
areas are polygons ``[[lat, lon], ...]``. They convert to the local north-east-down frame of home with
the project's flat-earth geodesy (:mod:`taskflight_common.geo`, ArduPilot's ``Location`` convention);
:func:`plan_point` gives the (north, east, altitude) form a :class:`~companion.tst.plan.NodePlan` holds.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from companion.tst.linear import OPERATORS, ConstraintError, parse_linear
from taskflight_common.geo import geodetic_to_ned, ned_to_geodetic

#: Comparison operators of a linear relation.
RELATION_OPERATORS = OPERATORS


class ParamError(ValueError):
    """A bad parameter value; ``field`` is the parameter name, ``index`` the list item at fault if any."""

    def __init__(self, reason: str, field: str | None = None, index: int | None = None) -> None:
        self.reason = reason
        self.field = field
        self.index = index
        where = f"{field}: " if field else ""
        super().__init__(f"{where}{reason}")


def _finite(value: Any, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ParamError(f"{what}: expected a finite number, got {value!r}")
    return float(value)


@dataclass(frozen=True)
class Interval:
    """A number constrained to ``lo <= x <= hi`` (Sec. III: "constrained to be within specific intervals")."""

    lo: float
    hi: float

    def __post_init__(self) -> None:
        lo = _finite(self.lo, "interval lower bound")
        hi = _finite(self.hi, "interval upper bound")
        if lo > hi:
            raise ParamError(f"empty interval [{lo:g}, {hi:g}] (lower bound above upper bound)")
        object.__setattr__(self, "lo", lo)
        object.__setattr__(self, "hi", hi)

    def contains(self, x: float) -> bool:
        return self.lo <= x <= self.hi

    def __str__(self) -> str:
        return f"[{self.lo:g}, {self.hi:g}]"


@dataclass(frozen=True)
class Qualitative:
    """A qualitative parameter constrained to one of ``options`` (``slow | standard | fast``)."""

    options: tuple[str, ...]

    def __post_init__(self) -> None:
        opts = tuple(self.options)
        if not opts:
            raise ParamError("no qualitative values given")
        for o in opts:
            if not isinstance(o, str) or not o.strip():
                raise ParamError(f"qualitative value {o!r} is not a word")
        stripped = tuple(o.strip() for o in opts)
        if len(set(stripped)) != len(stripped):
            raise ParamError(f"qualitative value repeated in {' | '.join(stripped)}")
        object.__setattr__(self, "options", stripped)

    @classmethod
    def parse(cls, value: str | Sequence[str]) -> Qualitative:
        """From ``"slow | standard"`` or ``["slow", "standard"]``."""
        if isinstance(value, str):
            return cls(tuple(part.strip() for part in value.split("|")))
        return cls(tuple(value))

    def contains(self, x: str) -> bool:
        return x in self.options

    def __str__(self) -> str:
        return " | ".join(self.options)


@dataclass(frozen=True)
class LinearRelation:
    """``sum(coefficient * name) op constant``: a linear relation between parameters and platform quantities.

    Parsed from text such as ``"duration <= endurance_left"`` or ``"altitude >= 0.5 * (ceiling + floor)"``
    with the solver's one grammar (:mod:`companion.tst.linear`: sums, products by numbers, division by
    numbers, parentheses); both sides may hold terms, which are moved to the left
    (``duration - endurance_left <= 0``). A name is
    a parameter of the node (``altitude``), of another node (``n3.altitude``) or a platform quantity
    (``endurance_left``); the constraint solver resolves them. The original ``text`` is kept.
    """

    text: str
    coefficients: tuple[tuple[str, float], ...]
    op: str
    constant: float

    @classmethod
    def parse(cls, text: str) -> LinearRelation:
        """Read ``text`` with the constraint solver's grammar (:func:`companion.tst.linear.parse_linear`)."""
        if not isinstance(text, str):
            raise ParamError(f"a relation is text, got {text!r}")
        try:
            lin = parse_linear(text, "relation")
        except ConstraintError as exc:
            raise ParamError(str(exc)) from None
        return cls(text.strip(), tuple(sorted(lin.terms.items())), lin.op, lin.rhs)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(n for n, _ in self.coefficients)

    def evaluate(self, values: Mapping[str, float], tol: float = 1e-9) -> bool:
        """Whether the relation holds for ``values`` (every name must be given)."""
        missing = [n for n in self.names if n not in values]
        if missing:
            raise ParamError(f"relation {self.text!r}: no value for {', '.join(missing)}")
        lhs = sum(c * float(values[n]) for n, c in self.coefficients)
        if self.op == "<=":
            return lhs <= self.constant + tol
        if self.op == ">=":
            return lhs >= self.constant - tol
        return abs(lhs - self.constant) <= tol

    def __str__(self) -> str:
        return self.text


#: A constraint on a free parameter.
Constraint = Interval | Qualitative | LinearRelation


def is_free(value: Any) -> bool:
    """A parameter is free when it holds a constraint rather than a value (Sec. III)."""
    return isinstance(value, Interval | Qualitative | LinearRelation)


def parse_constraint(value: Any) -> Constraint | None:
    """The constraint written as ``value`` in a mission, or None when ``value`` is a plain value.

    Forms: ``{interval: [lo, hi]}``, ``{one_of: [a, b]}``, ``{relation: "x <= y"}``; the shorthands
    ``"a | b"`` (qualitative) and ``"x <= y"`` (a string holding <, > or =) also count. A constraint
    object passes through.
    """
    if is_free(value):
        return value
    if isinstance(value, Mapping):
        if len(value) != 1:
            raise ParamError("a constraint is one of {interval: [lo, hi]}, {one_of: [...]}, "
                             "{relation: '...'}")
        (key, arg), = value.items()
        if key == "interval":
            if not isinstance(arg, Sequence) or isinstance(arg, str) or len(arg) != 2:
                raise ParamError("interval: expected [lo, hi]")
            return Interval(arg[0], arg[1])
        if key == "one_of":
            if isinstance(arg, str) or not isinstance(arg, Sequence):
                raise ParamError("one_of: expected a list of qualitative values")
            return Qualitative.parse(arg)
        if key == "relation":
            return LinearRelation.parse(arg)
        raise ParamError(f"unknown constraint '{key}' (known: interval, one_of, relation)")
    if isinstance(value, str):
        if any(op in value for op in "<>="):  # a relation, or a mistyped one (LinearRelation.parse says)
            return LinearRelation.parse(value)
        if "|" in value:
            return Qualitative.parse(value)
    return None


def constraint_to_json(c: Constraint) -> dict[str, Any]:
    """The mission form of a constraint (``parse_constraint`` reads it back)."""
    if isinstance(c, Interval):
        return {"interval": [c.lo, c.hi]}
    if isinstance(c, Qualitative):
        return {"one_of": list(c.options)}
    return {"relation": c.text}


def check_geopoint(value: Any, n: int = 3) -> tuple[float, ...]:
    """``[lat, lon, alt]`` (``n`` = 3) or ``[lat, lon]`` (``n`` = 2) as floats, ranges checked."""
    if isinstance(value, str | bytes | Mapping) or not isinstance(value, Sequence) or len(value) != n:
        form = "[lat, lon, alt]" if n == 3 else "[lat, lon]"
        raise ParamError(f"expected a geopoint {form}, got {value!r}")
    lat = _finite(value[0], "latitude")
    lon = _finite(value[1], "longitude")
    if not -90.0 <= lat <= 90.0:
        raise ParamError(f"latitude {lat:g} out of range [-90, 90]")
    if not -180.0 <= lon <= 180.0:
        raise ParamError(f"longitude {lon:g} out of range [-180, 180]")
    if n == 2:
        return (lat, lon)
    return (lat, lon, _finite(value[2], "altitude"))


def check_geopoints(value: Any, sizes: tuple[int, ...] = (2, 3), minimum: int = 1
                    ) -> tuple[tuple[float, ...], ...]:
    """A list of geopoints, all of one of ``sizes`` elements, at least ``minimum`` of them."""
    if isinstance(value, str | bytes | Mapping) or not isinstance(value, Sequence):
        raise ParamError(f"expected a list of geopoints, got {value!r}")
    if len(value) < minimum:
        raise ParamError(f"expected at least {minimum} geopoints, got {len(value)}")
    points: list[tuple[float, ...]] = []
    for i, p in enumerate(value):
        n = len(p) if isinstance(p, Sequence) and not isinstance(p, str) and len(p) in sizes else sizes[-1]
        if points and n != len(points[0]):
            raise ParamError(f"geopoint {i} has {n} elements, the first has {len(points[0])}", index=i)
        try:
            points.append(check_geopoint(p, n))
        except ParamError as exc:
            raise ParamError(f"geopoint {i}: {exc.reason}", index=i) from None
    return tuple(points)


def check_area(value: Any) -> tuple[tuple[float, float], ...]:
    """An area polygon ``[[lat, lon], ...]``: at least 3 vertices, not self-intersecting (shapely)."""
    points = check_geopoints(value, sizes=(2,), minimum=3)
    from shapely.geometry import Polygon  # local import: shapely is only needed for areas

    poly = Polygon([(lon, lat) for lat, lon in points])
    if poly.is_valid and poly.area > 0.0:
        return tuple((p[0], p[1]) for p in points)
    if poly.convex_hull.area <= 0.0:
        raise ParamError("area polygon has no area (its vertices are on a line)")
    raise ParamError("area polygon crosses itself")


def geopoint_to_ned(point: Sequence[float], home: Sequence[float]) -> tuple[float, float, float]:
    """(north, east, down) metres of ``[lat, lon, alt-above-home]`` from ``home`` (lat, lon[, ...]).

    ``[lat, lon]`` gives down = 0. The project's local frame: ArduPilot's flat-earth conversion
    (:func:`taskflight_common.geo.geodetic_to_ned`).
    """
    alt = float(point[2]) if len(point) > 2 else 0.0
    return geodetic_to_ned((float(home[0]), float(home[1]), 0.0), float(point[0]), float(point[1]), alt)


def plan_point(point: Sequence[float], home: Sequence[float]) -> tuple[float, float, float]:
    """A geopoint as a plan point: (north, east, altitude above home), see
    :class:`~companion.tst.plan.NodePlan`."""
    n, e, d = geopoint_to_ned(point, home)
    return (n, e, -d)


def plan_point_to_geopoint(point: Sequence[float], home: Sequence[float]) -> tuple[float, float, float]:
    """``[lat, lon, alt above home]`` of a plan point (north, east, altitude above home)."""
    lat, lon, alt = ned_to_geodetic((float(home[0]), float(home[1]), 0.0), point[0], point[1], -point[2])
    return (round(lat, 9), round(lon, 9), round(alt, 4))


def area_to_local(area: Sequence[Sequence[float]], home: Sequence[float]) -> list[tuple[float, float]]:
    """The (north, east) vertices of an area polygon ``[[lat, lon], ...]`` relative to ``home``."""
    out = []
    for p in area:
        n, e, _ = geopoint_to_ned((p[0], p[1]), home)
        out.append((n, e))
    return out
