"""The behavior catalog (seed 001 Sec. 6.2.2, Fig. 5): behavior descriptors and compatibility conditions.

The catalog is a YAML file written by a developer (the bundled one is
``mission_specs/behavior_catalog.yaml``)::

    requester_priority: [emergency, operator, mission, default]   # highest first (optional)
    behavior_descriptors:
    - behavior: GO_TO_POINT
      category: goal_based          # or recurrent
      timeout: {factor: 1.5, margin_s: 20}   # from the plan: factor x planned s + margin (timeouts.py)
                                    # or a number: fixed s of autopilot time; 0 or absent: no time-out
      goal: {tolerance_m: 1.0, settle_s: 10}  # the measured state that counts as the goal reached
      default: no                   # yes: active unless an incompatible behavior is
      processes: [motion_controller, trajectory_planner]
      performance: {no_progress_s: 8, progress_m: 0.5}   # optional, read by the execution controller
      parameters:
      - parameter: coordinate
        type: number                # number | integer | symbol | text | boolean
        allowed_values: [-1000, 1000]   # a range for numbers, a list of symbols for symbol
        dimensions: 3               # 1 (default): a scalar; n: an n-tuple
        sequence: no                # yes: a list of such values (a path)
        unit: m
        required: yes               # default: yes unless a default is given
        default: ...
    compatibility_conditions:
    - mutually_exclusive: [TAKE_OFF, LAND, KEEP_HOVERING, GO_TO_POINT, ROTATE]
    - active: [SELF_LOCALIZE]
      before: [GO_TO_POINT, ROTATE, KEEP_HOVERING]

Validation on load (every error names the file, line and field,
:class:`~taskflight_common.yamlio.ConfigError`):
unknown keys, a missing or unknown ``type``, a bad range or default, a behavior described twice, a
condition naming an unknown behavior, and a loop in the precedence relation (Definition 2: "The
precedence conditions set must not present loops").
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mission_specs import bundled
from taskflight_common.yamlio import ConfigError, Fields, load_yaml, load_yaml_text

CATEGORIES = ("goal_based", "recurrent")
#: the keys of a descriptor's ``goal`` (tolerances on the measured state) and planned ``timeout``
GOAL_KEYS = ("tolerance_m", "tolerance_deg", "settle_s")
TIMEOUT_KEYS = ("factor", "margin_s")
PARAMETER_TYPES = ("number", "integer", "symbol", "text", "boolean")
#: The requesters' priority, highest first (Sec. 6.1.2, Definition 3; "operator" is ours).
DEFAULT_REQUESTER_PRIORITY = ("emergency", "operator", "mission", "default")
BUNDLED_CATALOG = bundled("behavior_catalog.yaml")


@dataclass(frozen=True)
class ParameterDescriptor:
    """One parameter of a behavior (Fig. 5: ``parameter``, ``allowed_values``, ``dimensions``)."""

    name: str
    type: str
    allowed_values: tuple[Any, ...] | None = None
    dimensions: int = 1
    sequence: bool = False
    unit: str = ""
    required: bool = True
    default: Any = None

    @property
    def range(self) -> tuple[float, float] | None:
        if self.type in ("number", "integer") and self.allowed_values is not None:
            return float(self.allowed_values[0]), float(self.allowed_values[1])
        return None

    def describe(self) -> str:
        shape = f"{self.dimensions} numbers" if self.dimensions > 1 else self.type
        if self.sequence:
            shape = f"a list of ({shape})"
        allowed = ""
        if self.range is not None:
            allowed = f" in [{self.range[0]:g}, {self.range[1]:g}]"
        elif self.allowed_values is not None:
            allowed = f" one of {', '.join(map(str, self.allowed_values))}"
        unit = f" {self.unit}" if self.unit else ""
        return f"{self.name}: {shape}{allowed}{unit}"


@dataclass(frozen=True)
class BehaviorDescriptor:
    """One behavior descriptor (Fig. 5)."""

    behavior: str
    category: str
    timeout_s: float | None
    default: bool
    processes: tuple[str, ...]
    parameters: tuple[ParameterDescriptor, ...]
    performance: Mapping[str, float] = field(default_factory=dict)
    description: str = ""
    #: the planned time-out (``timeout: {factor, margin_s}``), empty when ``timeout_s`` is fixed or none
    timeout_plan: Mapping[str, float] = field(default_factory=dict)
    #: the goal's tolerances on the measured state (``goal: {tolerance_m, tolerance_deg, settle_s}``)
    goal: Mapping[str, float] = field(default_factory=dict)

    def parameter(self, name: str) -> ParameterDescriptor | None:
        for p in self.parameters:
            if p.name == name:
                return p
        return None


class BehaviorCatalog:
    """Descriptors, mutually exclusive sets and precedence conditions; immutable once built."""

    def __init__(self, descriptors: Iterable[BehaviorDescriptor],
                 mutually_exclusive: Iterable[Iterable[str]] = (),
                 precedence: Iterable[tuple[Iterable[str], Iterable[str]]] = (),
                 requester_priority: Sequence[str] = DEFAULT_REQUESTER_PRIORITY,
                 source: str = "<catalog>") -> None:
        self.source = source
        self._by_name: dict[str, BehaviorDescriptor] = {}
        for d in descriptors:
            if d.behavior in self._by_name:
                raise ValueError(f"behavior {d.behavior} described twice")
            self._by_name[d.behavior] = d
        self.mutually_exclusive = tuple(frozenset(s) for s in mutually_exclusive)
        self.precedence = tuple((frozenset(a), frozenset(b)) for a, b in precedence)
        self.requester_priority = tuple(requester_priority)
        for group in self.mutually_exclusive:
            self._check_known(group)
        for active, before in self.precedence:
            self._check_known(active | before)
        self._incompatible: dict[str, frozenset[str]] = {
            name: frozenset().union(*(g - {name} for g in self.mutually_exclusive if name in g))
            for name in self._by_name}
        self._required: dict[str, frozenset[str]] = {
            name: frozenset().union(*(a for a, b in self.precedence if name in b)) for name in self._by_name}
        cycle = find_cycle({n: self._required[n] for n in self._by_name})
        if cycle:
            raise ValueError(f"precedence loop: {' before '.join(cycle)}")

    def _check_known(self, names: Iterable[str]) -> None:
        for n in names:
            if n not in self._by_name:
                raise ValueError(f"unknown behavior {n}")

    # --- queries -------------------------------------------------------------------------------------
    def __contains__(self, name: object) -> bool:
        return name in self._by_name

    def __iter__(self) -> Iterator[BehaviorDescriptor]:
        return iter(self._by_name.values())

    def names(self) -> list[str]:
        return list(self._by_name)

    def get(self, name: str) -> BehaviorDescriptor:
        try:
            return self._by_name[name]
        except KeyError:
            raise KeyError(f"unknown behavior {name!r} (known: {', '.join(sorted(self._by_name))})") from None

    def incompatible(self, a: str, b: str) -> bool:
        """Definition 1: a and b are in one mutually exclusive set (a behavior with itself: always)."""
        return a == b or b in self._incompatible.get(a, frozenset())

    def required_before(self, name: str) -> frozenset[str]:
        """Definition 2: the behaviors that must be active before ``name`` is activated."""
        return self._required.get(name, frozenset())

    def defaults(self) -> list[BehaviorDescriptor]:
        """The default behaviors, in an order where a required behavior comes first."""
        out: list[BehaviorDescriptor] = []
        pending = [d for d in self._by_name.values() if d.default]
        while pending:
            for d in pending:
                if not (self.required_before(d.behavior) & {p.behavior for p in pending if p is not d}):
                    out.append(d)
                    pending.remove(d)
                    break
        return out

    def priority(self, requester: str) -> int:
        """Higher is stronger; an unknown requester is refused by the coordinator."""
        order = self.requester_priority
        return len(order) - order.index(requester)

    def to_dict(self) -> dict[str, Any]:
        return {
            "requester_priority": list(self.requester_priority),
            "behavior_descriptors": [
                {"behavior": d.behavior, "category": d.category,
                 "timeout": dict(d.timeout_plan) if d.timeout_plan else d.timeout_s,
                 "goal": dict(d.goal), "default": d.default,
                 "processes": list(d.processes), "description": d.description,
                 "parameters": [{"parameter": p.name, "type": p.type, "dimensions": p.dimensions,
                                 "sequence": p.sequence, "unit": p.unit, "required": p.required,
                                 "default": p.default,
                                 "allowed_values": list(p.allowed_values) if p.allowed_values is not None
                                 else None} for p in d.parameters]}
                for d in self],
            "compatibility_conditions":
                [{"mutually_exclusive": sorted(g)} for g in self.mutually_exclusive]
                + [{"active": sorted(a), "before": sorted(b)} for a, b in self.precedence],
        }


def find_cycle(requires: Mapping[str, Iterable[str]]) -> list[str] | None:
    """A loop in the "must be active before" graph, as a list of names (first = last), or None."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(n: str) -> list[str] | None:
        state[n] = 1
        stack.append(n)
        for m in sorted(requires.get(n, ())):
            if state.get(m) == 1:
                return [*stack[stack.index(m):], m]
            if state.get(m) is None:
                found = visit(m)
                if found:
                    return found
        stack.pop()
        state[n] = 2
        return None

    for n in sorted(requires):
        if state.get(n) is None:
            found = visit(n)
            if found:
                return list(reversed(found))
    return None


