"""Module specifications: the YAML (or dict) module library of the autopilot model.

Seed 002 Sec. 3.2 lists what a Paparazzi module file declares: a name and a task group, dependencies
with required or conflicting modules or functionalities and the functionalities it provides
(Fig. 3), initialization functions, periodic functions with their frequency, and event functions.
This module parses that information from the YAML format of ``docs/design.md``::

    main_loop_hz: 500
    modules:
      - name: imu
        task_group: sensors
        depends: "a,b|c,@func"     # ',' = AND, '|' = OR, '@' = a functionality
        provides: "@imu"           # comma separated; the '@' is optional here
        conflicts: "mod4,@func3"   # modules or @functionalities
        init: [imu.init]
        periodic:
          - {function: imu.periodic, freq: 500}
          - {function: imu.slow, freq: 10, offset: 3, cost: 40}
        event: [imu.poll]
    select: [imu]

Every problem is a :class:`taskflight_common.yamlio.ConfigError` naming file, line and field. The same parser
accepts plain Python dicts (file ``<dict>``, no line numbers) so tests can build libraries inline.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Any

from taskflight_common.yamlio import ConfigError, Fields, load_yaml

#: Task groups in their fixed execution order (seed 002 Sec. 4.2, Fig. 4; docs/design.md).
TASK_GROUPS: tuple[str, ...] = (
    "sensors", "estimation", "navigation", "control", "actuators", "core", "telemetry",
)
#: Name of the pseudo group of event functions, polled at the start of every iteration.
EVENTS_GROUP = "events"

DEFAULT_MAIN_LOOP_HZ = 500.0

_NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_.\-]*$")

_TOP_KEYS = ("main_loop_hz", "modules", "select")
_MODULE_KEYS = ("name", "task_group", "doc", "depends", "provides", "conflicts", "init", "periodic", "event")
_PERIODIC_KEYS = ("function", "freq", "offset", "cost")


@dataclass(frozen=True)
class PeriodicSpec:
    """One periodic function: called when ``iteration % prescaler == offset``.

    ``prescaler = main_loop_hz / freq`` (an integer, checked); ``offset`` is ``None`` unless fixed in
    the YAML (then the offset heuristics keep it); ``cost`` is an optional per-call load estimate
    (any consistent unit, e.g. microseconds) used by the optimised offset heuristic (default 1).
    """

    function: str
    freq: float
    prescaler: int
    offset: int | None = None
    cost: float | None = None
    line: int | None = None


@dataclass(frozen=True)
class ModuleSpec:
    """One module of the library (seed 002 Sec. 3.2 and Fig. 3).

    ``depends`` is a tuple of AND terms, each a tuple of OR alternatives: ``"a,b|c,@f"`` becomes
    ``(("a",), ("b", "c"), ("@f",))``. Functionalities always carry their ``@`` prefix, also in
    ``provides``.
    """

    name: str
    task_group: str
    depends: tuple[tuple[str, ...], ...] = ()
    provides: tuple[str, ...] = ()
    conflicts: tuple[str, ...] = ()
    init: tuple[str, ...] = ()
    periodic: tuple[PeriodicSpec, ...] = ()
    event: tuple[str, ...] = ()
    doc: str = ""
    file: str | None = None
    line: int | None = None

    @property
    def where(self) -> str:
        """``file:line`` of the module's definition (for error messages)."""
        f = self.file or "<dict>"
        return f if self.line is None else f"{f}:{self.line}"


@dataclass(frozen=True)
class ModulesConfig:
    """A parsed module file: the library (by name, in file order), the selection, the main loop rate."""

    main_loop_hz: float
    modules: Mapping[str, ModuleSpec]
    select: tuple[str, ...] = ()
    file: str | None = None
    period_us: int = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "period_us", period_us_of(self.main_loop_hz))


def term_text(term: Sequence[str]) -> str:
    """The text of one AND term: ``("b", "c") -> "b|c"``."""
    return "|".join(term)


def is_functionality(name: str) -> bool:
    return name.startswith("@")


