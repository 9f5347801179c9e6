"""Controlled flooding that scales (seed 003 Sec. III-A with :mod:`companion.team.gossip`): a packet carries
the own row, a bounded number of others' rows and a bounded digest whatever the team's size, and every
member still holds a fresh row of every other, on a full mesh and over relays."""

from __future__ import annotations

import dataclasses
import hashlib
import random
import zlib
from collections.abc import Callable

import pytest

from companion.team.gossip import DIGEST_SIZE, MAX_RELAYS, epoch_tag
from companion.team.groupstate import GroupState
from companion.team.link import TeamLink
from companion.team.transport import LossyTransport, MemoryBus
from companion.team.types import Claim, MemberEntry, MemberStatus
from companion.team.wire import (
    KIND_DIGEST,
    KIND_STATE,
    BadSignatureError,
    DigestEntry,
    UnsignedError,
    WireError,
    decode_packet,
    encode_digest,
    encode_packets,
)

KEY = hashlib.sha256(b"a team key of the gossip test").digest()


class Team:
    """``n`` members (ids ``first``, ``first + 1``, ...) on a memory bus at random phases, 0.5 s period,
    on a simulated clock; a tap hears every packet sent."""

    def __init__(self, n: int, loss: float, range_m: float | None = None, *, first: int = 1,
                 key: bytes | None = None) -> None:
        self.bus = MemoryBus()
        rng = random.Random(n)
        self.ids = list(range(first, first + n))
        self.pos = {m: (58.39 + rng.uniform(0, 0.01), 15.57 + rng.uniform(0, 0.02), 30.0) for m in self.ids}
        self.t = [100.0]
        self.loss, self.range_m, self.key = loss, range_m, key
        self.links: dict[int, TeamLink] = {m: self.member(m) for m in self.ids}
        self.tap = self.bus.attach()
        self.heard: list[bytes] = []
        self.phase = {m: rng.uniform(0, 0.5) for m in self.ids}

    def member(self, m: int, clock: Callable[[], float] | None = None) -> TeamLink:
        tr = LossyTransport(self.bus.attach(), self.loss, seed=m, range_m=self.range_m,
                            position_of=self.pos.get, member=m)
        pos = self.pos
        return TeamLink(GroupState(m), tr, period_s=0.5, clock=clock or (lambda: self.t[0]), key=self.key,
                        own=lambda: MemberEntry(member=m, stamp=0.0, seq=0, position=pos[m],
                                                status=MemberStatus.BUSY, claims=(Claim(m, 1, 9.0),),
                                                name=f"v{m}"))

    def run(self, seconds: float) -> float:
        end = self.t[0] + seconds
        while self.t[0] < end:
            self.t[0] = round(self.t[0] + 0.05, 6)
            for m, link in self.links.items():
                if self.t[0] - 100.0 >= self.phase[m]:
                    link.step(self.t[0])
            while (data := self.tap.recv(0.0)) is not None:
                self.heard.append(data)
        return self.t[0]


def run_team(n: int, loss: float, seconds: float, range_m: float | None = None
             ) -> tuple[dict[int, TeamLink], list[bytes], float]:
    """``n`` members at random phases, 0.5 s period, ``seconds`` of simulated time; every packet sent (as
    a listener on the bus hears it) and the final time."""
    team = Team(n, loss, range_m)
    now = team.run(seconds)
    return team.links, team.heard, now


@pytest.mark.parametrize("n", [8, 40])
def test_rows_per_packet_do_not_grow_with_the_team(n: int) -> None:
    links, heard, now = run_team(n, 0.2, 12.0)
    rows = [len(p.rows) for p in map(decode_packet, heard) if p.kind == KIND_STATE]
    digest = [len(p.digest) for p in map(decode_packet, heard) if p.digest]
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


# --------------------------------------------------------------------------------------- format 2 digests

