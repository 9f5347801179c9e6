"""The team link (seed 003 Sec. III-A, "Orinoco"): periodic broadcast of the group state.

"Communication is achieved by the periodic broadcasting of group-level state information from each
vehicle ... whenever a broadcast is made, the broadcaster's knowledge of other vehicles is broadcast
along with its knowledge of its own state" (controlled flooding). :class:`TeamLink` ties a
:class:`~companion.team.groupstate.GroupState` to a :class:`~companion.team.transport.Transport`:

* :meth:`TeamLink.step` takes every pending packet (non-blocking), decodes it and merges its rows
  (garbage and foreign versions counted, never raised; its own echoes dropped by sender id); once a
  period has passed since the last broadcast it refreshes the own row (the content from ``own()``,
  stamped ``now`` with the next sequence number: the owner's (stamp, seq) always advances), ticks the
  votes of confidence (one sample interval per period) and broadcasts its own row, the rows others need
  and a digest of what it knows (:mod:`companion.team.gossip`: a packet's rows and digest entries are
  bounded whatever the team's size); ``selection="full"`` sends every alive row it knows instead (seed
  003's plain flooding, O(N^2) on the channel, kept for comparison in the bench).
* The task board floods too: the station (member 0) sends it with every broadcast, members relay it
  with every ``relay_board_every``-th broadcast and with the first one after they learned a newer
  board, so it spreads in about one period per hop while the bandwidth stays low.
* :meth:`TeamLink.start` runs the steps in a daemon thread; ``listeners`` are told when a member is
  gone, joins (new, back from gone, or rebooted), the board changes, a duplicate id is heard, or this
  link refuses to join.

Identity and authentication (:mod:`.auth`, :mod:`.groupstate`). Each packet names its sender's id and
boot epoch: a packet with this member's id and epoch is its own echo (multicast loopback); with this
member's id and *another* epoch it comes from another process using the same id. Of two such members
the one whose row has been published longer (the higher (seq, epoch) of its own row) keeps the id; the
other *refuses to join*: it stops publishing its row (it sends only an empty beacon in its epoch, so that
the duplicate stays visible to all), publishes no claims (:class:`~.member.TeamMember`), says
so in its log, its status (``refused``) and a "refused" event, and never comes back by itself (restart it
with another id). The others keep the first one's row (the identity rule) and report the duplicate
("duplicate" event). With a key every packet must be signed; unsigned, forged, replayed packets and
packets stamped more than 30 s ahead of the team's clock (:class:`~.auth.ReplayGuard`: this clock, or
the majority's when it is ahead) are dropped and counted (:class:`LinkStats`), as are
rows and boards stamped that far ahead.

The default period, 0.5 s, meets both targets of the bench (bench/bench_teamlink.py, 20 vehicles and a
station, 20 % loss) with margin: p95 age of each member's view of every other 0.5 s on a full mesh and
1.5 s when a 700 m radio range makes rows travel over relays (each hop adds up to a period), at
2.7 kB/s per vehicle (a 21-row packet of ~1.3 kB twice a second, the board every 4th). A 1 s period
halves the bandwidth but its multi-hop p95 age is 3 s, and it doubles the time to declare a dead
vehicle gone (``voc_max`` periods: 5 s at 0.5 s); 0.25 s would cost 5.4 kB/s, over the bound.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

from companion.team.auth import FUTURE_WINDOW_S, ReplayGuard
from companion.team.decode_once import decode_shared
from companion.team.gossip import Gossip
from companion.team.groupstate import GroupState
from companion.team.transport import Transport
from companion.team.types import STATION_ID, MemberEntry, TaskBoard
from companion.team.wire import (
    MAX_PACKET,
    BadSignatureError,
    BoardAssembler,
    ForeignVersionError,
    Packet,
    UnsignedError,
    UnverifiableError,
    WireError,
    encode_packets,
)

log = logging.getLogger(__name__)

DEFAULT_PERIOD_S = 0.5


@dataclass
class LinkStats:
    """Counters of one :class:`TeamLink`."""

    packets_sent: int = 0
    bytes_sent: int = 0
    packets_received: int = 0
    bytes_received: int = 0
    garbage: int = 0              #: undecodable packets (bad magic, CRC, truncation ...)
    foreign_version: int = 0      #: team-link packets of another format version
    own_echoes: int = 0           #: own packets heard back (multicast loopback), ignored
    unsigned: int = 0             #: unsigned packets dropped (a key is configured)
    bad_signature: int = 0        #: signed packets whose signature did not match (forged or modified)
    unverifiable: int = 0         #: signed packets dropped because this link has no key
    replayed: int = 0             #: packets whose number was already taken (or too old) for their sender
    future: int = 0               #: packets, rows or boards stamped too far ahead of this clock
    duplicates: int = 0           #: packets from another process with this link's id (another epoch)
    other_epoch: int = 0          #: rows of another epoch refused because the held one is alive
    rows_replaced: int = 0        #: rows taken because newer (or new)
    vocs_raised: int = 0
    boards_taken: int = 0
    send_errors: int = 0
    broadcasts: int = 0
    announcements: int = 0        #: broadcasts between periods (a member announcing new claims)
    rows_relayed: int = 0         #: rows of others sent (asked for in a digest, new or changed)
    digests: int = 0              #: digests received (in a STATE packet or a DIGEST one)
    digests_sent: int = 0         #: digests sent
    first_send: float | None = None
    last_send: float | None = None
    max_packet: int = 0


def link_drops(link: TeamLink) -> dict[str, int]:
    """The counters of what a link dropped for identity, authentication and time (for status reports)."""
    st = link.stats
    return {"own_echoes": st.own_echoes, "unsigned": st.unsigned, "bad_signature": st.bad_signature,
            "unverifiable": st.unverifiable, "replayed": st.replayed, "future": st.future,
            "duplicates": st.duplicates, "other_epoch": st.other_epoch}


@dataclass(frozen=True)
class LinkEvent:
    """What a listener is told: ``kind`` is "gone", "joined", "duplicate" (with ``member``), "board", or
    "refused" (this link refuses to join: ``reason``)."""

    kind: str
    member: int | None = None
    board: TaskBoard | None = None
    reason: str = ""


class TeamLink:
    """One member's team link (module doc). ``own`` returns the own row's content (position, velocity,
    status, task, claims, name; member, stamp, seq and voc are set here), or None to leave the row
    as it is; without ``own`` the current own row (set by the caller with ``state.refresh_own``) is
    re-stamped every period so it stays fresh. ``key``: the team key (:mod:`.auth`; None: unsigned
    packets, and signed ones are dropped). ``future_s``: how far ahead of ``clock`` a stamp may be."""

    def __init__(self, state: GroupState, transport: Transport, *, period_s: float = DEFAULT_PERIOD_S,
                 clock: Callable[[], float] = time.time, own: Callable[[], MemberEntry | None] | None = None,
                 relay_board_every: int = 4, max_packet: int = MAX_PACKET, key: bytes | None = None,
                 future_s: float = FUTURE_WINDOW_S, selection: str = "digest",
                 gossip: Gossip | None = None) -> None:
        if not period_s > 0:
            raise ValueError(f"TeamLink: period_s {period_s!r} must be positive")
        if relay_board_every < 1:
            raise ValueError(f"TeamLink: relay_board_every {relay_board_every!r} must be at least 1")
        self.state, self.transport = state, transport
        self.period_s, self.clock, self._own_fn = period_s, clock, own
        self.relay_board_every, self.max_packet = relay_board_every, max_packet
        if selection not in ("digest", "full"):
            raise ValueError(f"TeamLink: selection {selection!r} is not 'digest' or 'full'")
        self.selection = selection
        self.gossip = gossip or Gossip(state.own_id, period_s)
        self.stats = LinkStats()
        self.key = key
        self.future_s = future_s
        self.refused: str | None = None   #: why this link refuses to join (a duplicate id); None: it joins
        self._guard = ReplayGuard(future_s=future_s)
        self._pseq = 0
        self._reported: set[tuple[int, int]] = set()   # (member, epoch) duplicates already reported
        self._warned: set[str] = set()
        self.listeners: list[Callable[[LinkEvent], None]] = []
        self._assembler = BoardAssembler()
        self._last_send: float | None = None
        self._board_news = False
        self._step_lock = threading.RLock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def own_id(self) -> int:
        return self.state.own_id

    @property
    def epoch(self) -> int:
        return self.state.epoch

    # ------------------------------------------------------------------------------------- receiving

    def handle(self, data: bytes) -> None:
        """Take one received datagram (counted; garbage, foreign versions, unsigned, forged, replayed and
        future packets never raise)."""
        events: list[LinkEvent] = []
        with self._step_lock:
            self._handle(data, events)
        self._notify(events)

    def _handle(self, data: bytes, events: list[LinkEvent]) -> None:
        """:meth:`handle` under the step lock; what listeners must be told goes into ``events``."""
        self.stats.packets_received += 1
        self.stats.bytes_received += len(data)
        pkt = self._decode(data)
        if pkt is None:
            return
        now = self.clock()
        verdict = self._guard.check(pkt.sender, pkt.epoch, pkt.pseq, pkt.stamp, now,
                                    replay=self.key is not None, voice=pkt.sender != self.own_id)
        if verdict == "future":
            self._count_future("packet", pkt.sender, pkt.stamp, now)
            return
        if verdict == "replayed":
            self.stats.replayed += 1
            log.debug("member %d: replayed packet from %d dropped", self.own_id, pkt.sender)
            return
        if pkt.sender == self.own_id:
            if pkt.epoch == self.epoch:
                self.stats.own_echoes += 1
            else:
                events.extend(self._duplicate_of_self(pkt))
            return
        self._watch_duplicates(pkt, events)
        if pkt.digest:
            self.stats.digests += 1
            self.gossip.heard_digest(pkt.digest, pkt.sender, self.state)
        if pkt.rows:
            rows = []
            for r in pkt.rows:
                if self._guard.future(r.stamp, now):
                    self._count_future("row", r.member, r.stamp, now)
                else:
                    rows.append(r)
            self.gossip.heard_rows(rows, pkt.sender)
            res = self.state.merge(rows, sender=pkt.sender)
            for old, row in res.taken:
                self.gossip.taken(old, row, now, pkt.sender)
            self.stats.rows_replaced += res.replaced
            self.stats.vocs_raised += res.raised
            self.stats.other_epoch += len(res.other_epoch)
            events += [LinkEvent("joined", member=m) for m in res.joined]
        part = pkt.board_part
        if part is not None:
            if self._guard.future(part.stamp, now):
                self._count_future("board", STATION_ID, part.stamp, now)
            elif self.own_id != STATION_ID and self.state.board_acceptable(part.epoch, part.seq):
                try:
                    board = self._assembler.add(part)
                except WireError as exc:
                    self.stats.garbage += 1
                    log.debug("member %d: bad board dropped: %s", self.own_id, exc)
                    board = None
                if board is not None and self.state.merge_board(board):
                    self.stats.boards_taken += 1
                    self._board_news = True
                    events.append(LinkEvent("board", board=board))

    def _decode(self, data: bytes) -> Packet | None:
        try:
            return decode_shared(data, self.key)
        except ForeignVersionError:
            self.stats.foreign_version += 1
        except UnsignedError:
            self.stats.unsigned += 1
            self._warn_once("unsigned", "unsigned team-link packets heard and dropped (this link has a key)")
        except BadSignatureError:
            self.stats.bad_signature += 1
            self._warn_once("forged", "team-link packets with a bad signature heard and dropped (forged, "
                                      "modified or another key)")
        except UnverifiableError:
            self.stats.unverifiable += 1
            self._warn_once("unverifiable", "signed team-link packets heard and dropped: this link has no "
                                            "key (give --team-key FILE)")
        except WireError as exc:
            self.stats.garbage += 1
            log.debug("member %d: garbage packet dropped: %s", self.own_id, exc)
        return None

    def _warn_once(self, what: str, text: str) -> None:
        if what not in self._warned:
            self._warned.add(what)
            log.warning("member %d: %s", self.own_id, text)

    def _count_future(self, what: str, member: int, stamp: float, now: float) -> None:
        self.stats.future += 1
        self._warn_once(f"future-{what}", f"a {what} of member {member} stamped {stamp - now:.0f} s ahead of "
                                          f"this clock dropped (more than {self.future_s:.0f} s: a clock "
                                          "far ahead, or a forgery)")

    def _duplicate_of_self(self, pkt: Packet) -> list[LinkEvent]:
        """A packet with this link's id from another epoch: another process uses the id. The one whose row
        was published longer keeps it; this link refuses if it is the other one."""
        self.stats.duplicates += 1
        if self.refused is not None:
            return []
        theirs = next((r for r in pkt.rows if r.member == pkt.sender and r.epoch == pkt.epoch), None)
        if theirs is None:
            return []  # a board packet: wait for its row
        mine = self.state.own()
        if mine is not None and (mine.seq, self.epoch) > (theirs.seq, pkt.epoch):
            if (pkt.sender, pkt.epoch) not in self._reported:
                self._reported.add((pkt.sender, pkt.epoch))
                log.error("member %d: duplicate id %d: another member (epoch %016x) uses this id; it started "
                          "later and should refuse to join", self.own_id, self.own_id, pkt.epoch)
                return [LinkEvent("duplicate", member=pkt.sender)]
            return []
        self.refused = (f"duplicate id {self.own_id}: another member (epoch {pkt.epoch:016x}, "
                        f"{theirs.name!r}) has used this id longer; give this vehicle another id")
        log.error("member %d: refuses to join the team: %s", self.own_id, self.refused)
        return [LinkEvent("refused", member=self.own_id, reason=self.refused)]

    def _watch_duplicates(self, pkt: Packet, events: list[LinkEvent]) -> None:
        """A packet from a member whose held row (of another epoch) is alive and fresh: two processes use
        one id; reported once per (member, epoch)."""
        held = self.state.get(pkt.sender)
        if held is None or held.epoch == pkt.epoch or self.state.stale(pkt.sender):
            return
        if (pkt.sender, pkt.epoch) in self._reported:
            return
        self._reported.add((pkt.sender, pkt.epoch))
        log.warning("member %d: duplicate id %d: heard from epoch %016x while epoch %016x is alive; keeping "
                    "the first", self.own_id, pkt.sender, pkt.epoch, held.epoch)
        events.append(LinkEvent("duplicate", member=pkt.sender))

    def _notify(self, events: list[LinkEvent]) -> None:
        for ev in events:
            for fn in list(self.listeners):
                try:
                    fn(ev)
                except Exception:
                    log.exception("member %d: team-link listener %r failed on %s", self.own_id, fn, ev)

    # ------------------------------------------------------------------------------------- stepping

    def step(self, now: float | None = None) -> bool:
        """Receive all pending packets, then broadcast if a period has passed; True when it broadcast."""
        now = self.clock() if now is None else now
        while True:
            data = self.transport.recv(0.0)
            if data is None:
                break
            self.handle(data)
        with self._step_lock:
            if self._last_send is not None and now - self._last_send < self.period_s:
                return False
            self._last_send = now
            if self.refused is None:
                self._refresh_own(now)
            gone = self.state.tick()
            if self.refused is None:
                self._broadcast(now, periodic=True)
            else:
                self._beacon(now)
        self._notify([LinkEvent("gone", member=m) for m in gone])
        return True

    def announce(self, now: float | None = None) -> None:
        """Broadcast the own row now, between periods (seed 003 Sec. III-B: a vehicle "selects the task ...
        and then broadcasts its selection"); the vocs are not aged (that is the periodic step's job)."""
        now = self.clock() if now is None else now
        with self._step_lock:
            if self.refused is not None:
                return
            self._refresh_own(now)
            self._broadcast(now)
        self.stats.announcements += 1

    def _refresh_own(self, now: float) -> None:
        cur = self.state.own()
        if self._own_fn is not None:
            content = self._own_fn()
            if content is None:
                return
        elif cur is not None:
            content = cur
        else:
            return
        seq = cur.seq + 1 if cur is not None else max(content.seq, 0)
        stamp = now  # shown, never ordered on: (epoch, seq) orders rows
        self.state.refresh_own(dataclasses.replace(content, member=self.own_id, stamp=stamp, seq=seq))

    def _beacon(self, now: float) -> None:
        """A refused link sends no row, only an empty packet in its own epoch each period: whoever holds the
        first's row hears the duplicate id (a refusal decided before this link ever spoke stays visible)."""
        self._send(encode_packets(self.own_id, [], None, max_size=self.max_packet, epoch=self.epoch,
                                  stamp=now, pseq=self._pseq, key=self.key), now)

    def _select(self, periodic: bool) -> list[MemberEntry]:
        """The rows this broadcast carries, own row first: every alive one (``full``), or the own row and
        the relays the gossip picks (an announcement between periods: the own row only)."""
        if self.selection == "full":
            return sorted(self.state.alive().values(), key=lambda e: e.member != self.own_id)
        own = self.state.own()
        rows = [own] if own is not None else []
        if periodic:
            relays = self.gossip.relays(self.state)
            self.stats.rows_relayed += len(relays)
            rows += relays
        return rows

    def _broadcast(self, now: float, periodic: bool = False) -> None:
        rows = self._select(periodic)
        if not rows:
            return
        board = self.state.board
        send_board = bool(board.tasks) or board.seq > 0 or board.stamp > 0 or board.epoch != 0
        if send_board and self.own_id != STATION_ID:
            send_board = self._board_news or self.stats.broadcasts % self.relay_board_every == 0
        digest = self.gossip.digest(self.state, now) if periodic and self.selection == "digest" else []
        try:
            packets = encode_packets(self.own_id, rows, board if send_board else None,
                                     max_size=self.max_packet, epoch=self.epoch, stamp=now,
                                     pseq=self._pseq, key=self.key, digest=digest)
        except WireError as exc:
            log.error("member %d: group state not encodable, not sent: %s", self.own_id, exc)
            self.stats.send_errors += 1
            return
        if send_board:
            self._board_news = False
        if digest:
            self.stats.digests_sent += 1
        self._send(packets, now)

    def _send(self, packets: list[bytes], now: float) -> None:
        self._pseq = (self._pseq + len(packets)) & 0xFFFFFFFF
        self.stats.broadcasts += 1
        if self.stats.first_send is None:
            self.stats.first_send = now
        self.stats.last_send = now
        for p in packets:
            try:
                self.transport.send(p)
            except OSError as exc:
                self.stats.send_errors += 1
                log.warning("member %d: team-link send failed: %s", self.own_id, exc)
                continue
            self.stats.packets_sent += 1
            self.stats.bytes_sent += len(p)
            self.stats.max_packet = max(self.stats.max_packet, len(p))

    # ------------------------------------------------------------------------------------- threading

    def start(self) -> None:
        """Run the link in a daemon thread: it broadcasts every period. A transport that pushes its datagrams
        (:meth:`Transport.subscribe`: UDP, whose one receive thread per process serves all the process's
        members) hands each to :meth:`handle` as it arrives and the thread only wakes to broadcast; from
        any other the thread receives too, with period/10 timeouts."""
        if self._thread is not None:
            raise RuntimeError("TeamLink already started")
        self._stop.clear()
        pushed = self.transport.subscribe(self.handle)
        self._thread = threading.Thread(target=self._run_pushed if pushed else self._run,
                                        name=f"team-link-{self.own_id}", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        timeout = self.period_s / 10.0
        while not self._stop.is_set():
            try:
                data = self.transport.recv(timeout)
                if data is not None:
                    self.handle(data)
                self.step(self.clock())
            except Exception:  # the link must outlive any single bad step
                log.exception("member %d: team-link step failed", self.own_id)
                self._stop.wait(timeout)

    def _run_pushed(self) -> None:
        while not self._stop.is_set():
            try:
                now = self.clock()
                self.step(now)
                with self._step_lock:
                    last = self._last_send
                wait = self.period_s if last is None else self.period_s - (self.clock() - last)
            except Exception:  # the link must outlive any single bad step
                log.exception("member %d: team-link step failed", self.own_id)
                wait = self.period_s / 10.0
            self._stop.wait(min(max(wait, 0.001), self.period_s))

    def close(self) -> None:
        """Stop the thread (if started) and close the transport."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        self.transport.close()