def period_us_of(main_loop_hz: float) -> int:
    """Main loop period in integer microseconds; raises ValueError if 1e6 / hz is not an integer."""
    q = Fraction(10**6) / _exact(main_loop_hz)
    if q.denominator != 1 or q < 1:
        raise ValueError(f"main loop frequency {main_loop_hz:g} Hz does not give an integer period in us")
    return int(q)


def prescaler_of(main_loop_hz: float, freq: float) -> int | None:
    """``main_loop_hz / freq`` if it is a positive integer (computed exactly on decimals), else None."""
    if freq <= 0:
        return None
    q = _exact(main_loop_hz) / _exact(freq)
    if q.denominator != 1 or q < 1:
        return None
    return int(q)


def _exact(x: float) -> Fraction:
    # Fraction(repr) reads 0.1 as 1/10, not as the binary double nearest to it.
    return Fraction(repr(float(x)))


# --- parsing -------------------------------------------------------------------------------------

def load_modules(path: str | Path) -> ModulesConfig:
    """Load a module YAML file (see the module docstring); errors are ConfigError(file, line, field)."""
    data = load_yaml(path)
    return parse_modules(data, file=str(path))


def parse_modules(data: Any, file: str | None = None) -> ModulesConfig:
    """Parse a module library from a mapping (YAML ``LineDict`` or a plain dict for tests)."""
    file = getattr(data, "file", None) or file or "<dict>"
    top = Fields(data, "", file)
    top.unknown(_TOP_KEYS)
    hz = top.number("main_loop_hz", DEFAULT_MAIN_LOOP_HZ, positive=True)
    try:
        period_us_of(hz)
    except ValueError as exc:
        raise top.error("main_loop_hz", f"{exc} (1000000 / main_loop_hz must be an integer)") from None

    raw_modules = top.raw("modules")
    if not isinstance(raw_modules, list):
        raise top.error("modules", "expected a list of modules")
    modules: dict[str, ModuleSpec] = {}
    for i, item in enumerate(raw_modules):
        spec = _parse_module(item, f"modules[{i}]", file, _line_of(raw_modules, i, top.line("modules")), hz)
        if spec.name in modules:
            first = modules[spec.name]
            raise ConfigError(file, spec.line, f"modules[{i}].name",
                              f"duplicate module name '{spec.name}' (first defined at {first.where})")
        modules[spec.name] = spec

    select = _name_list(top, "select", file)
    seen: set[str] = set()
    raw_select = top.raw("select", [])
    for i, name in enumerate(select):
        line = _line_of(raw_select, i, top.line("select"))
        if name not in modules:
            raise ConfigError(file, line, f"select[{i}]", f"unknown module '{name}' (not in modules)")
        if name in seen:
            raise ConfigError(file, line, f"select[{i}]", f"module '{name}' selected twice")
        seen.add(name)
    return ModulesConfig(main_loop_hz=hz, modules=modules, select=tuple(select), file=file)


def _parse_module(item: Any, prefix: str, file: str, line: int | None, hz: float) -> ModuleSpec:
    f = Fields(item, prefix, file, line)
    f.unknown(_MODULE_KEYS)
    name = f.string("name")
    if not _NAME_RE.match(name):
        raise f.error("name", f"invalid module name '{name}' (letters, digits, '_', '.', '-')")
    group = f.string("task_group", choices=TASK_GROUPS)
    depends = _expression(f, "depends", allow_or=True)
    provides = tuple(t[0] if is_functionality(t[0]) else "@" + t[0]
                     for t in _expression(f, "provides", allow_or=False))
    conflicts = tuple(t[0] for t in _expression(f, "conflicts", allow_or=False))
    for term in depends:
        if len(term) == 1 and term[0] == name:
            raise f.error("depends", f"module '{name}' depends on itself")
    init = tuple(_name_list(f, "init", file, functions=True))
    event = tuple(_name_list(f, "event", file, functions=True))

    periodic: list[PeriodicSpec] = []
    raw = f.raw("periodic", [])
    if raw is None:
        raw = []
    if not isinstance(raw, list):
        raise f.error("periodic", "expected a list of {function, freq, offset?, cost?} mappings")
    seen: set[str] = set()
    for j, entry in enumerate(raw):
        p = _parse_periodic(entry, f.path(f"periodic[{j}]"), file, _line_of(raw, j, f.line("periodic")), hz)
        if p.function in seen:
            raise ConfigError(file, p.line, f.path(f"periodic[{j}].function"),
                              f"function '{p.function}' listed twice in module '{name}'")
        seen.add(p.function)
        periodic.append(p)
    return ModuleSpec(name=name, task_group=group, depends=depends, provides=provides, conflicts=conflicts,
                      init=init, periodic=tuple(periodic), event=event, doc=f.string("doc", ""),
                      file=file, line=f.line("name"))


