"""Bench: the team link at scale: bandwidth, staleness, merge cost and airtime (seed 003 Sec. III-A).

``--members`` vehicles (20, 50 and 100 by default) and a team-control station (member 0, publishing a
nine-task board) on one in-process :class:`~companion.team.transport.MemoryBus`, each receiving through its
own seeded :class:`~companion.team.transport.LossyTransport`, run by :class:`~companion.team.link.TeamLink`
in simulated time (``--seconds`` of it, stepped every 50 ms; no sleeping). Each member starts at a random
phase of the period; the vehicles fly slowly (2-5 m/s) in random directions in a 2 x 2 km square (turning
back at its edges) and each holds one claim, so a row carries a position, a velocity and a claim as in
flight. The link selects the rows of each broadcast with :mod:`companion.team.gossip` (own row, rows others
need, a bounded digest); "full" is seed 003's plain flooding (every row in every broadcast), for comparison.

Figures, after a 10 s warm-up, sampled every 0.5 s:

* staleness: for every vehicle, ``now - stamp`` of the row it holds for every other vehicle, p50, p95 and
  max over all pairs and samples;
* bytes per second sent per vehicle (UDP payload: what the bus carries), packets per second, the largest
  packet; merge cost: the mean CPU time (the thread's, so other processes' load does not count) of
  :meth:`TeamLink.handle` (decode and merge) per received packet;
* airtime: 802.11 broadcast at the basic rate (``--rate``, 6 Mbit/s; no acknowledgement, no retry): each
  packet takes a 20 us OFDM preamble plus (payload + 28 bytes of IP/UDP + 36 bytes of 802.11 MAC header,
  LLC/SNAP and FCS) * 8 / rate; the channel occupancy is the sum over the team of those times per second
  (100 % is a saturated channel; contention and backoff come on top);
* gone events: a live vehicle whose voc ran out at some member.

Packets are format 2 and signed with a team key (HMAC-SHA256, 16-byte trailer; the receiver checks the
signature and the replay window, in the merge cost), as ``taskflight up`` runs a fleet; ``--unsigned``
measures the CRC trailer and no check.

Full flooding at 50 and 100 vehicles is not simulated (every member decodes every row of every packet: too
slow here); its bytes are the encoder's for a broadcast of every row, the figure that matters on air.
Target (issue): at 100 members <= 1 kB/s per vehicle on average on the bus.
"""

from __future__ import annotations

import argparse
import hashlib
import math
import random
import sys
import time
from dataclasses import dataclass

from bench.common import machine, pct, table
from companion.team.groupstate import GroupState
from companion.team.link import DEFAULT_PERIOD_S, LinkEvent, TeamLink
from companion.team.transport import LossyTransport, MemoryBus
from companion.team.types import (
    STATION_ID,
    Claim,
    MemberEntry,
    MemberStatus,
    TaskBoard,
    TaskKind,
    TeamTask,
)
from companion.team.wire import encode_packets

DT = 0.05
#: the bench team's key: packets signed as ``taskflight up`` runs a fleet (``--unsigned``: none)
KEY = hashlib.sha256(b"bench_teamlink").digest()
WARMUP_S = 10.0
SAMPLE_S = 0.5
UDP_IP_HEADERS = 28
ORIGIN = (58.39, 15.57)
M_PER_DEG = 111_320.0
HALF_SIDE_M = 1000.0  #: the vehicles fly in a 2 x 2 km square
PREAMBLE_S = 20e-6  #: 802.11a/g OFDM preamble and PLCP header
MAC_BYTES = 36  #: 802.11 data frame overhead: MAC header 24, LLC/SNAP 8, FCS 4


@dataclass
class Result:
    members: int
    selection: str
    loss: float
    period: float
    range_m: float | None
    p50: float
    p95: float
    max: float
    bytes_per_s: float
    air_bytes_per_s: float
    packets_per_s: float
    max_packet: int
    false_gone: int
    merge_us: float
    occupancy: float  #: % of the channel's time at ``rate`` (the whole team)


def airtime_s(payload: int, rate: float) -> float:
    """Seconds one broadcast packet of ``payload`` UDP bytes takes on 802.11 at ``rate`` bit/s."""
    return PREAMBLE_S + (payload + UDP_IP_HEADERS + MAC_BYTES) * 8 / rate