# --- loading ---------------------------------------------------------------------------------------------
def _parameter(f: Fields) -> ParameterDescriptor:
    f.unknown(["parameter", "type", "allowed_values", "dimensions", "sequence", "unit", "required", "default",
               "description"])
    name = f.string("parameter")
    if not f.has("type"):
        raise f.error(None, f"parameter '{name}' has no type (one of {', '.join(PARAMETER_TYPES)})")
    kind = f.string("type", choices=PARAMETER_TYPES)
    dims = f.integer("dimensions", 1, lo=1, hi=16)
    if dims > 1 and kind not in ("number", "integer"):
        raise f.error("dimensions", f"only numbers have dimensions (type is {kind})")
    allowed = f.raw("allowed_values", None)
    if allowed is not None:
        if not isinstance(allowed, list) or not allowed:
            raise f.error("allowed_values", "expected a non-empty list")
        if kind in ("number", "integer"):
            if len(allowed) != 2 or not all(isinstance(v, int | float) and not isinstance(v, bool)
                                            and math.isfinite(v) for v in allowed) or allowed[0] > allowed[1]:
                raise f.error("allowed_values", "expected a range [min, max] of numbers with min <= max")
        elif kind == "symbol":
            if not all(isinstance(v, str) and v.isidentifier() for v in allowed):
                raise f.error("allowed_values", "expected a list of symbols (identifiers)")
        else:
            raise f.error("allowed_values", f"a {kind} parameter has no allowed_values")
        allowed = tuple(allowed)
    sequence = f.boolean("sequence", False)
    default = f.raw("default", None)
    required = f.boolean("required", default is None)
    desc = ParameterDescriptor(name, kind, allowed, dims, sequence, f.string("unit", ""), required, default)
    if default is not None:
        from .activation import ActivationError, check_value  # one check for defaults and requests

        try:
            object.__setattr__(desc, "default", check_value(desc, default))
        except ActivationError as exc:
            raise f.error("default", exc.reason) from None
    return desc


