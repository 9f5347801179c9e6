"""Bench: group-state staleness and bandwidth of the team link (seed 003 Sec. III-A).

``--members`` vehicles (20) and a team-control station (member 0, publishing a nine-task board) on one
in-process :class:`~companion.team.transport.MemoryBus`, each receiving through its own seeded
:class:`~companion.team.transport.LossyTransport`, run by :class:`~companion.team.link.TeamLink` in
simulated time (``--seconds`` of it, 120 by default, stepped every 50 ms; no sleeping). Each member
starts at a random phase of the period; the vehicles fly slowly (2-5 m/s) in random directions in
a 2 x 2 km square (turning back at its edges) and each holds one claim, so a row carries a
position, a velocity and a claim as in flight.

Figures, after a 10 s warm-up, sampled every 0.5 s:

* staleness: for every vehicle, ``now - stamp`` of the row it holds for every other vehicle (its
  view of the others' state), p50, p95 and max over all pairs and samples;
* bytes per second sent per vehicle (UDP payload; "on air" adds the 28 bytes of IP and UDP headers
  per packet), packets per second, the largest packet;
* gone events: a live vehicle whose voc ran out at some member (0 on the full mesh; with a short radio
  range a vehicle at a corner can be out of everyone's reach for a while, so some are real).

The first table sweeps the loss (0, 10, 20, 40 %) at the default period; the second sweeps the period
at 20 % loss (the choice of the default); the third repeats it with a radio range (``--range``, 700 m)
shorter than the 2 x 2 km area the vehicles start in, so many rows reach a vehicle only over relays
(each hop adds up to a period). Targets: p95 staleness <= 2 s and <= 5 kB/s per
vehicle at 20 % loss with 20 members.
"""

from __future__ import annotations

import argparse
import math
import random
import sys
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

DT = 0.05
WARMUP_S = 10.0
SAMPLE_S = 0.5
UDP_IP_HEADERS = 28
ORIGIN = (58.39, 15.57)
M_PER_DEG = 111_320.0
HALF_SIDE_M = 1000.0  #: the vehicles fly in a 2 x 2 km square


@dataclass
class Result:
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
        range_m: float | None = None) -> Result:
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
        links[m] = TeamLink(GroupState(m), tr, period_s=period, clock=lambda: t, own=own)
        links[m].listeners.append(on_event)
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
    return Result(loss=loss, period=period, range_m=range_m, p50=pct(ages, 0.5), p95=pct(ages, 0.95),
                  max=max(ages),
                  bytes_per_s=sum(s.bytes_sent for s in sent) / len(sent) / span,
                  air_bytes_per_s=sum(s.bytes_sent + UDP_IP_HEADERS * s.packets_sent for s in sent)
                  / len(sent) / span,
                  packets_per_s=sum(s.packets_sent for s in sent) / len(sent) / span,
                  max_packet=max(s.max_packet for s in sent), false_gone=false_gone)


def rows(results: list[Result]) -> list[list[object]]:
    return [[f"{r.loss:.0%}", f"{r.period:g}", "-" if r.range_m is None else f"{r.range_m:g}",
             f"{r.p50:.2f}", f"{r.p95:.2f}", f"{r.max:.2f}",
             f"{r.bytes_per_s:.0f}", f"{r.air_bytes_per_s:.0f}", f"{r.packets_per_s:.2f}", r.max_packet,
             r.false_gone] for r in results]


HEADERS = ["loss", "period s", "range m", "p50 age s", "p95 age s", "max age s", "B/s per vehicle",
           "B/s on air", "packets/s", "max packet B", "gone events"]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--members", type=int, default=20, help="vehicles (plus one station; default 20)")
    ap.add_argument("--seconds", type=float, default=120.0, help="simulated seconds per run (default 120)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--losses", default="0,0.1,0.2,0.4", help="loss fractions of the first table")
    ap.add_argument("--periods", default="0.25,0.5,1.0,2.0",
                    help="periods (s) of the second table, at 20 %% loss")
    ap.add_argument("--range", type=float, default=700.0, help="radio range (m) of the third table")
    args = ap.parse_args()
    print(f"# bench_teamlink ({machine()})\n")
    print(f"{args.members} vehicles + a station (nine-task board), {args.seconds:g} s simulated, "
          f"period {DEFAULT_PERIOD_S} s (the default), loss swept:\n")
    losses = [float(x) for x in args.losses.split(",") if x.strip()]
    results = [run(args.members, p, DEFAULT_PERIOD_S, args.seconds, args.seed) for p in losses]
    print(table(HEADERS, rows(results)))
    periods = [float(x) for x in args.periods.split(",") if x.strip()]
    print(f"\nThe period at 20 % loss, {args.members} vehicles:\n")
    print(table(HEADERS, rows([run(args.members, 0.2, p, args.seconds, args.seed) for p in periods])))
    print(f"\nMulti-hop: radio range {args.range:g} m over the 2 x 2 km area (vehicles beyond it hear each "
          f"other only through relays), 20 % loss:\n")
    multihop = [run(args.members, 0.2, p, args.seconds, args.seed, args.range) for p in periods]
    print(table(HEADERS, rows(multihop)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