class Vehicle:
    """A slowly flying vehicle: its own row's content for the link."""

    def __init__(self, member: int, rng: random.Random) -> None:
        self.member = member
        self.n, self.e = rng.uniform(-HALF_SIDE_M, HALF_SIDE_M), rng.uniform(-HALF_SIDE_M, HALF_SIDE_M)
        speed, heading = rng.uniform(2.0, 5.0), rng.uniform(0, 2 * math.pi)
        self.vn, self.ve = speed * math.cos(heading), speed * math.sin(heading)
        self.claim = Claim(task=member % 9 + 1, version=1, cost=rng.uniform(50, 900))

    def move(self, dt: float) -> None:
        self.n += self.vn * dt
        self.e += self.ve * dt
        if abs(self.n) > HALF_SIDE_M:  # turn back at the edge of the area: the team stays together
            self.vn = -self.vn
        if abs(self.e) > HALF_SIDE_M:
            self.ve = -self.ve

    def entry(self) -> MemberEntry:
        lat = ORIGIN[0] + self.n / M_PER_DEG
        lon = ORIGIN[1] + self.e / (M_PER_DEG * math.cos(math.radians(ORIGIN[0])))
        return MemberEntry(member=self.member, stamp=0.0, seq=0, position=(lat, lon, 30.0),
                           velocity=(self.vn, self.ve, 0.0), status=MemberStatus.BUSY, task=self.claim.task,
                           claims=(self.claim,), name=f"uav-{self.member:02d}")


def board(stamp: float) -> TaskBoard:
    kinds = [TaskKind.VISIT, TaskKind.PATROL_LINE, TaskKind.BORDER_PIECE, TaskKind.AREA_PART]
    tasks = []
    for j in range(1, 10):
        kind = kinds[j % 4]
        npts = {TaskKind.VISIT: 1, TaskKind.PATROL_LINE: 4, TaskKind.BORDER_PIECE: 5,
                TaskKind.AREA_PART: 6}[kind]
        pts = tuple((ORIGIN[0] + j * 1e-3 + k * 2e-4, ORIGIN[1] - k * 3e-4, 0.0) for k in range(npts))
        tasks.append(TeamTask(id=j, version=1, kind=kind, points=pts, altitude=30.0, name=f"task {j}"))
    return TaskBoard(stamp=stamp, seq=1, tasks=tuple(tasks))


def run(members: int, loss: float, period: float, seconds: float, seed: int,
        range_m: float | None = None, selection: str = "digest", rate: float = 6e6,
        key: bytes | None = KEY) -> Result:
    rng = random.Random(seed)
    bus = MemoryBus()
    t = 0.0
    vehicles = {m: Vehicle(m, rng) for m in range(1, members + 1)}
    links: dict[int, TeamLink] = {}
    false_gone = 0

    def position_of(m: int) -> tuple[float, float, float] | None:
        return vehicles[m].entry().position if m in vehicles else (*ORIGIN, 0.0)

    def on_event(ev: LinkEvent) -> None:
        nonlocal false_gone
        if ev.kind == "gone":
            false_gone += 1

    for m in [STATION_ID, *vehicles]:
        tr = LossyTransport(bus.attach(), loss, seed=seed * 1000 + m, range_m=range_m,
                            position_of=position_of, member=m)
        own = (vehicles[m].entry if m in vehicles else
               (lambda: MemberEntry(member=STATION_ID, stamp=0.0, seq=0, position=(*ORIGIN, 0.0),
                                    status=MemberStatus.STATION, name="station")))
        links[m] = TeamLink(GroupState(m), tr, period_s=period, clock=lambda: t, own=own, selection=selection,
                            key=key)
        links[m].listeners.append(on_event)
    merge = [0.0, 0]
    airtime = [0.0]
    for link in links.values():
        def timed(data: bytes, handle=link.handle) -> None:
            t0 = time.thread_time()
            handle(data)
            merge[0] += time.thread_time() - t0
            merge[1] += 1
        link.handle = timed  # type: ignore[method-assign]
        send = link.transport.send

        def sent(data: bytes, send=send) -> None:
            airtime[0] += airtime_s(len(data), rate)
            send(data)
        link.transport.send = sent  # type: ignore[method-assign]
    start = {m: rng.uniform(0.0, period) for m in links}
    links[STATION_ID].state.set_board(board(0.0))
    ages: list[float] = []
    next_sample = WARMUP_S
    steps = round(seconds / DT)
    for i in range(1, steps + 1):
        t = i * DT
        for v in vehicles.values():
            v.move(DT)
        for m, link in links.items():
            if t >= start[m]:
                link.step(t)
        if t >= next_sample - 1e-9:
            next_sample += SAMPLE_S
            for m in vehicles:
                st = links[m].state.staleness(t)
                ages += [a for o, a in st.items() if o != STATION_ID]
    sent = [links[m].stats for m in vehicles]
    span = seconds - max(start.values())
    return Result(members=members, selection=selection, loss=loss, period=period, range_m=range_m,
                  p50=pct(ages, 0.5), p95=pct(ages, 0.95),
                  max=max(ages),
                  bytes_per_s=sum(s.bytes_sent for s in sent) / len(sent) / span,
                  air_bytes_per_s=sum(s.bytes_sent + UDP_IP_HEADERS * s.packets_sent for s in sent)
                  / len(sent) / span,
                  packets_per_s=sum(s.packets_sent for s in sent) / len(sent) / span,
                  max_packet=max(s.max_packet for s in sent), false_gone=false_gone,
                  merge_us=1e6 * merge[0] / max(merge[1], 1), occupancy=100.0 * airtime[0] / seconds)