def test_digest_carries_wide_ids_and_epochs_and_is_signed_like_every_packet() -> None:
    entries = [DigestEntry(70000, epoch_tag(2**63 + 5), 41, False), DigestEntry(2**32 - 1, 0, 0, True)]
    assert entries[0].epoch == 5 and epoch_tag(2**40) == 1  # the low 32 bits, never 0
    data = encode_digest(70001, entries, epoch=2**64 - 1, stamp=5.5, pseq=9, key=KEY)
    pkt = decode_packet(data, key=KEY)
    assert (pkt.kind, pkt.sender, pkt.epoch, pkt.pseq, pkt.signed) == (KIND_DIGEST, 70001, 2**64 - 1, 9, True)
    assert pkt.digest == tuple(entries) and not pkt.rows
    forged = bytearray(data)
    forged[-20] ^= 0x04  # a want flag or a seq changed
    with pytest.raises(BadSignatureError):
        decode_packet(bytes(forged), key=KEY)
    with pytest.raises(UnsignedError):
        decode_packet(encode_digest(70001, entries, epoch=3), key=KEY)
    with pytest.raises(WireError, match="digest member"):
        encode_digest(1, [DigestEntry(2**32, 1, 1)], epoch=1)
    with pytest.raises(WireError, match="digest epoch tag"):
        encode_digest(1, [DigestEntry(1, 2**32, 1)], epoch=1)
    bad = bytearray(encode_digest(1, entries[:1], epoch=1))
    bad[-5] = 7  # the want byte, then the CRC
    bad[-4:] = zlib.crc32(bytes(bad[:-4])).to_bytes(4, "big")
    with pytest.raises(WireError, match="digest want"):
        decode_packet(bytes(bad))


def test_the_digest_rides_in_the_state_packet_when_it_fits() -> None:
    """One packet a period (own row and digest) instead of two: a header and a signature saved; a digest
    that does not fit after the rows goes in a DIGEST packet of its own."""
    own = MemberEntry(member=5, epoch=3, stamp=1.0, seq=2, position=(58.39, 15.57, 30.0), name="v5")
    entries = [DigestEntry(m, 9, 40 + m, m % 3 == 0) for m in range(1, 11)]
    (one,) = encode_packets(5, [own], epoch=3, stamp=1.0, key=KEY, digest=entries)
    pkt = decode_packet(one, key=KEY)
    assert pkt.kind == KIND_STATE and pkt.rows == (own,) and pkt.digest == tuple(entries)
    many = [dataclasses.replace(own, member=m, name=f"member {m}") for m in range(5, 45)]
    packets = encode_packets(5, many, epoch=3, key=KEY, digest=[*entries] * 7)  # 911 bytes: alone
    decoded = [decode_packet(p, key=KEY) for p in packets]
    assert decoded[-1].kind == KIND_DIGEST and decoded[-1].digest == tuple(entries * 7)
    assert [r.member for p in decoded for r in p.rows] == [r.member for r in many]
    assert all(len(p) <= 1400 for p in packets)
    with pytest.raises(WireError, match="digest of 1431 bytes"):
        encode_packets(5, [own], epoch=3, key=KEY, digest=[*entries] * 11)


def test_a_keyed_team_with_32_bit_ids_gossips_and_drops_a_replayed_or_forged_digest() -> None:
    team = Team(12, 0.0, first=100000, key=KEY)
    now = team.run(10.0)
    for m, link in team.links.items():
        assert set(link.state.alive()) == set(team.ids), m
        assert max(link.state.staleness(now).values()) <= 3.0
    digests = [d for d in team.heard if decode_packet(d, key=KEY).digest]
    assert digests and all(decode_packet(d, key=KEY).signed for d in digests)
    victim = team.links[team.ids[0]]
    before = victim.stats.replayed
    old = [d for d in digests[len(digests) // 2:] if decode_packet(d, key=KEY).sender != victim.own_id][:2]
    for d in old:  # taken once already (no loss), within the replay window
        victim.handle(d)
    assert victim.stats.replayed == before + 2
    # a keyless forger asks for every row: nobody relays for it
    forger = encode_digest(999, [DigestEntry(m, 0, 0, True) for m in team.ids], epoch=7, stamp=now)
    queued = {m: dict(link.gossip._relay) for m, link in team.links.items()}
    for link in team.links.values():
        link.handle(forger)
        assert link.stats.unsigned >= 1
    assert {m: dict(link.gossip._relay) for m, link in team.links.items()} == queued


def test_a_member_rebooted_with_its_clock_an_hour_behind_is_seen_over_relays() -> None:
    """A 2 x 1 km spread, 500 m radio range: the new epoch's row reaches members out of the rebooted one's
    reach over relays (asked for in digests by (epoch, seq), no host clock compared) within 5 s."""
    team = Team(20, 0.0, range_m=500.0)
    team.run(20.0)
    m = team.ids[7]
    old = team.links[m]
    old_epoch = old.epoch
    old.close()
    team.links[m] = team.member(m, clock=lambda: team.t[0] - 3600.0)
    assert team.links[m].epoch != old_epoch
    now = team.run(6.5)  # 1.5 s for the old epoch to go stale, then 5 s
    holders = {o: link.state.get(m) for o, link in team.links.items() if o != m}
    epoch = team.links[m].epoch
    behind = sorted(o for o, r in holders.items() if r is None or r.epoch != epoch or r.voc == 0)
    assert not behind, (behind, now)
