"""Controlled flooding that scales (seed 003 Sec. III-A with :mod:`companion.team.gossip`): a packet carries
the own row, a bounded number of others' rows and a bounded digest whatever the team's size, and every
member still holds a fresh row of every other, on a full mesh and over relays."""

from __future__ import annotations

import random

import pytest

from companion.team.gossip import DIGEST_SIZE, MAX_RELAYS
from companion.team.groupstate import GroupState
from companion.team.link import TeamLink
from companion.team.transport import LossyTransport, MemoryBus
from companion.team.types import Claim, MemberEntry, MemberStatus
from companion.team.wire import KIND_DIGEST, KIND_STATE, decode_packet


def run_team(n: int, loss: float, seconds: float, range_m: float | None = None
             ) -> tuple[dict[int, TeamLink], list[bytes], float]:
    """``n`` members at random phases, 0.5 s period, ``seconds`` of simulated time; every packet sent (as
    a listener on the bus hears it) and the final time."""
    bus = MemoryBus()
    rng = random.Random(n)
    pos = {m: (58.39 + rng.uniform(0, 0.01), 15.57 + rng.uniform(0, 0.02), 30.0) for m in range(1, n + 1)}
    t = [100.0]
    links: dict[int, TeamLink] = {}
    for m in range(1, n + 1):
        tr = LossyTransport(bus.attach(), loss, seed=m, range_m=range_m, position_of=pos.get, member=m)
        links[m] = TeamLink(GroupState(m), tr, period_s=0.5, clock=lambda: t[0],
                            own=lambda m=m: MemberEntry(member=m, stamp=0.0, seq=0, position=pos[m],
                                                        status=MemberStatus.BUSY, claims=(Claim(m, 1, 9.0),),
                                                        name=f"v{m}"))
    tap = bus.attach()
    heard: list[bytes] = []
    phase = {m: rng.uniform(0, 0.5) for m in links}
    end = t[0] + seconds
    while t[0] < end:
        t[0] = round(t[0] + 0.05, 6)
        for m, link in links.items():
            if t[0] - 100.0 >= phase[m]:
                link.step(t[0])
        while (data := tap.recv(0.0)) is not None:
            heard.append(data)
    return links, heard, t[0]


@pytest.mark.parametrize("n", [8, 40])
def test_rows_per_packet_do_not_grow_with_the_team(n: int) -> None:
    links, heard, now = run_team(n, 0.2, 12.0)
    rows = [len(p.rows) for p in map(decode_packet, heard) if p.kind == KIND_STATE]
    digest = [len(p.digest) for p in map(decode_packet, heard) if p.kind == KIND_DIGEST]
    assert max(rows) <= 1 + MAX_RELAYS and max(digest) <= DIGEST_SIZE
    for m, link in links.items():  # and every member knows every other, fresh
        assert set(link.state.alive()) == set(links), m
        assert max(link.state.staleness(now).values()) <= 3.0, (m, link.state.staleness(now))


def test_rows_reach_members_over_relays() -> None:
    """A 2 x 1 km spread with a 500 m radio range: most rows reach a member only over relays."""
    links, _heard, now = run_team(20, 0.0, 25.0, range_m=500.0)
    stale = sorted(s for link in links.values() for s in link.state.staleness(now).values())
    assert all(set(link.state.alive()) == set(links) for link in links.values())
    assert stale[int(0.95 * len(stale))] <= 4.0, stale[-10:]
