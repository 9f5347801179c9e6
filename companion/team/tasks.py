"""The operator's team tasks and their division into allocatable pieces (seed 003 Sec. II).

Seed 003 Sec. II: "A general format for handling multi-agent tasks is demonstrated via the border patrol
task, which prompts the user to select the desired number of patrolling UAVs. The border is then divided
into the desired number of individual UAV tasks. When the total number of assigned individual tasks is
greater than the number of unassigned UAVs, the user is offered the choice of reducing the number of UAVs
... the border task is automatically redivided into a smaller number of individual tasks and reassigned."

* :class:`TaskDef` is what the operator gives: a visit (a point), a patrol line (a polyline flown back
  and forth until cancelled), a border patrol divided among N (N pieces of equal length), an area scan
  divided among N (N parts of equal area), or a TST (a C root gives one task per child, delegated to
  different vehicles); each kind is one module of :mod:`companion.team.kinds`.
* :func:`validate` and :func:`divide` turn a definition into :class:`~companion.team.types.TeamTask` s,
  asking its kind.
* :class:`TaskLedger` is the team-control station's task list: ids, versions and the state machine
  unassigned -> assigned -> active -> done, any live state -> cancelled, assigned/active -> unassigned
  when the holder drops the task or is gone. :meth:`TaskLedger.board` publishes it.
* :func:`derive_states` reads a task's state from the members' rows (their claims).

Bad input raises :class:`ValueError` naming the field, and the ledger is left as it was.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from shapely.geometry import Point, Polygon

from companion.team import kinds
from companion.team.geometry import LocalFrame
from companion.team.types import (
    ClaimState,
    GeoPoint,
    MemberEntry,
    TaskBoard,
    TaskState,
    TeamTask,
)

#: the operator's task kinds (divided kinds are split into BORDER_PIECE / AREA_PART team tasks)
DEF_KINDS = kinds.names()
#: the most pieces a task may be divided into
MAX_PIECES = 64


@dataclass(frozen=True)
class Fence:
    """The operational envelope: a polygon in local metres of ``frame`` (x north, y east), or in
    (lat, lon) degrees when ``frame`` is None. "A task outside the fence must be rejected"."""

    polygon: Polygon
    frame: LocalFrame | None = None

    def contains(self, p: GeoPoint) -> bool:
        if self.frame is None:
            q = Point(p[0], p[1])
        else:
            x, y, _ = self.frame.to_local(p)
            q = Point(x, y)
        return self.polygon.covers(q)


@dataclass(frozen=True)
class TaskDef:
    """One task as the operator gives it (``n``: the number of vehicles for a divided task; ``points``
    [lat, lon] or [lat, lon, alt] as given, checked by :func:`validate`)."""

    kind: str
    points: tuple[Sequence[float], ...] = ()
    n: int = 1
    altitude: float = 0.0
    speed: float = 0.0
    name: str = ""
    tree: Mapping[str, Any] | None = None


def validate(defn: TaskDef, fence: Fence | None = None) -> tuple[GeoPoint, ...]:
    """Check a definition; returns its points. Raises ValueError naming the field."""
    kind = kinds.by_name(defn.kind)
    for name in ("altitude", "speed"):
        v = getattr(defn, name)
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) or v < 0:
            raise ValueError(f"{name}: must be a finite number >= 0, got {v!r}")
    if isinstance(defn.n, bool) or not isinstance(defn.n, int) or defn.n < 1:
        raise ValueError(f"n: the number of vehicles must be an integer >= 1, got {defn.n!r}")
    if defn.n > MAX_PIECES:
        raise ValueError(f"n: at most {MAX_PIECES} pieces, got {defn.n}")
    if defn.n != 1 and not kind.divided_by_n:
        divided = " or ".join(k for k in kinds.names() if kinds.divided_by_n(k))
        raise ValueError(f"n: only a {divided} is divided, not a {defn.kind}")
    pts = kind.points(defn)
    kind.check(defn, pts)
    if fence is not None:
        for i, p in enumerate(pts):
            if not fence.contains(p):
                raise ValueError(f"points[{i}]: {p[0]:.7f}, {p[1]:.7f} is outside the fence")
    return pts


def divide(defn: TaskDef, ids: Iterable[int], fence: Fence | None = None, group: int = 0
           ) -> list[TeamTask]:
    """The allocatable TeamTasks of ``defn`` with ids drawn from ``ids`` (``group``: the parent's id).

    Each kind divides its own (:mod:`companion.team.kinds`): a border patrol into ``n`` pieces of equal
    length, an area scan into ``n`` parts of equal area, a TST with a C root into one task per child.
    """
    pts = validate(defn, fence)
    common: dict[str, Any] = {"version": 1, "altitude": float(defn.altitude), "speed": float(defn.speed)}
    return kinds.by_name(defn.kind).divide(defn, pts, iter(ids), group, common)


def offer_smaller_n(requested: int, free: int) -> int | None:
    """Seed 003 Sec. II: more pieces than unassigned vehicles -> the smaller N to offer the operator
    (``free``, at least 1); None when ``requested`` pieces fit the free vehicles, and always for one piece
    (the offer itself: asked again with the N offered while every vehicle is busy, one piece is taken and
    waits for a vehicle, as any task does, instead of the same offer being made again)."""
    if requested < 1:
        raise ValueError(f"requested: must be >= 1, got {requested}")
    if free < 0:
        raise ValueError(f"free: must be >= 0, got {free}")
    return None if requested <= max(1, free) else max(1, free)


#: legal state transitions of a task on the station's ledger
TRANSITIONS: dict[TaskState, frozenset[TaskState]] = {
    TaskState.UNASSIGNED: frozenset({TaskState.ASSIGNED, TaskState.CANCELLED}),
    TaskState.ASSIGNED: frozenset({TaskState.ACTIVE, TaskState.UNASSIGNED, TaskState.CANCELLED}),
    TaskState.ACTIVE: frozenset({TaskState.DONE, TaskState.UNASSIGNED, TaskState.CANCELLED}),
    TaskState.DONE: frozenset(),
    TaskState.CANCELLED: frozenset(),
}


class TransitionError(ValueError):
    """An illegal task state transition."""


@dataclass
class _Row:
    task: TeamTask
    state: TaskState = TaskState.UNASSIGNED
    holder: int | None = None


@dataclass
class _Group:
    defn: TaskDef
    pieces: list[int] = field(default_factory=list)


@dataclass(frozen=True)
class LedgerSnapshot:
    """A :class:`TaskLedger`'s content: every task with its ledger state and holder, the divided tasks'
    definitions and pieces, the next id and the board's (stamp, seq)."""

    tasks: tuple[tuple[TeamTask, TaskState, int | None], ...]
    groups: tuple[tuple[int, TaskDef, tuple[int, ...]], ...]
    next_id: int
    seq: int
    stamp: float


class TaskLedger:
    """The team-control station's task list (the one writer of the board, seed 003 Sec. III-B)."""

    def __init__(self, fence: Fence | None = None, first_id: int = 101) -> None:
        self.fence = fence
        self._next = first_id
        self._rows: dict[int, _Row] = {}
        self._groups: dict[int, _Group] = {}
        self._seq = 0
        self._stamp = 0.0

    # --- operator verbs -----------------------------------------------------------------------------
    def add(self, defn: TaskDef, now: float | None = None) -> tuple[int, ...]:
        """Add an operator task; returns the ids of its allocatable tasks (nothing changes on error)."""
        divided = kinds.by_name(defn.kind).is_group(defn)
        start = self._next
        group = start if divided else 0
        counter = iter(range(start + (1 if divided else 0), start + 10_000))
        tasks = divide(defn, counter, self.fence, group)
        self._next = max(t.id for t in tasks) + 1
        if divided:
            self._groups[group] = _Group(defn, [t.id for t in tasks])
        for t in tasks:
            self._rows[t.id] = _Row(t)
        self._changed(now)
        return tuple(t.id for t in tasks)

    def cancel(self, task_id: int, now: float | None = None) -> tuple[int, ...]:
        """Cancel a task, or every live piece of a group; returns the cancelled ids."""
        if task_id in self._groups:
            ids = [i for i in self._groups[task_id].pieces if not self._rows[i].state.final]
        elif task_id in self._rows:
            ids = [task_id]
        else:
            raise ValueError(f"task: no task {task_id}")
        for i in ids:
            self._check(i, TaskState.CANCELLED)
        for i in ids:
            self._set(i, TaskState.CANCELLED, None)
        self._changed(now)
        return tuple(ids)

    def redivide(self, group: int, n: int, now: float | None = None) -> tuple[int, ...]:
        """Seed 003: re-divide a border/area into ``n`` pieces (the live old pieces are cancelled)."""
        if group not in self._groups:
            raise ValueError(f"group: no divided task {group}")
        old = self._groups[group]
        defn = replace(old.defn, n=n)
        start = self._next
        tasks = divide(defn, iter(range(start, start + 10_000)), self.fence, group)
        for i in old.pieces:
            if not self._rows[i].state.final:
                self._set(i, TaskState.CANCELLED, None)
        self._next = max(t.id for t in tasks) + 1
        self._groups[group] = _Group(defn, [t.id for t in tasks])
        for t in tasks:
            self._rows[t.id] = _Row(t)
        self._changed(now)
        return tuple(t.id for t in tasks)

    # --- persistence --------------------------------------------------------------------------------
    def export(self) -> LedgerSnapshot:
        """Everything :meth:`restore` needs to rebuild this ledger (the ground service persists it)."""
        return LedgerSnapshot(
            tasks=tuple((r.task, r.state, r.holder) for r in self._rows.values()),
            groups=tuple((g, grp.defn, tuple(grp.pieces)) for g, grp in self._groups.items()),
            next_id=self._next, seq=self._seq, stamp=self._stamp)

    def restore(self, snap: LedgerSnapshot, now: float | None = None) -> None:
        """Rebuild the ledger from ``snap`` (the same ids, states, holders, versions and groups), e.g. a
        restarted ground service from its database. The next ids continue past every restored id, and
        the board advances past the snapshot's (stamp, seq) (``now``: the restart's time), so members
        holding the old board take the restored one. Raises ValueError (nothing changed) when the
        snapshot is inconsistent: a duplicate id, a group naming an unknown piece, an illegal holder."""
        rows: dict[int, _Row] = {}
        for task, state, holder in snap.tasks:
            if task.id in rows:
                raise ValueError(f"tasks: task {task.id} twice")
            if holder is not None and state not in (TaskState.ASSIGNED, TaskState.ACTIVE, TaskState.DONE):
                raise ValueError(f"tasks: task {task.id} is {state.value} but has holder {holder}")
            rows[task.id] = _Row(task, TaskState(state), holder)
        groups: dict[int, _Group] = {}
        for gid, defn, pieces in snap.groups:
            missing = [i for i in pieces if i not in rows]
            if missing:
                raise ValueError(f"groups: group {gid} names unknown pieces {missing}")
            groups[gid] = _Group(defn, list(pieces))
        top = max([*rows, *groups, 0])
        self._rows, self._groups = rows, groups
        self._next = max(int(snap.next_id), top + 1, self._next)
        self._seq = max(int(snap.seq), self._seq)
        self._stamp = max(float(snap.stamp), self._stamp)
        self._changed(now)

    @property
    def next_id(self) -> int:
        return self._next

    @property
    def stamp_seq(self) -> tuple[float, int]:
        """The board's (stamp, seq) now."""
        return self._stamp, self._seq

    def group(self, gid: int) -> tuple[TaskDef, tuple[int, ...]] | None:
        """A divided task's definition and pieces (None: no such group)."""
        g = self._groups.get(gid)
        return (g.defn, tuple(g.pieces)) if g is not None else None

    def touch(self, now: float | None = None) -> None:
        """Advance the board's (stamp, seq) with nothing else changed: the station publishes a board
        whose view it changed (tasks held back from the team, then released)."""
        self._changed(now)

    # --- state machine ----------------------------------------------------------------------------
    def transition(self, task_id: int, to: TaskState, holder: int | None = None, now: float | None = None
                   ) -> None:
        """Move a task to ``to`` (TransitionError when illegal, naming both states)."""
        self._check(task_id, to)
        self._set(task_id, to, holder if to in (TaskState.ASSIGNED, TaskState.ACTIVE, TaskState.DONE)
                  else None)
        self._changed(now)

    def assign(self, task_id: int, holder: int, now: float | None = None) -> None:
        row = self._row(task_id)
        if row.state is TaskState.ASSIGNED:  # a new holder (a conflict resolved, a re-allocation)
            row.holder = holder
            self._changed(now)
            return
        self.transition(task_id, TaskState.ASSIGNED, holder, now)

    def apply(self, derived: Mapping[int, tuple[TaskState, int | None, float]], now: float | None = None
              ) -> list[tuple[int, TaskState, int | None]]:
        """Follow the states derived from the rows (:func:`derive_states`) through legal steps
        (unassigned -> assigned -> active -> done); returns the changes (id, new state, holder)."""
        order = [TaskState.UNASSIGNED, TaskState.ASSIGNED, TaskState.ACTIVE, TaskState.DONE]
        changes = []
        for tid, (state, holder, _cost) in derived.items():
            row = self._rows.get(tid)
            if row is None or row.state.final or state is TaskState.CANCELLED:
                continue
            if state is row.state and holder == row.holder:
                continue
            if state is TaskState.UNASSIGNED:
                self._set(tid, TaskState.UNASSIGNED, None)
            else:
                k = order.index(row.state)
                for step in order[k + 1:order.index(state) + 1]:
                    self._set(tid, step, holder)
                row.holder = holder
            changes.append((tid, row.state, row.holder))
        if changes:
            self._changed(now)
        return changes

    # --- reading ---------------------------------------------------------------------------------------
    def state(self, task_id: int) -> TaskState:
        return self._row(task_id).state

    def holder(self, task_id: int) -> int | None:
        return self._row(task_id).holder

    def task(self, task_id: int) -> TeamTask:
        return self._row(task_id).task

    def ids(self) -> tuple[int, ...]:
        return tuple(self._rows)

    def group_of(self, group: int) -> tuple[int, ...]:
        return tuple(self._groups[group].pieces) if group in self._groups else ()

    def board(self, now: float | None = None) -> TaskBoard:
        """The board to publish (stamp: the last change, seq advancing with every change)."""
        return TaskBoard(stamp=self._stamp, seq=self._seq, tasks=tuple(r.task for r in self._rows.values()))

    # --- internals -------------------------------------------------------------------------------------
    def _row(self, task_id: int) -> _Row:
        if task_id not in self._rows:
            raise ValueError(f"task: no task {task_id}")
        return self._rows[task_id]

    def _check(self, task_id: int, to: TaskState) -> None:
        row = self._row(task_id)
        if to not in TRANSITIONS[row.state]:
            raise TransitionError(f"task {task_id}: illegal transition {row.state.value} -> {to.value}")

    def _set(self, task_id: int, to: TaskState, holder: int | None) -> None:
        row = self._rows[task_id]
        row.state = to
        row.holder = holder
        published = to if to.final else TaskState.UNASSIGNED
        if published is not row.task.state:
            row.task = replace(row.task, state=published, version=row.task.version + 1)

    def _changed(self, now: float | None) -> None:
        self._seq += 1
        if now is not None:
            self._stamp = max(self._stamp, float(now))


def derive_states(board: TaskBoard, entries: Mapping[int, MemberEntry] | Iterable[MemberEntry]
                  ) -> dict[int, tuple[TaskState, int | None, float]]:
    """Each task's (state, holder, cost) from the members' rows (their claims, seed 003 Sec. III-B).

    Only members whose status is available count. A live task is DONE if a member reports it done,
    ACTIVE if a member flies it, ASSIGNED if claimed (the holder: the lowest cost, ties by the lower id),
    else UNASSIGNED. A final task keeps its board state. Claims for another version are ignored.
    """
    rows: Sequence[MemberEntry] = list(entries.values() if isinstance(entries, Mapping) else entries)
    out: dict[int, tuple[TaskState, int | None, float]] = {}
    rank = {ClaimState.DONE: 0, ClaimState.ACTIVE: 1, ClaimState.CLAIMED: 2}
    to_state = {ClaimState.DONE: TaskState.DONE, ClaimState.ACTIVE: TaskState.ACTIVE,
                ClaimState.CLAIMED: TaskState.ASSIGNED}
    for t in board.tasks:
        if t.state.final:
            out[t.id] = (t.state, None, math.nan)
            continue
        best: tuple[int, float, int] | None = None
        for e in rows:
            if not e.status.available:
                continue
            for c in e.claims:
                if c.task == t.id and c.version == t.version and c.state in rank:
                    key = (rank[c.state], c.cost, e.member)
                    if best is None or key < best:
                        best = key
        if best is None:
            out[t.id] = (TaskState.UNASSIGNED, None, math.nan)
        else:
            state = next(s for s, r in rank.items() if r == best[0])
            out[t.id] = (to_state[state], best[2], best[1])
    return out
