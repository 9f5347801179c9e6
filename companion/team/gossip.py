"""Which rows a member's broadcast carries: controlled flooding that scales (seed 003 Sec. III-A).

Seed 003: "whenever a broadcast is made, the broadcaster's knowledge of other vehicles is broadcast along
with its knowledge of its own state". Sending every row known in every broadcast costs each vehicle O(N)
bytes a period, O(N^2) on the shared channel (100 vehicles: 6 kB a broadcast, 9.7 Mbit/s). Here each
broadcast carries the broadcaster's knowledge as a *digest* and only the rows someone needs:

* every period a member sends its own row, at most :attr:`Gossip.max_relays` rows of others (below) and
  a digest of :attr:`Gossip.digest_size` entries ``(member, epoch tag, seq, want)`` (in the STATE packet
  when it fits there, else a DIGEST packet of its own): first the rows it
  *wants* (members it never heard of that another's digest names; rows not refreshed here for
  ``stale_periods`` periods, or for ``far_stale_periods`` when the row last came over a relay, its owner
  out of reach), then a round-robin slice of the rows it holds (so that every row is named within
  N / digest_size periods: a member learns of rows it does not know);
* a member relays a row it holds when another's digest shows it is behind (a want, or a seq of the same
  epoch older by ``stale_periods`` periods: the owner advances its seq at least once a period; freshness
  is (epoch, seq), never a host clock, :mod:`.groupstate`); when the same member asks for that row again
  within ``interest_periods`` periods (a neighbour out of the owner's reach, not one that missed a packet), it
  relays each new version of the row it takes for ``interest_periods`` periods after the last ask (so the
  far member keeps getting it without asking each time), and once when the row is new here or its
  content changed (status, task, claims, name: what the allocation reads), so a change floods over
  relays at once;
* a relay queued is dropped when another member relays that row (as new) first: on a full mesh most
  requests are answered once (members broadcast at random phases of the period).

A packet therefore carries at most ``1 + max_relays`` rows and ``digest_size`` digest entries whatever N:
the traffic per vehicle and the decode-and-merge work per message do not grow with the team
(bench/bench_teamlink.py measures both, and the staleness this costs). Rows over several hops still
arrive: a member behind asks in its digest, a neighbour that holds the row sends it.
"""

from __future__ import annotations

from collections.abc import Iterable

from .groupstate import GroupState
from .types import MemberEntry
from .wire import DigestEntry

#: digest entries a member sends per period
DIGEST_SIZE = 10
#: the most digest entries one packet of :data:`~.wire.MAX_PACKET` bytes holds (13 bytes each)
MAX_DIGEST = 104
#: rows of other members a packet carries at most
MAX_RELAYS = 16
#: a row not refreshed for this many periods is asked for (a want in the digest) ...
STALE_PERIODS = 3.0
#: ... and a row that came over a relay (its owner out of reach) for this many
FAR_STALE_PERIODS = 1.0
#: a row asked for is relayed at each new version for this many periods after the last ask
INTEREST_PERIODS = 4.0


def _content(e: MemberEntry) -> tuple[object, ...]:
    """What the allocation reads of a row (its position changes every period and is not a change)."""
    return (e.status, e.task, e.claims, e.name)


def epoch_tag(epoch: int) -> int:
    """The 32 bits of a boot epoch a digest carries (never 0: 0 is "no row"); two epochs of one member share
    a tag with probability 2^-32, and then only a relay is missed or sent for nothing (rows carry the whole
    epoch: the merge never sees a tag)."""
    return (epoch & 0xFFFFFFFF) or 1