def _descriptor(f: Fields) -> BehaviorDescriptor:
    f.unknown(["behavior", "category", "timeout", "default", "processes", "parameters", "performance",
               "description", "goal"])
    name = f.string("behavior")
    if not name.isidentifier() or name.upper() != name:
        raise f.error("behavior", f"'{name}' is not an upper-case identifier (e.g. GO_TO_POINT)")
    category = f.string("category", choices=CATEGORIES)
    timeout, plan = _timeout(f)
    if category == "recurrent" and (timeout or plan):
        raise f.error("timeout", "a recurrent behavior has no goal, hence no time-out")
    default = f.boolean("default", False)
    processes = f.raw("processes", [])
    if not isinstance(processes, list) or not all(isinstance(p, str) and p.isidentifier() for p in processes):
        raise f.error("processes", "expected a list of process names")
    params_raw = f.raw("parameters", [])
    if not isinstance(params_raw, list):
        raise f.error("parameters", "expected a list of parameter descriptors")
    params: list[ParameterDescriptor] = []
    for i, item in enumerate(params_raw):
        line = params_raw.line_of(i) if hasattr(params_raw, "line_of") else f.line("parameters")
        p = _parameter(Fields(item, f"{f.path('parameters')}[{i}]", f.file, line))
        if any(q.name == p.name for q in params):
            raise ConfigError(f.file, line, f"{f.path('parameters')}[{i}].parameter",
                              f"'{p.name}' given twice")
        params.append(p)
    perf: dict[str, float] = {}
    if f.has("performance"):
        pf = f.sub("performance")
        for key in pf.data:
            perf[str(key)] = pf.number(str(key), lo=0.0)
    goal = _numbers(f, "goal", GOAL_KEYS)
    return BehaviorDescriptor(name, category, timeout or None, default, tuple(processes), tuple(params), perf,
                              f.string("description", ""), plan, goal)


def _numbers(f: Fields, key: str, keys: Sequence[str]) -> dict[str, float]:
    if not f.has(key):
        return {}
    sub = f.sub(key)
    if not isinstance(sub.data, Mapping):
        raise f.error(key, f"expected a mapping of {', '.join(keys)}")
    sub.unknown(list(keys))
    return {str(k): sub.number(str(k), lo=0.0) for k in sub.data}