def full_encoder(members: int, period: float, rate: float, seed: int,
                 key: bytes | None = KEY) -> tuple[float, float, int]:
    """Plain flooding without simulating it: (bytes/s per vehicle, channel occupancy %, packet bytes) of
    every vehicle broadcasting every row once a period (the board every 4th period)."""
    rng = random.Random(seed)
    rows = [Vehicle(m, rng).entry() for m in range(1, members + 1)]
    rows = [MemberEntry(**{**r.__dict__, "stamp": 1.0, "seq": 1, "voc": 10}) for r in rows]
    plain = encode_packets(1, rows, epoch=1, key=key)
    with_board = encode_packets(1, rows, board(1.0), epoch=1, key=key)
    per_period = (3 * sum(map(len, plain)) + sum(map(len, with_board))) / 4
    air = (3 * sum(airtime_s(len(p), rate) for p in plain)
           + sum(airtime_s(len(p), rate) for p in with_board)) / 4
    return per_period / period, 100.0 * air * (members + 1) / period, max(map(len, with_board))


def rows(results: list[Result]) -> list[list[object]]:
    return [[r.members, r.selection, f"{r.loss:.0%}", "-" if r.range_m is None else f"{r.range_m:g}",
             f"{r.p50:.2f}", f"{r.p95:.2f}", f"{r.max:.2f}",
             f"{r.bytes_per_s:.0f}", f"{r.packets_per_s:.2f}", r.max_packet, f"{r.merge_us:.0f}",
             f"{r.occupancy:.1f}", r.false_gone] for r in results]


HEADERS = ["members", "rows sent", "loss", "range m", "p50 age s", "p95 age s", "max age s",
           "B/s per vehicle", "packets/s", "max packet B", "merge us/msg", "channel %", "gone events"]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--members", default="20,50,100", help="team sizes (vehicles, plus one station)")
    ap.add_argument("--seconds", type=float, default=25.0, help="simulated seconds per run (default 25)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--losses", default="0,0.2", help="loss fractions")
    ap.add_argument("--rate", type=float, default=6e6, help="802.11 basic rate, bit/s (default 6e6)")
    ap.add_argument("--range", type=float, default=700.0, help="radio range (m) of the multi-hop table")
    ap.add_argument("--multihop", default="20,50", help="team sizes of the multi-hop table ('' for none)")
    ap.add_argument("--unsigned", action="store_true",
                    help="no team key (CRC trailer, no signature check, no replay guard)")
    args = ap.parse_args()
    key = None if args.unsigned else KEY
    sizes = [int(x) for x in args.members.split(",") if x.strip()]
    losses = [float(x) for x in args.losses.split(",") if x.strip()]
    print(f"# bench_teamlink ({machine()})\n")
    print(f"Full mesh, {args.seconds:g} s simulated, period {DEFAULT_PERIOD_S} s, airtime at "
          f"{args.rate / 1e6:g} Mbit/s, packets {'unsigned' if key is None else 'signed (team key)'}:\n")
    results = []
    for n in sizes:
        for loss in losses:
            results.append(run(n, loss, DEFAULT_PERIOD_S, args.seconds, args.seed, rate=args.rate, key=key))
            print(f"  {n} members {loss:.0%} done", file=sys.stderr, flush=True)
    if sizes and min(sizes) <= 20:
        results.append(run(min(sizes), 0.2, DEFAULT_PERIOD_S, args.seconds, args.seed, selection="full",
                           rate=args.rate, key=key))
    print(table(HEADERS, rows(results)))
    print("\nPlain flooding (every row in every broadcast), the encoder's bytes:\n")
    full = [[n, f"{b:.0f}", size, f"{occ:.1f}"]
            for n in sizes for b, occ, size in [full_encoder(n, DEFAULT_PERIOD_S, args.rate, args.seed, key)]]
    print(table(["members", "B/s per vehicle", "largest broadcast B", "channel %"], full))
    hops = [int(x) for x in args.multihop.split(",") if x.strip()]
    if hops:
        print(f"\nMulti-hop: radio range {args.range:g} m over the 2 x 2 km area (vehicles beyond it hear "
              f"each other only through relays), 20 % loss:\n")
        print(table(HEADERS, rows([run(n, 0.2, DEFAULT_PERIOD_S, args.seconds, args.seed, args.range,
                                       rate=args.rate, key=key) for n in hops])))
    return 0


if __name__ == "__main__":
    sys.exit(main())
