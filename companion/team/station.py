"""The team-control station (seed 003 Fig. 1, the top of the interface hierarchy; Sec. II-III).

Seed 003 Sec. II: "High-level control is commanded by the Team Control Interface, which is used to assign
task-level commands to the entire fleet." The station is a member of the team link like the vehicles
(its own row has status STATION): it is the one writer of the task board (:class:`~.tasks.TaskLedger`)
and it hears the group state. It never assigns: the vehicles divide the tasks among themselves
(Sec. III-B); the station follows what their rows say (:func:`~.tasks.derive_states`) to show each task's
state, holder and cost, and marks a task done once its holder reports it so. When the station stops, the
team goes on with the last board it flooded.

Border patrols and area scans ask for N vehicles. Seed 003: "When the total number of assigned individual
tasks is greater than the number of unassigned UAVs, the user is offered the choice of reducing the number
of UAVs assigned to the border patrol task. In this event, the border task is automatically redivided into
a smaller number of individual tasks and reassigned." :meth:`TeamControlStation.add` answers such a
request with the offer and changes nothing; the operator adds it again with the smaller N, or with
``force`` to keep N (the pieces wait for vehicles). A vehicle is free when it flies no task (no ACTIVE
claim): under CBBA a vehicle whose bundle holds only claims not yet flown re-bids for the new pieces.

:meth:`redivide` re-divides a task already added (the operator's ``POST /api/tasks/{id}/redivide``; without
N, into as many pieces as vehicles can fly it now). When vehicles drop out of a divided task (a piece's
holder gone, taken or overridden, and no free vehicle to take the piece over), the station redivides it
among the vehicles left (:meth:`step`, logged as ``redivided`` with ``why: dropout``), as seed 003 does
for the smaller N.

Durability: an operator verb's change is handed to :attr:`TeamControlStation.persist` (the ground
service's database) before it is published; if that raises, the ledger is put back as it was and the
error goes to the caller (nothing half-done, nothing flown that is not stored). Restored with
``hold=True``, the open tasks of a previous run are held: kept off the published board (no vehicle flies
them) until :meth:`release`, except those a live vehicle is found claiming or flying once the team is
heard again (a restart under running vehicles keeps what they fly).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

from . import kinds
from .groupstate import GroupState
from .link import DEFAULT_PERIOD_S, LinkEvent, TeamLink
from .tasks import Fence, LedgerSnapshot, TaskDef, TaskLedger, derive_states, offer_smaller_n, validate
from .transport import Transport
from .types import STATION_ID, ClaimState, MemberEntry, MemberStatus, TaskBoard, TaskState

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class AddResult:
    """What :meth:`TeamControlStation.add` did: the new task ids, or an offer of a smaller N (nothing
    added), with the number of vehicles free now."""

    ids: tuple[int, ...] = ()
    offer: int | None = None
    free: int = 0

    @property
    def added(self) -> bool:
        return bool(self.ids)


@dataclass(frozen=True)
class TaskView:
    """One task as the operator sees it."""

    id: int
    kind: str
    state: str
    holder: int | None
    cost: float | None
    group: int
    version: int
    name: str
    points: tuple[tuple[float, float, float], ...]


@dataclass
class StationLog:
    """Assignment changes and link events, newest last (bounded)."""

    entries: list[dict[str, Any]] = field(default_factory=list)

    def add(self, **fields: Any) -> None:
        self.entries.append(fields)
        del self.entries[:-1000]


class TeamControlStation:
    """See module docstring. Thread-safe; :meth:`start` runs the link and the follow-up in threads."""

    def __init__(self, transport: Transport, *, fence: Fence | None = None, period_s: float | None = None,
                 clock: Callable[[], float] = time.time, voc_max: int | None = None, name: str = "station",
                 first_id: int = 101, position: tuple[float, float, float] = (0.0, 0.0, 0.0),
                 key: bytes | None = None) -> None:
        self.clock = clock
        self.name = name
        self.position = position
        self.ledger = TaskLedger(fence, first_id=first_id)
        self.state = GroupState(STATION_ID, **({} if voc_max is None else {"voc_max": voc_max}))
        self.link = TeamLink(self.state, transport, period_s=period_s or DEFAULT_PERIOD_S, clock=clock,
                             own=self._own_row, key=key)
        self.link.listeners.append(self._on_link)
        self.log = StationLog()
        self.listeners: list[Callable[[dict[str, Any]], None]] = []
        self._costs: dict[int, float] = {}
        self._conflicts: set[int] = set()
        self.conflicts = 0
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._settle_until = 0.0
        #: writes an operator verb's change ({"event", "ids", ...}) before it is published; raising undoes it
        self.persist: Callable[[dict[str, Any]], None] | None = None
        self._held: set[int] = set()
        self._hold_pending = False
        self._piece_holders: dict[int, int] = {}  # piece of a divided task -> the last vehicle that held it

    # --- lifecycle --------------------------------------------------------------------------------------
    def start(self) -> TeamControlStation:
        self.link.start()
        self._thread = threading.Thread(target=self._loop, name="team-station", daemon=True)
        self._thread.start()
        return self

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        self.link.close()

    def _loop(self) -> None:
        while not self._stop.wait(self.link.period_s / 2.0):
            try:
                self.step()
            except Exception:
                log.exception("team station: follow-up failed")

    def _own_row(self) -> MemberEntry:
        return MemberEntry(member=STATION_ID, stamp=0.0, seq=0, position=self.position,
                           status=MemberStatus.STATION, name=self.name)

    # --- the operator's verbs ---------------------------------------------------------------------------
    def add(self, defn: TaskDef, force: bool = False) -> AddResult:
        """Add an operator task (ValueError naming the field for bad input; nothing changes then)."""
        with self._lock:
            validate(defn, self.ledger.fence)  # bad input is refused before any offer is made
            free = self.free_vehicles()
            if kinds.divided_by_n(defn.kind) and not force:
                offer = offer_smaller_n(defn.n, free)
                if offer is not None:
                    self._record("offer", kind=defn.kind, requested=defn.n, offer=offer, free=free)
                    return AddResult(offer=offer, free=free)
            before = self.ledger.export() if self.persist else None
            ids = self.ledger.add(defn, self.clock())
            self._commit(before, "added", kind=defn.kind, ids=list(ids), name=defn.name)
            return AddResult(ids=ids, free=free)

    def cancel(self, task_id: int) -> tuple[int, ...]:
        """Cancel a task or a divided task's live pieces (ValueError for an unknown or finished task)."""
        with self._lock:
            before = self.ledger.export() if self.persist else None
            ids = self.ledger.cancel(task_id, self.clock())
            self._commit(before, "cancelled", ids=list(ids))
            self._held -= set(ids)
            return ids

    def redivide(self, group: int, n: int | None = None, why: str = "operator") -> tuple[int, ...]:
        """Re-divide the divided task ``group`` into ``n`` pieces (None: as many as vehicles can fly it now:
        those holding one of its pieces and the free ones; at least 1). ValueError for a task that is
        not divided, finished, or a bad N (nothing changes then)."""
        with self._lock:
            if not self._live_pieces(group):
                raise ValueError(f"group: task {group} is not a divided task with live pieces")
            if n is None:
                n = max(1, self.capacity(group))
            if n < 1:
                raise ValueError(f"n: must be >= 1, got {n}")
            before = self.ledger.export() if self.persist else None
            ids = self.ledger.redivide(group, n, self.clock())
            self._commit(before, "redivided", group=group, n=n, ids=list(ids), why=why)
            return ids

    def _live_pieces(self, group: int) -> list[int]:
        return [t.id for t in self.ledger.board().live() if t.group == group and group != 0]

    def capacity(self, group: int) -> int:
        """Vehicles that can fly the divided task ``group`` now: those holding one of its live pieces and
        the free ones (:meth:`free_vehicles`) holding none."""
        pieces = set(self._live_pieces(group))
        rows = self.vehicle_rows()
        holders = {m for m, e in rows.items() if e.status.available
                   and any(c.task in pieces and c.state in (ClaimState.CLAIMED, ClaimState.ACTIVE)
                           for c in e.claims)}
        return len(holders) + sum(1 for m, e in rows.items() if m not in holders and self._free(e))

    def _commit(self, before: LedgerSnapshot | None, event: str, **fields: Any) -> None:
        """Persist an operator verb's change (undone if that fails, the error raised), then record and
        publish it."""
        if self.persist is not None and before is not None:
            try:
                self.persist({"t": round(self.clock(), 3), "event": event, **fields})
            except BaseException:
                self.ledger.restore(before, self.clock())
                raise
        self._record(event, **fields)
        self._publish()

    def release(self, ids: list[int] | None = None) -> tuple[int, ...]:
        """Give held tasks (all with ``None``) to the team: they are published and flown. ValueError
        naming the ids that are not held."""
        with self._lock:
            want = set(self._held) if ids is None else set(ids)
            if ids is not None and not want <= self._held:
                raise ValueError(f"ids: tasks {sorted(want - self._held)} are not held")
            if not want:
                return ()
            self._held -= want
            self.ledger.touch(self.clock())
            self._record("released", ids=sorted(want))
            self._publish()
            return tuple(sorted(want))

    def cost_of(self, task_id: int) -> float | None:
        """The holder's cost of a task (None: not held or not known)."""
        with self._lock:
            return self._costs.get(task_id) if self.ledger.holder(task_id) is not None else None

    def held(self) -> tuple[int, ...]:
        with self._lock:
            return tuple(sorted(self._held))

    def restore(self, snap: LedgerSnapshot, settle_s: float = 10.0, hold: bool = False) -> None:
        """Take the task list of a previous run (a restarted ground service): the same ids and states,
        published with a newer (stamp, seq), so the vehicles keep the tasks they hold. For up to
        ``settle_s`` the follow-up waits until every holder of a live task is heard again (a station
        that has heard nobody yet would otherwise read every held task as unassigned).

        ``hold``: every open task is held (module docstring); once the team is heard (or ``settle_s``
        passed) the tasks a live vehicle claims or flies are kept and published, the others stay held
        until :meth:`release`. Nothing is published before that."""
        with self._lock:
            self.ledger.restore(snap, self.clock())
            self._settle_until = self.clock() + settle_s
            if hold:
                self._held = {t for t in self.ledger.ids() if not self.ledger.state(t).final}
                self._hold_pending = bool(self._held)
            self._record("restored", tasks=len(snap.tasks), groups=len(snap.groups), held=sorted(self._held))
            if not self._hold_pending:
                self._publish()

    # --- following the team ----------------------------------------------------------------------------
    def step(self) -> list[tuple[int, TaskState, int | None]]:
        """Derive each task's state from the rows; the board follows (done, holder changes)."""
        with self._lock:
            rows = self.vehicle_rows()
            if self.clock() < self._settle_until:
                holders = {self.ledger.holder(t) for t in self.ledger.ids()
                           if not self.ledger.state(t).final} - {None}
                if not holders <= set(rows):
                    return []
                self._settle_until = 0.0
            if self._hold_pending:
                self._keep_flown(rows)
            board = self._board()
            derived = derive_states(board, rows)
            self._costs = {tid: cost for tid, (_s, _h, cost) in derived.items()}
            self._watch_conflicts(rows)
            changes = self.ledger.apply(derived, self.clock())
            for tid, state, holder in changes:
                self._record("task", task=tid, state=state.value, holder=holder)
            if changes:
                self._publish()
            self._redivide_after_dropouts(derived, rows)
            return changes

    def _redivide_after_dropouts(self, derived: dict[int, tuple[TaskState, int | None, float]],
                                 rows: dict[int, MemberEntry]) -> None:
        """A divided task whose pieces outnumber the vehicles that can fly it, after a piece's holder
        dropped out (gone, taken, overridden: not among the available rows), is redivided among them."""
        groups: dict[int, list[int]] = {}
        for t in self.ledger.board().live():
            if t.group and t.id not in self._held:  # a held task waits for the operator
                groups.setdefault(t.group, []).append(t.id)
        live = {tid for ids in groups.values() for tid in ids}
        for tid in [t for t in self._piece_holders if t not in live]:
            del self._piece_holders[tid]
        available = {m for m, e in rows.items() if e.status.available}
        for group, ids in groups.items():
            holders = {tid: derived[tid][1] for tid in ids if tid in derived}
            orphaned = [tid for tid in ids if holders.get(tid) is None
                        and tid in self._piece_holders and self._piece_holders[tid] not in available]
            for tid, holder in holders.items():
                if holder is not None:
                    self._piece_holders[tid] = holder
            if not orphaned:
                continue
            n = self.capacity(group)
            if 1 <= n < len(ids):
                log.info("team station: task %d: pieces %s lost their vehicles; redivided among %d", group,
                         orphaned, n)
                self.redivide(group, n, why="dropout")

    def _watch_conflicts(self, rows: dict[int, MemberEntry]) -> None:
        """Seed 003 Sec. V: "conflicts were declared when two UAVs claimed the same task. These conflicts
        were resolved": recorded as ``conflict`` (the claimants) and ``resolved`` (the one left)."""
        claimants: dict[int, list[int]] = {}
        for m, e in rows.items():
            if e.status.available:
                for c in e.claims:
                    if c.state in (ClaimState.CLAIMED, ClaimState.ACTIVE):
                        claimants.setdefault(c.task, []).append(m)
        for tid, members in claimants.items():
            if len(members) > 1 and tid not in self._conflicts:
                self._conflicts.add(tid)
                self.conflicts += 1
                self._record("conflict", task=tid, members=sorted(members))
        for tid in list(self._conflicts):
            if len(claimants.get(tid, [])) <= 1:
                self._conflicts.discard(tid)
                holder = claimants.get(tid, [None])[0]
                self._record("resolved", task=tid, holder=holder)

    def _keep_flown(self, rows: dict[int, MemberEntry]) -> None:
        """The team is heard after a restore with hold: the held tasks a live vehicle claims, flies or
        reports done are kept (published again), the others stay held."""
        self._hold_pending = False
        flown = {c.task for e in rows.values() if e.status.available for c in e.claims
                 if c.state in (ClaimState.CLAIMED, ClaimState.ACTIVE, ClaimState.DONE)}
        kept = self._held & flown
        self._held -= kept
        self.ledger.touch(self.clock())
        self._record("kept", ids=sorted(kept), held=sorted(self._held))
        self._publish()

    def _board(self) -> TaskBoard:
        """The ledger's board without the held tasks."""
        board = self.ledger.board(self.clock())
        if not self._held:
            return board
        return replace(board, tasks=tuple(t for t in board.tasks if t.id not in self._held))

    def _publish(self) -> None:
        board = self._board()
        current = self.state.board
        if current.epoch != self.state.epoch or board.seq > current.seq:
            self.state.set_board(board)

    def _on_link(self, ev: LinkEvent) -> None:
        if ev.kind in ("gone", "joined"):
            self._record(ev.kind, member=ev.member)
        elif ev.kind == "duplicate":
            self._record("duplicate", member=ev.member,
                         message=f"duplicate member id {ev.member}: two members use it; the first keeps its "
                                 "row, the second should refuse to join (give it another id)")
        elif ev.kind == "refused":
            self._record("refused", member=ev.member, message=f"this station refuses to join: {ev.reason}")

    def _record(self, event: str, **fields: Any) -> None:
        entry = {"t": round(self.clock(), 3), "event": event, **fields}
        self.log.add(**entry)
        log.info("team station: %s %s", event, fields)
        for fn in list(self.listeners):
            try:
                fn(entry)
            except Exception:
                log.exception("team station listener failed")

    # --- views ---------------------------------------------------------------------------------------
    def vehicle_rows(self) -> dict[int, MemberEntry]:
        """The live vehicles' rows (not the station's, not the gone ones)."""
        return {m: e for m, e in self.state.alive().items() if e.status is not MemberStatus.STATION}

    def free_vehicles(self) -> int:
        """Vehicles in the team flying no task (seed 003: the unassigned UAVs): a claim not yet flown does
        not bind a vehicle (under CBBA its bundle is re-bid when new tasks come; under greedy it is held
        for a moment before it is flown)."""
        return sum(1 for e in self.vehicle_rows().values() if self._free(e))

    @staticmethod
    def _free(e: MemberEntry) -> bool:
        return e.status.available and not any(c.state is ClaimState.ACTIVE for c in e.claims)

    def tasks(self) -> list[TaskView]:
        with self._lock:
            out = []
            for tid in self.ledger.ids():
                t = self.ledger.task(tid)
                state = self.ledger.state(tid)
                holder = self.ledger.holder(tid)
                cost = self._costs.get(tid) if holder is not None else None
                # held, except while the restore waits for a holder that may come back flying it
                shown = "held" if tid in self._held and (not self._hold_pending or holder is None) \
                    else state.value
                out.append(TaskView(tid, t.kind.value, shown, holder, cost, t.group, t.version, t.name,
                                    t.points))
            return out

    def assignment(self) -> dict[int, tuple[str, int | None]]:
        """task id -> (state, holder)."""
        return {v.id: (v.state, v.holder) for v in self.tasks()}

    def all_final(self) -> bool:
        with self._lock:
            return all(self.ledger.state(t).final for t in self.ledger.ids())
