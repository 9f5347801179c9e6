"""The static schedule: which function runs in which iteration, in which order (seed 002 Sec. 4.2-4.3).

Built from a parsed module library: the modules are resolved and ordered (Algorithm 1), their
functions are grouped by task group in the fixed order :data:`~.spec.TASK_GROUPS` (within a group:
the topological order of the modules, then the order of the functions in the module), and every
periodic function gets a prescaler and an offset (:mod:`.offsets`).

Orders:

* init functions: the topological order of the modules (dependencies first), across groups;
* event functions: group order, then topological order (all polled at the start of every iteration);
* periodic functions: group order, then topological order, then file order in the module.

Function names are bound to callables with :meth:`Schedule.bind` (a registry ``{name: callable}``
built by the vehicle); the schedule itself is plain data and can be inspected without it.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace

from .errors import SchedulerError
from .offsets import HEURISTICS, OffsetTask, hyperperiod, offsets_for
from .resolve import Resolution, resolve_modules
from .spec import TASK_GROUPS, ModulesConfig

log = logging.getLogger(__name__)

Registry = Mapping[str, Callable[[], object]]


@dataclass(frozen=True)
class FunctionRef:
    """An init or event function of a module (``fn`` is set once bound to a registry)."""

    name: str
    module: str
    group: str
    where: str
    fn: Callable[[], object] | None = None


@dataclass(frozen=True)
class PeriodicCall:
    """A periodic function placed in the schedule: runs when ``iteration % prescaler == offset``."""

    name: str
    module: str
    group: str
    where: str
    freq: float
    prescaler: int
    offset: int
    cost: float = 1.0
    fixed: bool = False     # the offset was given explicitly in the module file
    fn: Callable[[], object] | None = None


@dataclass(frozen=True)
class Schedule:
    """The complete static schedule of the main loop."""

    main_loop_hz: float
    period_us: int
    modules: tuple[str, ...]                 # fully ordered (Algorithm 1, second pass)
    groups: Mapping[str, tuple[str, ...]]    # task group -> its modules in topological order
    init: tuple[FunctionRef, ...]
    events: tuple[FunctionRef, ...]
    periodic: tuple[PeriodicCall, ...]
    hyperperiod: int
    heuristic: str
    resolution: Resolution

    def functions(self) -> tuple[FunctionRef | PeriodicCall, ...]:
        """Every function of the schedule: init, events, periodic."""
        return (*self.init, *self.events, *self.periodic)

    @property
    def bound(self) -> bool:
        """True when every function has its callable (see :meth:`bind`)."""
        return all(f.fn is not None for f in self.functions())

    def bind(self, registry: Registry) -> Schedule:
        """Return a copy whose functions are looked up in ``registry``; SchedulerError lists the missing."""
        missing = sorted({f"'{f.name}' of module '{f.module}' ({f.where})"
                          for f in self.functions() if f.name not in registry})
        if missing:
            raise SchedulerError("functions not in the registry: " + "; ".join(missing))
        for f in self.functions():
            if not callable(registry[f.name]):
                raise SchedulerError(f"registry entry '{f.name}' of module '{f.module}' is not callable")
        return replace(
            self,
            init=tuple(replace(f, fn=registry[f.name]) for f in self.init),
            events=tuple(replace(f, fn=registry[f.name]) for f in self.events),
            periodic=tuple(replace(f, fn=registry[f.name]) for f in self.periodic),
        )

    def offset_tasks(self) -> list[OffsetTask]:
        """The periodic functions as :class:`~.offsets.OffsetTask` (explicit offsets fixed)."""
        return [OffsetTask(p.name, p.prescaler, p.cost, p.offset if p.fixed else None) for p in self.periodic]

    def with_heuristic(self, heuristic: str) -> Schedule:
        """The same schedule with offsets recomputed by another heuristic (explicit offsets kept)."""
        offsets = offsets_for(self.offset_tasks(), heuristic)
        periodic = tuple(replace(p, offset=o) for p, o in zip(self.periodic, offsets, strict=True))
        return replace(self, periodic=periodic, heuristic=heuristic)

    def due(self, iteration: int) -> list[tuple[str, list[PeriodicCall]]]:
        """The periodic calls of one iteration, as ``[(group, [calls...]), ...]`` in execution order."""
        out: list[tuple[str, list[PeriodicCall]]] = []
        for g in TASK_GROUPS:
            calls = [p for p in self.periodic if p.group == g and iteration % p.prescaler == p.offset]
            if calls:
                out.append((g, calls))
        return out

    def describe(self) -> str:
        """A text listing: modules in order, then per group the functions with prescaler and offset."""
        lines = [f"main loop {self.main_loop_hz:g} Hz (period {self.period_us} us), hyperperiod "
                 f"{self.hyperperiod} iterations, offsets: {self.heuristic}",
                 "modules: " + ", ".join(self.modules)]
        if self.events:
            lines.append("events (every iteration): " + ", ".join(e.name for e in self.events))
        for g in TASK_GROUPS:
            calls = [p for p in self.periodic if p.group == g]
            if not calls:
                continue
            lines.append(f"{g}:")
            for p in calls:
                fixed = " (fixed)" if p.fixed else ""
                lines.append(f"  {p.name:<32} {p.freq:>8g} Hz  every {p.prescaler:>5} at {p.offset}{fixed}"
                             f"  [{p.module}]")
        return "\n".join(lines)


def build_schedule(config: ModulesConfig, registry: Registry | None = None, *,
                   select: Sequence[str] | None = None, heuristic: str = "optimised",
                   costs: Mapping[str, float] | None = None) -> Schedule:
    """Resolve ``config`` (seed 002 Algorithm 1) and lay out its functions; bind them if a registry is given.

    ``select`` overrides the file's ``select`` list; ``heuristic`` is one of ``none``, ``naive``,
    ``optimised`` (default); ``costs`` maps function names to a per-call load estimate overriding
    the ``cost`` of the module file (default 1 per call).
    """
    if heuristic not in HEURISTICS:
        raise ValueError(f"unknown offset heuristic '{heuristic}' (one of {', '.join(HEURISTICS)})")
    chosen = tuple(select) if select is not None else config.select
    unknown = [m for m in chosen if m not in config.modules]
    if unknown:
        raise SchedulerError(f"selected module(s) not in the library: {', '.join(unknown)}")
    resolution = resolve_modules(config.modules, chosen)
    specs = [config.modules[m] for m in resolution.order]
    costs = dict(costs or {})

    groups = {g: tuple(s.name for s in specs if s.task_group == g) for g in TASK_GROUPS}
    init = tuple(FunctionRef(n, s.name, s.task_group, s.where) for s in specs for n in s.init)
    events: list[FunctionRef] = []
    periodic: list[PeriodicCall] = []
    for g in TASK_GROUPS:
        for s in specs:
            if s.task_group != g:
                continue
            events.extend(FunctionRef(n, s.name, g, s.where) for n in s.event)
            for p in s.periodic:
                cost = costs.pop(p.function, p.cost if p.cost is not None else 1.0)
                if cost < 0:
                    raise ValueError(f"cost of '{p.function}' must be >= 0, got {cost}")
                where = f"{s.file or '<dict>'}:{p.line}" if p.line is not None else s.where
                periodic.append(PeriodicCall(p.function, s.name, g, where, p.freq, p.prescaler,
                                             p.offset if p.offset is not None else 0, float(cost),
                                             p.offset is not None))
    if costs:
        log.warning("cost estimates for functions not in the schedule ignored: %s", ", ".join(sorted(costs)))

    h = hyperperiod([p.prescaler for p in periodic])
    schedule = Schedule(main_loop_hz=config.main_loop_hz, period_us=config.period_us,
                        modules=resolution.order, groups=groups, init=init, events=tuple(events),
                        periodic=tuple(periodic), hyperperiod=h, heuristic="none", resolution=resolution)
    schedule = schedule.with_heuristic(heuristic)
    log.info("schedule: %d modules, %d periodic functions, hyperperiod %d, offsets %s",
             len(schedule.modules), len(periodic), h, heuristic)
    return schedule.bind(registry) if registry is not None else schedule