def _parse_periodic(entry: Any, prefix: str, file: str, line: int | None, hz: float) -> PeriodicSpec:
    f = Fields(entry, prefix, file, line)
    f.unknown(_PERIODIC_KEYS)
    function = f.string("function")
    if not function.strip():
        raise f.error("function", "empty function name")
    freq = f.number("freq", hz, positive=True)
    n = prescaler_of(hz, freq)
    if n is None:
        raise f.error("freq", f"{freq:g} Hz does not divide the main loop frequency {hz:g} Hz "
                              "(main_loop_hz / freq must be a positive integer)")
    offset = None
    if f.has("offset"):
        offset = f.integer("offset")
        if not 0 <= offset < n:
            raise f.error("offset", f"offset {offset} out of range: must be in [0, {n - 1}] "
                                    f"for prescaler {n} ({freq:g} Hz in a {hz:g} Hz main loop)")
    cost = f.number("cost", lo=0.0) if f.has("cost") else None
    return PeriodicSpec(function=function, freq=freq, prescaler=n, offset=offset, cost=cost,
                        line=f.line("function"))


def _expression(f: Fields, key: str, *, allow_or: bool) -> tuple[tuple[str, ...], ...]:
    """Parse ``"a,b|c,@f"`` (or a list of such strings) into AND terms of OR alternatives."""
    raw = f.raw(key, "")
    if raw is None:
        raw = ""
    if isinstance(raw, list):
        if not all(isinstance(x, str) for x in raw):
            raise f.error(key, "expected a string like 'a,b|c,@func' or a list of strings")
        raw = ",".join(raw)
    if not isinstance(raw, str):
        raise f.error(key, "expected a string like 'a,b|c,@func' or a list of strings")
    if not raw.strip():
        return ()
    terms: list[tuple[str, ...]] = []
    for part in raw.split(","):
        alts = tuple(a.strip() for a in part.split("|"))
        if len(alts) > 1 and not allow_or:
            raise f.error(key, f"'|' (OR) is not allowed in {key}: '{part.strip()}'")
        for a in alts:
            bare = a[1:] if a.startswith("@") else a
            if not bare or not _NAME_RE.match(bare):
                raise f.error(key, f"invalid name '{a}' in '{raw}'")
        if len(set(alts)) != len(alts):
            raise f.error(key, f"repeated alternative in '{part.strip()}'")
        terms.append(alts)
    return tuple(terms)


def _name_list(f: Fields, key: str, file: str, *, functions: bool = False) -> list[str]:
    raw = f.raw(key, [])
    if raw is None:
        return []
    if not isinstance(raw, list):
        raise f.error(key, "expected a list of names")
    out: list[str] = []
    for i, item in enumerate(raw):
        line = _line_of(raw, i, f.line(key))
        if not isinstance(item, str) or not item.strip():
            raise ConfigError(file, line, f.path(f"{key}[{i}]"), "expected a non-empty name")
        if not functions and not _NAME_RE.match(item):
            raise ConfigError(file, line, f.path(f"{key}[{i}]"), f"invalid module name '{item}'")
        out.append(item)
    return out


def _line_of(seq: Any, i: int, default: int | None) -> int | None:
    line_of = getattr(seq, "line_of", None)
    if line_of is None:
        return default
    return line_of(i) or default
