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
take a board only when newer by (stamp, seq) (:meth:`GroupState.merge_board`).
"""

from __future__ import annotations

import dataclasses
import logging
import threading
from collections.abc import Iterable
from dataclasses import dataclass

from companion.team.types import STATION_ID, MemberEntry, TaskBoard

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class MergeResult:
    """What one :meth:`GroupState.merge` changed."""

    replaced: int = 0               #: rows replaced by newer ones (or new rows)
    raised: int = 0                 #: vocs raised without a newer row (owner heard, or a higher report)
    joined: tuple[int, ...] = ()    #: members new to this state or back from gone
    ignored_own: int = 0            #: rows for this member sent by others (never taken)


class GroupState:
    """The group-state vector on member ``own`` (seed 003 Sec. III-A). Thread-safe; readers get
    snapshots (the rows are immutable)."""

    def __init__(self, own: int, *, voc_max: int = 10) -> None:
        if not isinstance(own, int) or not 0 <= own <= 255:
            raise ValueError(f"own member id {own!r} outside 0..255")
        if not isinstance(voc_max, int) or not 1 <= voc_max <= 255:
            raise ValueError(f"voc_max {voc_max!r} outside 1..255")
        self._own = own
        self.voc_max = voc_max
        self._rows: dict[int, MemberEntry] = {}
        self._heard: set[int] = set()   # owners heard (or refreshed, for own) since the last tick
        self._board = TaskBoard()
        self._lock = threading.Lock()

    @property
    def own_id(self) -> int:
        return self._own

    # --------------------------------------------------------------------------------------- writers

    def refresh_own(self, entry: MemberEntry) -> MemberEntry:
        """Replace the own row with ``entry`` (the owner only): its member must be ``own`` and it must
        be newer by (stamp, seq) than the current own row. The stored row has voc = ``voc_max``."""
        if entry.member != self._own:
            raise ValueError(f"refresh_own: row of member {entry.member}, this state is member {self._own}'s")
        with self._lock:
            cur = self._rows.get(self._own)
            if cur is not None and not entry.newer_than(cur):
                raise ValueError(f"refresh_own: (stamp, seq) ({entry.stamp}, {entry.seq}) does not advance "
                                 f"past ({cur.stamp}, {cur.seq})")
            row = dataclasses.replace(entry, voc=self.voc_max)
            self._rows[self._own] = row
            self._heard.add(self._own)
            return row

    def merge(self, entries: Iterable[MemberEntry], *, sender: int | None = None) -> MergeResult:
        """Take the rows of a packet from ``sender`` (None: unknown) by the voc rules (module doc)."""
        replaced = raised = ignored = 0
        joined: list[int] = []
        with self._lock:
            for r in entries:
                if r.member == self._own:
                    ignored += 1
                    continue
                cur = self._rows.get(r.member)
                from_owner = sender is not None and r.member == sender
                if cur is None or r.newer_than(cur):
                    voc = self.voc_max if from_owner else min(r.voc, self.voc_max)
                    if voc <= 0:
                        continue  # a relay's gone row tells nothing about the member being there
                    self._rows[r.member] = dataclasses.replace(r, voc=voc)
                    replaced += 1
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
        return MergeResult(replaced=replaced, raised=raised, joined=tuple(joined), ignored_own=ignored)

    def merge_board(self, board: TaskBoard) -> bool:
        """Take ``board`` if newer by (stamp, seq) than the one held; True when taken."""
        with self._lock:
            if not board.newer_than(self._board):
                return False
            self._board = board
            return True

    def set_board(self, board: TaskBoard) -> None:
        """The station publishes a new board (the station only; it must be newer by (stamp, seq))."""
        if self._own != STATION_ID:
            raise PermissionError(f"set_board: only the team-control station (member {STATION_ID}) writes "
                                  f"the board; this is member {self._own}")
        with self._lock:
            if not board.newer_than(self._board):
                raise ValueError(f"set_board: (stamp, seq) ({board.stamp}, {board.seq}) does not advance "
                                 f"past ({self._board.stamp}, {self._board.seq})")
            self._board = board

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