def _timeout(f: Fields) -> tuple[float, dict[str, float]]:
    """``timeout``: a fixed number of seconds, or ``{factor, margin_s}`` applied to the planned duration."""
    if f.has("timeout") and isinstance(f.raw("timeout"), Mapping):
        plan = _numbers(f, "timeout", TIMEOUT_KEYS)
        if "factor" in plan and plan["factor"] < 1.0:
            raise f.error("timeout", "factor must be at least 1 (the plan itself takes that long)")
        return 0.0, {"factor": plan.get("factor", 1.0), "margin_s": plan.get("margin_s", 0.0)}
    return f.number("timeout", 0.0, lo=0.0), {}


def _names(f: Fields, key: str, known: Mapping[str, Any]) -> list[str]:
    raw = f.raw(key)
    if not isinstance(raw, list) or not raw:
        raise f.error(key, "expected a non-empty list of behaviors")
    for i, n in enumerate(raw):
        if n not in known:
            line = raw.line_of(i) if hasattr(raw, "line_of") else f.line(key)
            raise ConfigError(f.file, line, f"{f.path(key)}[{i}]", f"unknown behavior {n!r}")
    return [str(n) for n in raw]


def catalog_from_data(data: Any, file: str = "<input>") -> BehaviorCatalog:
    """Build and validate a catalog from parsed YAML (see module docstring)."""
    top = Fields(data, "", file)
    top.unknown(["behavior_descriptors", "compatibility_conditions", "requester_priority"])
    raw = top.raw("behavior_descriptors")
    if not isinstance(raw, list) or not raw:
        raise top.error("behavior_descriptors", "expected a non-empty list of behavior descriptors")
    descriptors: dict[str, BehaviorDescriptor] = {}
    for i, item in enumerate(raw):
        line = raw.line_of(i) if hasattr(raw, "line_of") else None
        d = _descriptor(Fields(item, f"behavior_descriptors[{i}]", file, line))
        if d.behavior in descriptors:
            raise ConfigError(file, line, f"behavior_descriptors[{i}].behavior",
                              f"{d.behavior} described twice")
        descriptors[d.behavior] = d
    priority = list(DEFAULT_REQUESTER_PRIORITY)
    if top.has("requester_priority"):
        pr = top.raw("requester_priority")
        names_ok = isinstance(pr, list) and pr and all(isinstance(r, str) and r.isidentifier() for r in pr)
        if not names_ok or len(set(pr)) != len(pr):
            raise top.error("requester_priority",
                            "expected a list of distinct requester names, highest first")
        if "default" not in pr:
            raise top.error("requester_priority", "must name the 'default' requester (default behaviors)")
        priority = [str(r) for r in pr]
    exclusive: list[list[str]] = []
    precedence: list[tuple[list[str], list[str]]] = []
    edge_line: dict[tuple[str, str], int | None] = {}  # (a, b) of "a before b" -> its condition's line
    conds = top.raw("compatibility_conditions", [])
    if not isinstance(conds, list):
        raise top.error("compatibility_conditions", "expected a list of conditions")
    for i, item in enumerate(conds):
        line = conds.line_of(i) if hasattr(conds, "line_of") else None
        f = Fields(item, f"compatibility_conditions[{i}]", file, line)
        if f.has("mutually_exclusive"):
            f.unknown(["mutually_exclusive"])
            exclusive.append(_names(f, "mutually_exclusive", descriptors))
        elif f.has("active") or f.has("before"):
            f.unknown(["active", "before"])
            active, before = _names(f, "active", descriptors), _names(f, "before", descriptors)
            precedence.append((active, before))
            edge_line.update({(a, b): line for a in active for b in before})
        else:
            raise f.error(None, "expected 'mutually_exclusive' or 'active' + 'before'")
    requires: dict[str, set[str]] = {}
    for a, b in edge_line:
        requires.setdefault(b, set()).add(a)
    cycle = find_cycle(requires)
    if cycle:
        lines = sorted({edge_line[(a, b)] or 0 for a, b in itertools.pairwise(cycle)})
        raise ConfigError(file, lines[-1], "compatibility_conditions",
                          f"precedence loop: {' before '.join(cycle)} (conditions on lines "
                          f"{', '.join(map(str, lines))})")
    return BehaviorCatalog(descriptors.values(), exclusive, precedence, priority, source=file)


def catalog_from_yaml(text: str, file: str = "<input>") -> BehaviorCatalog:
    return catalog_from_data(load_yaml_text(text, file), file)


def load_catalog(path: str | Path = BUNDLED_CATALOG) -> BehaviorCatalog:
    """Read and validate a catalog file (the bundled one by default)."""
    return catalog_from_data(load_yaml(path), str(path))
