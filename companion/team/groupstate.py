"""The group state with the vote of confidence (seed 003 Sec. III-A, "Orinoco").

Seed 003 Sec. III-A: "group-state information can be visualized as a two-dimensional vector where one
dimension denotes the particular vehicle and the other dimension denotes the specific field of
interest"; "each vehicle information entry includes a GPS time stamp and a sequence number, which
provide an origin and a resolution ... the protocol uses the time and sequence number of each newly
received entry to decide whether or not to update the local entries"; "the voc decreases every sample
interval if an entry has not been updated by that particular entry's owner. It is updated only when a
message is heard from the owner of that entry or from another vehicle with a higher voc number for
that entry."

:class:`GroupState` is that vector on one member, one :class:`~companion.team.types.MemberEntry` per
member with one writer per row: only the owner refreshes its row (:meth:`GroupState.refresh_own`);
rows of others come only through :meth:`GroupState.merge` (controlled flooding). The voc rules:

* a row heard from its owner (the packet's sender is the row's member) and not older than the local
  one is taken (if newer) and its voc set to ``voc_max``;
* a newer row from a relay replaces the local one and carries the relay's voc for it;
* the same row from a relay with a higher voc raises the local voc to it (not for a gone row: a late
  relay of an old row cannot resurrect a member);
* :meth:`GroupState.tick`, once per sample interval, lowers by one the voc of every row whose owner
  was not heard since the last tick; a row reaching zero is *gone*. Gone rows are kept, so only a
  genuinely newer row (a rebooted vehicle, a vehicle back in range) brings the member back.

The task board has one writer too, the team-control station (:meth:`GroupState.set_board`); others
take a board only when newer (:meth:`GroupState.merge_board`).

Time that survives reboots. The paper's GPS time stamp is replaced by the owner's boot epoch (a random
64-bit number each member draws when it starts, :func:`new_epoch`): rows are ordered by seq within one
epoch (:meth:`~companion.team.types.MemberEntry.newer_than`), so a companion that reboots with its clock an
hour behind is seen at once. The identity rule decides between two epochs of one member id: a row of
another epoch replaces the one held only when that one is *stale* (its owner not heard for
``stale_ticks`` sample intervals: 1.5 s at the default period, well below the time a companion takes to
restart) or gone; while the held epoch is heard, the other one is counted (``MergeResult.other_epoch``)
and never taken, so the first of two vehicles with one id keeps its row everywhere (the second refuses
to join, :class:`~companion.team.link.TeamLink`). The board follows the station's epoch: a board of
another epoch is taken once the station's row of that epoch has been taken (the same rule), within an
epoch the higher version wins.
"""

from __future__ import annotations

import dataclasses
import logging
import secrets
import threading
from collections.abc import Iterable
from dataclasses import dataclass

from companion.team.types import MEMBER_ID_MAX, STATION_ID, MemberEntry, TaskBoard

log = logging.getLogger(__name__)

#: sample intervals without hearing a row's owner after which another epoch may replace it
STALE_TICKS = 3


def new_epoch() -> int:
    """A boot epoch: a random non-zero 64-bit number (no storage needed on the companion; two boots
    draw the same one with a probability of 2^-64)."""
    return secrets.randbits(64) or 1


@dataclass(frozen=True)
class MergeResult:
    """What one :meth:`GroupState.merge` changed."""

    raised: int = 0                 #: vocs raised without a newer row (owner heard, or a higher report)
    joined: tuple[int, ...] = ()    #: members new to this state, back from gone, or rebooted
    ignored_own: int = 0            #: rows for this member sent by others (never taken)
    other_epoch: tuple[int, ...] = ()  #: members whose row of another epoch was refused (held one alive)
    #: (the row held before or None, the row taken) for each replacement, in the packet's order
    taken: tuple[tuple[MemberEntry | None, MemberEntry], ...] = ()

    @property
    def replaced(self) -> int:
        """Rows replaced by newer ones (or new rows)."""
        return len(self.taken)


