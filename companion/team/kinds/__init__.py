"""The registry of team task kinds (seed 003 Sec. II-III): one module per kind.

========================  ==============  =====================================================
operator's kind           board's kind    module
========================  ==============  =====================================================
``visit``                 visit           :mod:`.visit`
``patrol_line``           patrol_line     :mod:`.patrol_line`
``border_patrol``         border_piece    :mod:`.border` (divided among ``n`` vehicles)
``area_scan``             area_part       :mod:`.area` (divided among ``n`` vehicles)
``tst``                   tst             :mod:`.tst` (a C root: one task per child)
========================  ==============  =====================================================

A new kind is a :class:`~.base.TeamTaskKind` subclass given to :func:`register` (its board kind a
member of :class:`~companion.team.types.TaskKind`, its wire code unused). Nothing else asks which kind
a task is: the ledger, the cost, the trees, the simulator and the wire format ask the kind.
"""

from __future__ import annotations

from companion.team.types import TaskKind

from .area import AreaScan
from .base import Route, TeamTaskKind, check_point
from .border import BorderPatrol
from .patrol_line import PatrolLine
from .tst import Tst, tst_points
from .visit import Visit

_BY_NAME: dict[str, TeamTaskKind] = {}
_BY_TASK: dict[TaskKind, TeamTaskKind] = {}


def register(kind: TeamTaskKind) -> TeamTaskKind:
    """Add ``kind`` (ValueError when its name, board kind or wire code is taken)."""
    if kind.name in _BY_NAME:
        raise ValueError(f"team task kind {kind.name!r} is registered already")
    if kind.task_kind in _BY_TASK:
        raise ValueError(f"board kind {kind.task_kind.value!r} is registered already")
    if any(k.wire_code == kind.wire_code for k in _BY_NAME.values()):
        raise ValueError(f"wire code {kind.wire_code} is taken")
    _BY_NAME[kind.name] = kind
    _BY_TASK[kind.task_kind] = kind
    return kind


def names() -> tuple[str, ...]:
    """The operator's kinds, in registration order."""
    return tuple(_BY_NAME)


def by_name(name: str) -> TeamTaskKind:
    """The kind of an operator's definition (ValueError naming ``kind`` when unknown)."""
    try:
        return _BY_NAME[name]
    except (KeyError, TypeError):
        raise ValueError(f"kind: must be one of {', '.join(_BY_NAME)}; got {name!r}") from None


def for_task(kind: TaskKind) -> TeamTaskKind:
    """The kind of a board's task."""
    try:
        return _BY_TASK[TaskKind(kind)]
    except (KeyError, ValueError):
        raise ValueError(f"unknown team task kind {kind!r}") from None


def divided_by_n(name: str) -> bool:
    """The operator gives ``n`` for this kind (False for an unknown name)."""
    k = _BY_NAME.get(name)
    return k is not None and k.divided_by_n


def wire_codes() -> dict[TaskKind, int]:
    return {k.task_kind: k.wire_code for k in _BY_NAME.values()}


def check_directed(kind: TaskKind, n_points: int) -> None:
    """A directed task of ``kind`` with ``n_points`` points can be built (ValueError naming the field)."""
    k = for_task(kind)
    if not k.directable:
        raise ValueError("kind: give a tree through POST /mission")
    if n_points < k.min_points:
        raise ValueError(f"points: a {k.task_kind.value} task needs at least {k.min_points} points")


for _kind in (Visit(), PatrolLine(), BorderPatrol(), AreaScan(), Tst()):
    register(_kind)

__all__ = ["Route", "TeamTaskKind", "by_name", "check_directed", "check_point", "divided_by_n", "for_task",
           "names", "register", "tst_points", "wire_codes"]
