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
  gone, joins (new, or back from gone), or the board changes.

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

from companion.team.gossip import Gossip
from companion.team.groupstate import GroupState
from companion.team.transport import Transport
from companion.team.types import STATION_ID, MemberEntry, TaskBoard
from companion.team.wire import (
    MAX_PACKET,
    BoardAssembler,
    ForeignVersionError,
    WireError,
    decode_packet,
    encode_digest,
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
    rows_replaced: int = 0        #: rows taken because newer (or new)
    vocs_raised: int = 0
    boards_taken: int = 0
    send_errors: int = 0
    broadcasts: int = 0
    announcements: int = 0        #: broadcasts between periods (a member announcing new claims)
    rows_relayed: int = 0         #: rows of others sent (asked for in a digest, new or changed)
    digests: int = 0              #: DIGEST packets received
    digests_sent: int = 0         #: DIGEST packets sent
    first_send: float | None = None
    last_send: float | None = None
    max_packet: int = 0


@dataclass(frozen=True)
class LinkEvent:
    """What a listener is told: ``kind`` is "gone", "joined" (with ``member``) or "board"."""

    kind: str
    member: int | None = None
    board: TaskBoard | None = None


class TeamLink:
    """One member's team link (module doc). ``own`` returns the own row's content (position, velocity,
    status, task, claims, name; member, stamp, seq and voc are set here), or None to leave the row
    as it is; without ``own`` the current own row (set by the caller with ``state.refresh_own``) is
    re-stamped every period so it stays fresh."""

    def __init__(self, state: GroupState, transport: Transport, *, period_s: float = DEFAULT_PERIOD_S,
                 clock: Callable[[], float] = time.time, own: Callable[[], MemberEntry | None] | None = None,
                 relay_board_every: int = 4, max_packet: int = MAX_PACKET, selection: str = "digest",
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

    # ------------------------------------------------------------------------------------- receiving

    def handle(self, data: bytes) -> None:
        """Take one received datagram (counted; garbage and foreign versions never raise)."""
        with self._step_lock:
            self.stats.packets_received += 1
            self.stats.bytes_received += len(data)
            try:
                pkt = decode_packet(data)
            except ForeignVersionError:
                self.stats.foreign_version += 1
                return
            except WireError as exc:
                self.stats.garbage += 1
                log.debug("member %d: garbage packet dropped: %s", self.own_id, exc)
                return
            if pkt.sender == self.own_id:
                self.stats.own_echoes += 1
                return
            events: list[LinkEvent] = []
            if pkt.digest:
                self.stats.digests += 1
                self.gossip.heard_digest(pkt.digest, pkt.sender, self.state)
            if pkt.rows:
                self.gossip.heard_rows(pkt.rows, pkt.sender)
                before = {r.member: self.state.get(r.member) for r in pkt.rows}
                res = self.state.merge(pkt.rows, sender=pkt.sender)
                now = self.clock()
                for m, old in before.items():
                    row = self.state.get(m)
                    if row is not None and row is not old and (old is None or row.newer_than(old)):
                        self.gossip.taken(old, row, now, pkt.sender)
                self.stats.rows_replaced += res.replaced
                self.stats.vocs_raised += res.raised
                events += [LinkEvent("joined", member=m) for m in res.joined]
            part = pkt.board_part
            if part is not None:
                held = self.state.board
                if (part.stamp, part.seq) > (held.stamp, held.seq):
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
        self._notify(events)

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
            self._refresh_own(now)
            gone = self.state.tick()
            self._broadcast(now, periodic=True)
        self._notify([LinkEvent("gone", member=m) for m in gone])
        return True

    def announce(self, now: float | None = None) -> None:
        """Broadcast the own row now, between periods (seed 003 Sec. III-B: a vehicle "selects the task ...
        and then broadcasts its selection"); the vocs are not aged (that is the periodic step's job)."""
        now = self.clock() if now is None else now
        with self._step_lock:
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
        stamp = max(now, cur.stamp) if cur is not None else now
        self.state.refresh_own(dataclasses.replace(content, member=self.own_id, stamp=stamp, seq=seq))

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
        send_board = bool(board.tasks) or board.seq > 0 or board.stamp > 0
        if send_board and self.own_id != STATION_ID:
            send_board = self._board_news or self.stats.broadcasts % self.relay_board_every == 0
        try:
            packets = encode_packets(self.own_id, rows, board if send_board else None,
                                     max_size=self.max_packet)
        except WireError as exc:
            log.error("member %d: group state not encodable, not sent: %s", self.own_id, exc)
            self.stats.send_errors += 1
            return
        if send_board:
            self._board_news = False
        if periodic and self.selection == "digest":
            digest = self.gossip.digest(self.state, now)
            if digest:
                packets.append(encode_digest(self.own_id, digest))
                self.stats.digests_sent += 1
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
        """Run the link in a daemon thread (receive with period/10 timeouts, broadcast every period)."""
        if self._thread is not None:
            raise RuntimeError("TeamLink already started")
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name=f"team-link-{self.own_id}", daemon=True)
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

    def close(self) -> None:
        """Stop the thread (if started) and close the transport."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        self.transport.close()