class GroupState:
    """The group-state vector on member ``own`` (seed 003 Sec. III-A). Thread-safe; readers get
    snapshots (the rows are immutable)."""

    def __init__(self, own: int, *, voc_max: int = 10, epoch: int | None = None,
                 stale_ticks: int = STALE_TICKS) -> None:
        if not isinstance(own, int) or not 0 <= own <= MEMBER_ID_MAX:
            raise ValueError(f"own member id {own!r} outside 0..{MEMBER_ID_MAX}")
        if not isinstance(voc_max, int) or not 1 <= voc_max <= 255:
            raise ValueError(f"voc_max {voc_max!r} outside 1..255")
        if epoch is not None and (not isinstance(epoch, int) or not 1 <= epoch < (1 << 64)):
            raise ValueError(f"epoch {epoch!r} outside 1..2^64-1")
        if not 1 <= stale_ticks <= voc_max:
            raise ValueError(f"stale_ticks {stale_ticks!r} outside 1..voc_max")
        self._own = own
        self.epoch = new_epoch() if epoch is None else epoch
        self.voc_max = voc_max
        self.stale_ticks = stale_ticks
        self._rows: dict[int, MemberEntry] = {}
        self._heard: set[int] = set()   # owners heard (or refreshed, for own) since the last tick
        self._board = TaskBoard()
        self._lock = threading.RLock()

    @property
    def own_id(self) -> int:
        return self._own

    # --------------------------------------------------------------------------------------- writers

    def refresh_own(self, entry: MemberEntry) -> MemberEntry:
        """Replace the own row with ``entry`` (the owner only): its member must be ``own`` and its seq
        must advance past the current own row's. The stored row has this state's epoch and voc =
        ``voc_max``."""
        if entry.member != self._own:
            raise ValueError(f"refresh_own: row of member {entry.member}, this state is member {self._own}'s")
        with self._lock:
            cur = self._rows.get(self._own)
            if cur is not None and not entry.seq > cur.seq:
                raise ValueError(f"refresh_own: seq {entry.seq} does not advance past {cur.seq}")
            row = dataclasses.replace(entry, epoch=self.epoch, voc=self.voc_max)
            self._rows[self._own] = row
            self._heard.add(self._own)
            return row

    def merge(self, entries: Iterable[MemberEntry], *, sender: int | None = None) -> MergeResult:
        """Take the rows of a packet from ``sender`` (None: unknown) by the voc rules (module doc)."""
        raised = ignored = 0
        joined: list[int] = []
        other: list[int] = []
        taken: list[tuple[MemberEntry | None, MemberEntry]] = []
        with self._lock:
            for r in entries:
                if r.member == self._own:
                    ignored += 1
                    continue
                held = cur = self._rows.get(r.member)
                from_owner = sender is not None and r.member == sender
                if cur is not None and r.epoch != cur.epoch:
                    if not self._stale(cur):
                        other.append(r.member)  # the identity rule: the held epoch is alive
                        continue
                    cur = None  # a reboot: the old epoch has gone silent
                if cur is None or r.newer_than(cur):
                    voc = self.voc_max if from_owner else min(r.voc, self.voc_max)
                    if voc <= 0:
                        continue  # a relay's gone row tells nothing about the member being there
                    row = self._rows[r.member] = dataclasses.replace(r, voc=voc)
                    taken.append((held, row))
                    if cur is None or cur.voc == 0:
                        joined.append(r.member)
                    if from_owner:
                        self._heard.add(r.member)
                elif cur.voc > 0 and not cur.newer_than(r):  # the same row, alive here
                    voc = self.voc_max if from_owner else min(r.voc, self.voc_max)
                    if from_owner:
                        self._heard.add(r.member)
                    if voc > cur.voc:
                        self._rows[r.member] = dataclasses.replace(cur, voc=voc)
                        raised += 1
        return MergeResult(raised=raised, joined=tuple(joined), ignored_own=ignored,
                           other_epoch=tuple(other), taken=tuple(taken))

    def _stale(self, row: MemberEntry) -> bool:
        """The row's owner has not been heard for ``stale_ticks`` sample intervals (or it is gone)."""
        return row.voc <= self.voc_max - self.stale_ticks

    def stale(self, member: int) -> bool:
        """Is the row held for ``member`` stale or gone (True when none is held)?"""
        with self._lock:
            row = self._rows.get(member)
            return row is None or self._stale(row)

    def board_acceptable(self, epoch: int, seq: int) -> bool:
        """Would a board of the station's ``epoch`` and version ``seq`` replace the one held? Within the
        held board's epoch: a higher version; another epoch: once the station's row of that epoch is held
        (taken by the identity rule), or while no board of any epoch is held."""
        with self._lock:
            held = self._board
            if epoch == held.epoch:
                return seq > held.seq
            if held.epoch == 0 and held.seq == 0 and not held.tasks:
                return True
            station = self._rows.get(STATION_ID)
            return station is not None and station.epoch == epoch and station.voc > 0

    def merge_board(self, board: TaskBoard) -> bool:
        """Take ``board`` if :meth:`board_acceptable`; True when taken."""
        with self._lock:
            if self._own == STATION_ID or not self.board_acceptable(board.epoch, board.seq):
                return False
            self._board = board
            return True

    def set_board(self, board: TaskBoard) -> TaskBoard:
        """The station publishes a new board (the station only): stored with this state's epoch; its
        version must advance past the held one's (any version replaces a board of another epoch)."""
        if self._own != STATION_ID:
            raise PermissionError(f"set_board: only the team-control station (member {STATION_ID}) writes "
                                  f"the board; this is member {self._own}")
        with self._lock:
            if self._board.epoch == self.epoch and not board.seq > self._board.seq:
                raise ValueError(f"set_board: version {board.seq} does not advance past {self._board.seq}")
            self._board = dataclasses.replace(board, epoch=self.epoch)
            return self._board

    def tick(self) -> list[int]:
        """One sample interval: every other row whose owner was not heard since the last tick loses one
        voc; returns the members whose voc just reached zero (gone)."""
        gone = []
        with self._lock:
            for m, row in self._rows.items():
                if m == self._own or m in self._heard or row.voc == 0:
                    continue
                self._rows[m] = dataclasses.replace(row, voc=row.voc - 1)
                if row.voc == 1:
                    gone.append(m)
            self._heard.clear()
        if gone:
            log.info("member %d: members %s gone (voc ran out)", self._own, gone)
        return gone

    # --------------------------------------------------------------------------------------- readers

    def entries(self) -> dict[int, MemberEntry]:
        """Every row held, gone ones included (voc 0)."""
        with self._lock:
            return dict(self._rows)

    def alive(self) -> dict[int, MemberEntry]:
        """The rows with a voc above zero (the own row included)."""
        with self._lock:
            return {m: r for m, r in self._rows.items() if r.voc > 0}

    def gone(self) -> dict[int, MemberEntry]:
        with self._lock:
            return {m: r for m, r in self._rows.items() if r.voc == 0}

    def own(self) -> MemberEntry | None:
        with self._lock:
            return self._rows.get(self._own)

    def get(self, member: int) -> MemberEntry | None:
        with self._lock:
            return self._rows.get(member)

    @property
    def board(self) -> TaskBoard:
        with self._lock:
            return self._board

    def staleness(self, now: float) -> dict[int, float]:
        """``now - stamp`` of the row held for every other member (gone ones included)."""
        with self._lock:
            return {m: now - r.stamp for m, r in self._rows.items() if m != self._own}