class Gossip:
    """One member's choice of rows to relay and digest to send (module docstring). Not thread-safe: the
    link calls it under its step lock."""

    def __init__(self, own_id: int, period_s: float, *, digest_size: int = DIGEST_SIZE,
                 max_relays: int = MAX_RELAYS, stale_periods: float = STALE_PERIODS,
                 far_stale_periods: float = FAR_STALE_PERIODS,
                 interest_periods: float = INTEREST_PERIODS) -> None:
        if digest_size < 1 or digest_size > MAX_DIGEST:
            raise ValueError(f"digest_size: must be in 1..{MAX_DIGEST}, got {digest_size}")
        if max_relays < 0:
            raise ValueError(f"max_relays: must be >= 0, got {max_relays}")
        self.own_id = own_id
        self.digest_size = digest_size
        self.max_relays = max_relays
        self.stale_s = stale_periods * period_s
        self.stale_seqs = max(1, round(stale_periods))
        self.far_stale_s = far_stale_periods * period_s
        self._far: set[int] = set()                    # members whose row last came over a relay
        self.interest_s = interest_periods * period_s
        self._interest: dict[int, float] = {}          # member -> until when a neighbour wants its rows
        self._asked: dict[tuple[int, int], float] = {}  # (member, asker) -> when it last asked
        self._now = 0.0
        self._updated: dict[int, float] = {}           # member -> local time its row last advanced here
        self._relay: dict[int, MemberEntry] = {}       # member -> the version queued (insertion order)
        self._unknown: set[int] = set()                # members another's digest names, unknown here
        self._cursor = 0
        self.relays_suppressed = 0

    # --- hearing --------------------------------------------------------------------------------------
    def heard_rows(self, rows: Iterable[MemberEntry], sender: int) -> None:
        """Rows in a packet from ``sender``: a relay of a row I queued, as new, makes mine needless."""
        for r in rows:
            if r.member == sender:
                continue
            q = self._relay.get(r.member)
            if q is not None and not q.newer_than(r):
                del self._relay[r.member]
                self.relays_suppressed += 1

    def taken(self, before: MemberEntry | None, row: MemberEntry, now: float, sender: int) -> None:
        """``row`` replaced ``before`` here (newer), heard from ``sender``: it is fresh; queued once when
        new or changed."""
        m = row.member
        self._updated[m] = now
        self._now = now
        if self._interest.get(m, -1.0) >= now:
            self._relay.setdefault(m, row)
        if sender == m:
            self._far.discard(m)
        else:
            self._far.add(m)
        self._unknown.discard(m)
        if before is None or before.voc == 0 or _content(before) != _content(row):
            self._relay.setdefault(m, row)

    def heard_digest(self, entries: Iterable[DigestEntry], sender: int, state: GroupState) -> None:
        """Another's digest: queue the rows it is behind on; note the members it knows and I do not."""
        for d in entries:
            m = d.member
            if m in (self.own_id, sender):
                continue
            cur = state.get(m)
            if cur is None or cur.voc == 0:
                if d.epoch and (cur is None or epoch_tag(cur.epoch) != d.epoch or d.seq > cur.seq):
                    self._unknown.add(m)
                continue
            if d.want:
                last = self._asked.get((m, sender))
                self._asked[(m, sender)] = self._now
                if last is not None and self._now - last <= self.interest_s:
                    self._interest[m] = self._now + self.interest_s
            if d.epoch != epoch_tag(cur.epoch):
                # another epoch (a reboot one of us has not seen yet): the asker decides by the identity
                # rule once it has the row
                if d.want:
                    self._relay.setdefault(m, cur)
            elif cur.seq > d.seq and (d.want or cur.seq - d.seq >= self.stale_seqs):
                self._relay.setdefault(m, cur)

    # --- sending --------------------------------------------------------------------------------------
    def relays(self, state: GroupState) -> list[MemberEntry]:
        """The rows of others to send now (at most ``max_relays``, the oldest requests first; each row as
        it is held now, alive only)."""
        out: list[MemberEntry] = []
        for m in list(self._relay):
            if len(out) >= self.max_relays:
                break
            del self._relay[m]
            cur = state.get(m)
            if cur is not None and cur.voc > 0 and m != self.own_id:
                out.append(cur)
        return out

    def digest(self, state: GroupState, now: float) -> list[DigestEntry]:
        """This period's digest: wants first (never heard, then the stalest rows), then the next slice of
        the rows held, round robin."""
        self._now = now
        if len(self._asked) > 4 * len(self._updated) + 64:  # forget old asks (bounded memory)
            self._asked = {k: t for k, t in self._asked.items() if now - t <= self.interest_s}
        alive = state.alive()
        out: list[DigestEntry] = [DigestEntry(m, 0, 0, True)
                                  for m in sorted(self._unknown)[:self.digest_size]]
        stale = sorted((self._updated.get(m, 0.0), m) for m in alive if m != self.own_id
                       and now - self._updated.get(m, 0.0) >= (self.far_stale_s if m in self._far
                                                               else self.stale_s))
        for _t, m in stale:
            if len(out) >= self.digest_size:
                return out
            e = alive[m]
            out.append(DigestEntry(m, epoch_tag(e.epoch), e.seq, True))
        named = {d.member for d in out}
        others = sorted(m for m in alive if m != self.own_id and m not in named)
        k = min(self.digest_size - len(out), len(others))
        for i in range(k):
            e = alive[others[(self._cursor + i) % len(others)]]
            out.append(DigestEntry(e.member, epoch_tag(e.epoch), e.seq, False))
        if others:
            self._cursor = (self._cursor + k) % len(others)
        return out
