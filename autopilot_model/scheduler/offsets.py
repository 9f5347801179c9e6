"""Offsets of periodic functions: seed 002 Sec. 4.3 and Fig. 5.

A periodic function of frequency ``f`` in a main loop of frequency ``F`` has the prescaler
``N = F / f`` and runs in the iterations ``i`` where ``i % N == offset``. Over the hyperperiod
``H = lcm(N_1, ..., N_k)`` the pattern repeats. The *load* of an iteration is the sum of the costs of
the functions it calls (cost 1 per call unless an estimate is given, e.g. measured duty time).

Heuristics (a function with an explicit offset keeps it in all of them):

* ``"none"``: offset 0 (Fig. 5, white boxes): all functions coincide at iteration 0 of every
  hyperperiod.
* ``"naive"``: Paparazzi's generator (``gen_modules.ml``), the paper's Fig. 5 caption: ``x`` is
  incremented by 0.1 at each new periodic function (without an explicit offset, in schedule order)
  *before* use and wraps to 0 after 0.9 (so 0.1, 0.2, ..., 0.9, 0.0, 0.1, ...); the offset is
  ``floor(x * N)``. It is computed exactly in integers (``k * N // 10``), so 0.8 gives ``8N // 10``
  where Paparazzi's float accumulation may give one less.
* ``"optimised"``: minimise the largest per-iteration load over the hyperperiod. Greedy in order of
  decreasing load ``cost / N`` (ties: smaller ``N``, then schedule order): each function takes the
  offset that minimises the current maximum load, then the sum of squared loads, then the offset
  itself. Then up to ``_REFINE_PASSES`` passes of local search re-place each function at its best
  offset given all the others, keeping a move only if it lowers (max, sum of squares). Finally, if the
  naive assignment is better on (max, sum of squares) it is returned instead, so ``optimised`` is never
  worse than ``naive`` (the guard rarely fires; see the tests).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .errors import SchedulerError

log = logging.getLogger(__name__)

HEURISTICS: tuple[str, ...] = ("none", "naive", "optimised")
#: Largest hyperperiod accepted (the main loop precomputes one call list per phase).
MAX_HYPERPERIOD = 1_000_000
_REFINE_PASSES = 4
_EPS = 1e-9


@dataclass(frozen=True)
class OffsetTask:
    """A periodic function as seen by the offset heuristics."""

    name: str
    prescaler: int
    cost: float = 1.0
    fixed_offset: int | None = None


@dataclass(frozen=True)
class OffsetReport:
    """Per-iteration load of one offset assignment over one hyperperiod."""

    heuristic: str
    offsets: tuple[int, ...]
    hyperperiod: int
    max_load: float
    mean_load: float
    coincidences: int   # iterations of the hyperperiod in which every function runs


def hyperperiod(prescalers: Sequence[int]) -> int:
    """LCM of the prescalers (1 if there are none); SchedulerError above MAX_HYPERPERIOD."""
    h = math.lcm(*prescalers) if prescalers else 1
    if h > MAX_HYPERPERIOD:
        raise SchedulerError(f"hyperperiod {h} iterations (lcm of prescalers {sorted(set(prescalers))}) "
                             f"exceeds {MAX_HYPERPERIOD}: choose frequencies with a smaller common period")
    return h


def load_profile(tasks: Sequence[OffsetTask], offsets: Sequence[int]) -> np.ndarray:
    """Load of every iteration of the hyperperiod for the given offsets."""
    h = hyperperiod([t.prescaler for t in tasks])
    load = np.zeros(h)
    for t, o in zip(tasks, offsets, strict=True):
        load[o::t.prescaler] += t.cost
    return load


def zero_offsets(tasks: Sequence[OffsetTask]) -> list[int]:
    """Heuristic "none": offset 0, explicit offsets kept."""
    return [t.fixed_offset if t.fixed_offset is not None else 0 for t in tasks]


def naive_offsets(tasks: Sequence[OffsetTask]) -> list[int]:
    """Heuristic "naive": Paparazzi's x += 0.1 per function, offset = floor(x * N) (Fig. 5)."""
    out: list[int] = []
    k = 0
    for t in tasks:
        if t.fixed_offset is not None:
            out.append(t.fixed_offset)
            continue
        k = k + 1 if k < 9 else 0       # 0.1, 0.2, ... 0.9, then 0.0
        out.append(k * t.prescaler // 10)
    return out


def optimised_offsets(tasks: Sequence[OffsetTask], *, guard: bool = True) -> list[int]:
    """Heuristic "optimised": greedy + local search minimising the max per-iteration load.

    With ``guard`` (default) the naive assignment is returned instead when it is better.
    """
    _check(tasks)
    h = hyperperiod([t.prescaler for t in tasks])
    load = np.zeros(h)
    offsets: list[int | None] = [None] * len(tasks)
    for i, t in enumerate(tasks):
        if t.fixed_offset is not None:
            offsets[i] = t.fixed_offset
            load[t.fixed_offset::t.prescaler] += t.cost
    free = [i for i, t in enumerate(tasks) if t.fixed_offset is None]
    free.sort(key=lambda i: (-tasks[i].cost / tasks[i].prescaler, tasks[i].prescaler, i))
    for i in free:
        o = _best_offset(load, tasks[i])
        offsets[i] = o
        load[o::tasks[i].prescaler] += tasks[i].cost

    for _ in range(_REFINE_PASSES):
        improved = False
        for i in free:
            t, cur = tasks[i], offsets[i]
            assert cur is not None
            before = _objective(load)
            load[cur::t.prescaler] -= t.cost
            o = _best_offset(load, t)
            load[o::t.prescaler] += t.cost
            after = _objective(load)
            if o != cur and _better(after, before):
                offsets[i] = o
                improved = True
            else:
                load[o::t.prescaler] -= t.cost
                load[cur::t.prescaler] += t.cost
        if not improved:
            break

    result = [o if o is not None else 0 for o in offsets]
    if not guard:
        return result
    naive = naive_offsets(tasks)
    if _better(_objective(load_profile(tasks, naive)), _objective(load)):
        log.info("optimised offsets: the naive assignment is better for this task set, using it")
        return naive
    return result


def offsets_for(tasks: Sequence[OffsetTask], heuristic: str) -> list[int]:
    """Offsets of ``tasks`` with one of :data:`HEURISTICS`."""
    if heuristic == "none":
        return zero_offsets(tasks)
    if heuristic == "naive":
        return naive_offsets(tasks)
    if heuristic == "optimised":
        return optimised_offsets(tasks)
    raise ValueError(f"unknown offset heuristic '{heuristic}' (one of {', '.join(HEURISTICS)})")


def evaluate(tasks: Sequence[OffsetTask], offsets: Sequence[int], heuristic: str = "") -> OffsetReport:
    """Max and mean per-iteration load and the number of iterations where all functions coincide."""
    load = load_profile(tasks, offsets)
    count = np.zeros(len(load), dtype=np.int64)
    for t, o in zip(tasks, offsets, strict=True):
        count[o::t.prescaler] += 1
    return OffsetReport(heuristic=heuristic, offsets=tuple(offsets), hyperperiod=len(load),
                        max_load=float(load.max()) if len(load) else 0.0,
                        mean_load=float(load.mean()) if len(load) else 0.0,
                        coincidences=int((count == len(tasks)).sum()) if tasks else 0)


def offset_report(tasks: Sequence[OffsetTask] | object) -> dict[str, OffsetReport]:
    """For "none", "naive" and "optimised": max / mean load and coincidences over the hyperperiod.

    ``tasks`` is a sequence of :class:`OffsetTask` or a :class:`~.schedule.Schedule` (its periodic
    functions, with their costs and explicit offsets).
    """
    as_tasks = getattr(tasks, "offset_tasks", None)
    task_list: Sequence[OffsetTask] = as_tasks() if callable(as_tasks) else tasks  # type: ignore[assignment]
    return {h: evaluate(task_list, offsets_for(task_list, h), h) for h in HEURISTICS}


def format_offset_report(report: dict[str, OffsetReport]) -> str:
    """A small text table of :func:`offset_report`."""
    lines = [f"{'offsets':<10} {'max load':>9} {'mean load':>10} {'all coincide':>13} {'hyperperiod':>12}"]
    for name, r in report.items():
        lines.append(f"{name:<10} {r.max_load:>9.3g} {r.mean_load:>10.3g} {r.coincidences:>13d} "
                     f"{r.hyperperiod:>12d}")
    return "\n".join(lines)


# --- helpers -------------------------------------------------------------------------------------

def _check(tasks: Sequence[OffsetTask]) -> None:
    for t in tasks:
        if t.prescaler < 1:
            raise ValueError(f"{t.name}: prescaler must be >= 1, got {t.prescaler}")
        if t.cost < 0 or not math.isfinite(t.cost):
            raise ValueError(f"{t.name}: cost must be finite and >= 0, got {t.cost}")
        if t.fixed_offset is not None and not 0 <= t.fixed_offset < t.prescaler:
            raise ValueError(f"{t.name}: offset {t.fixed_offset} not in [0, {t.prescaler - 1}]")


def _best_offset(load: np.ndarray, t: OffsetTask) -> int:
    """Offset minimising (max load, sum of squares, offset) once ``t`` is added to ``load``."""
    n = t.prescaler
    if n == 1:
        return 0
    cols = load.reshape(-1, n)               # column o = iterations o, o+n, o+2n, ...
    new_max = np.maximum(cols.max(axis=0) + t.cost, load.max())
    # sum of squares grows by sum((l + c)^2 - l^2) = 2 c sum(l) + c^2 * (H / n): compare sum(l)
    sums = cols.sum(axis=0)
    cand = np.flatnonzero(new_max <= new_max.min() + _EPS)
    s = sums[cand]
    return int(cand[s <= s.min() + _EPS][0])


def _objective(load: np.ndarray) -> tuple[float, float]:
    return (float(load.max()) if len(load) else 0.0, float(np.dot(load, load)))


def _better(a: tuple[float, float], b: tuple[float, float]) -> bool:
    if a[0] < b[0] - _EPS:
        return True
    return a[0] <= b[0] + _EPS and a[1] < b[1] - _EPS * max(1.0, b[1])
