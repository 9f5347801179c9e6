"""The team link (seed 003 Sec. III-A): group state with the vote of confidence, controlled flooding,
transports (real UDP multicast and broadcast on loopback, the memory bus, the lossy wrapper)."""

from __future__ import annotations

import dataclasses
import itertools
import json
import socket
import threading
from collections.abc import Callable
from typing import Any

import pytest

from companion.team.groupstate import GroupState
from companion.team.link import LinkEvent, TeamLink
from companion.team.transport import (
    LossyTransport,
    MemoryBus,
    MemoryTransport,
    UdpTransport,
    distance_m,
    open_transport,
)
from companion.team.types import (
    STATION_ID,
    GeoPoint,
    MemberEntry,
    MemberStatus,
    TaskBoard,
    TaskKind,
    TeamTask,
)
from companion.team.wire import VERSION, encode_packet
from harness.timing import wait_for
from taskflight_common.ports import free_ports

VOC = 10


def row(m: int, stamp: float, seq: int, voc: int = 0, **kw: Any) -> MemberEntry:
    return MemberEntry(member=m, stamp=stamp, seq=seq, voc=voc, **kw)


# ------------------------------------------------------------------------------------ group state

def test_newer_row_replaces_stale_relay_never_does() -> None:
    g = GroupState(1, voc_max=VOC)
    g.merge([row(3, 100.0, 5, voc=VOC)], sender=3)
    assert g.get(3).seq == 5 and g.get(3).voc == VOC
    # a relay (member 2) carries an older row of 3, even with a high voc: nothing changes
    res = g.merge([row(3, 100.0, 4, voc=VOC)], sender=2)
    assert res.replaced == 0 and g.get(3).seq == 5
    # the owner's own late (reordered) packet with an older row changes nothing either
    g.merge([row(3, 100.0, 3, voc=VOC)], sender=3)
    assert g.get(3).seq == 5
    # a newer row through a relay replaces it and carries the relay's voc
    res = g.merge([row(3, 100.5, 6, voc=4)], sender=2)
    assert res.replaced == 1 and g.get(3).seq == 6 and g.get(3).voc == 4


def test_same_stamp_orders_by_sequence_number() -> None:
    g = GroupState(1)
    g.merge([row(3, 100.0, 5)], sender=3)
    g.merge([row(3, 100.0, 6, voc=2)], sender=2)
    assert g.get(3).seq == 6


def test_voc_ages_out_after_voc_max_sample_intervals() -> None:
    g = GroupState(1, voc_max=VOC)
    g.merge([row(3, 100.0, 5)], sender=3)
    g.refresh_own(row(1, 100.0, 1))
    assert g.tick() == []  # the owner was heard since the last tick: no loss
    for _ in range(VOC - 1):
        assert g.tick() == []
    assert g.get(3).voc == 1 and 3 in g.alive()
    assert g.tick() == [3]
    assert 3 in g.gone() and 3 not in g.alive() and g.get(3).voc == 0
    assert g.tick() == []  # reported once
    assert g.own().voc == VOC and 1 in g.alive()  # the own row never ages


def test_owner_heard_keeps_voc_relay_heard_ages() -> None:
    g = GroupState(1, voc_max=VOC)
    g.merge([row(3, 100.0, 1)], sender=3)
    g.tick()
    g.merge([row(3, 100.5, 2, voc=VOC)], sender=2)  # only a relay: the owner not heard this interval
    g.tick()
    assert g.get(3).voc == VOC - 1
    g.merge([row(3, 101.0, 3)], sender=3)
    assert g.get(3).voc == VOC


def test_higher_voc_report_raises_lower_does_not_lower() -> None:
    g = GroupState(1, voc_max=VOC)
    g.merge([row(3, 100.0, 5)], sender=3)
    for _ in range(6):
        g.tick()
    assert g.get(3).voc == VOC - 5  # the first tick after hearing the owner takes nothing
    res = g.merge([row(3, 100.0, 5, voc=8)], sender=2)
    assert res.raised == 1 and g.get(3).voc == 8
    g.merge([row(3, 100.0, 5, voc=2)], sender=2)
    assert g.get(3).voc == 8
    g.merge([row(3, 100.0, 5, voc=200)], sender=2)
    assert g.get(3).voc == VOC  # never above voc_max


def test_own_row_never_taken_from_others() -> None:
    g = GroupState(1)
    own = g.refresh_own(row(1, 50.0, 1, position=(1.0, 2.0, 3.0)))
    res = g.merge([row(1, 1e9, 99, voc=VOC, position=(9.0, 9.0, 9.0))], sender=2)
    assert res.ignored_own == 1 and g.own() == own
    res = g.merge([row(1, 1e9, 99, voc=VOC)], sender=1)  # even "from" itself: it is the only writer
    assert g.own() == own


def test_refresh_own_rules() -> None:
    g = GroupState(1)
    g.refresh_own(row(1, 50.0, 1))
    with pytest.raises(ValueError, match="does not advance"):
        g.refresh_own(row(1, 50.0, 1))
    with pytest.raises(ValueError, match="does not advance"):
        g.refresh_own(row(1, 60.0, 0))
    with pytest.raises(ValueError, match="member 2"):
        g.refresh_own(row(2, 60.0, 1))
    assert g.own().seq == 1 and g.own().voc == g.voc_max and g.own().epoch == g.epoch


def test_gone_member_not_resurrected_by_old_row_rejoins_with_newer() -> None:
    g = GroupState(1, voc_max=3)
    g.merge([row(3, 100.0, 5)], sender=3)
    gone = [m for _ in range(4) for m in g.tick()]  # one interval with the owner heard, then 3 without
    assert gone == [3]
    # a late relay still holding the old row with a voc: ignored
    res = g.merge([row(3, 100.0, 5, voc=3)], sender=2)
    assert res.raised == 0 and 3 in g.gone()
    # the owner itself with its old row (a reordered packet): not a sign of a new life either
    g.merge([row(3, 100.0, 4)], sender=3)
    assert 3 in g.gone()
    # a relay's gone row (voc 0) of a newer refresh tells nothing
    g.merge([row(3, 101.0, 1, voc=0)], sender=2)
    assert 3 in g.gone()
    # a rebooted vehicle: a new epoch, its sequence restarted, its clock behind
    res = g.merge([row(3, 20.0, 0, epoch=77)], sender=3)
    assert res.joined == (3,) and g.get(3).voc == 3 and 3 in g.alive()


def test_board_one_writer_newer_wins() -> None:
    st = GroupState(STATION_ID)
    b1 = TaskBoard(stamp=10.0, seq=1, tasks=(TeamTask(1, 1, TaskKind.VISIT, ((58.0, 15.0, 10.0),)),))
    stored = st.set_board(b1)
    assert stored == dataclasses.replace(b1, epoch=st.epoch)
    with pytest.raises(ValueError, match="does not advance"):
        st.set_board(dataclasses.replace(b1, tasks=()))
    assert st.board == stored
    member = GroupState(4)
    with pytest.raises(PermissionError):
        member.set_board(b1)
    assert member.merge_board(stored) and not member.merge_board(stored)
    # a board of another epoch (no station row of that epoch held), whatever its version: refused
    assert not member.merge_board(TaskBoard(stamp=9.0, seq=50, epoch=st.epoch + 1))
    assert member.board == stored


def test_snapshots_are_copies() -> None:
    g = GroupState(1)
    g.merge([row(3, 1.0, 1)], sender=3)
    snap = g.entries()
    g.merge([row(4, 1.0, 1)], sender=4)
    assert set(snap) == {3} and set(g.entries()) == {3, 4}
    assert g.staleness(5.0) == {3: 4.0, 4: 4.0}


# ------------------------------------------------------------------------------------ links in memory

class Team:
    """Links on one memory bus, stepped in simulated time; member i at ``positions[i]``."""

    def __init__(self, members: list[int], positions: dict[int, GeoPoint], *, range_m: float | None = None,
                 loss: float = 0.0, period_s: float = 0.5, voc_max: int = VOC) -> None:
        self.bus = MemoryBus()
        self.positions = positions
        self.t = 1000.0
        self.links: dict[int, TeamLink] = {}
        self.lossy: dict[int, LossyTransport] = {}
        for i, m in enumerate(members):
            tr = LossyTransport(self.bus.attach(), loss, seed=100 + i, range_m=range_m,
                                position_of=self.positions.get, member=m)
            self.lossy[m] = tr
            status = MemberStatus.STATION if m == STATION_ID else MemberStatus.IDLE
            self.links[m] = TeamLink(GroupState(m, voc_max=voc_max), tr, period_s=period_s,
                                     clock=lambda: self.t, own=self._own_fn(m, status))

    def _own_fn(self, m: int, status: MemberStatus) -> Callable[[], MemberEntry]:
        return lambda: MemberEntry(member=m, stamp=0.0, seq=0, position=self.positions[m], status=status,
                                   name=f"m{m}")

    def run(self, seconds: float, dt: float = 0.05, skip: frozenset[int] = frozenset()) -> None:
        end = self.t + seconds
        while self.t < end:
            self.t = round(self.t + dt, 6)
            for m, link in self.links.items():
                if m not in skip:
                    link.step(self.t)


def line_positions(members: list[int], spacing_m: float) -> dict[int, GeoPoint]:
    return {m: (58.39, 15.57 + i * spacing_m / 58_000.0, 30.0) for i, m in enumerate(members)}


def test_flooding_a_hears_c_only_through_b() -> None:
    pos = line_positions([1, 2, 3], 400.0)  # A=1 -- B=2 -- C=3, 400 m apart, radio range 500 m
    assert 700 < distance_m(pos[1], pos[3]) < 900
    team = Team([1, 2, 3], pos, range_m=500.0)
    team.run(5.0)
    a = team.links[1].state
    assert set(a.alive()) == {1, 2, 3}
    assert team.lossy[1].dropped_range > 0 and team.lossy[3].dropped_range > 0
    assert team.lossy[2].dropped_range == 0
    c_row = a.get(3)
    assert c_row.position == pytest.approx(pos[3]) and c_row.name == "m3"
    assert a.staleness(team.t)[3] < 1.5  # two hops of half-second periods
    # A's view of C is only as new as B's
    assert (c_row.stamp, c_row.seq) <= (team.links[2].state.get(3).stamp, team.links[2].state.get(3).seq)


def test_stale_relay_cannot_roll_back_a_direct_view() -> None:
    pos = line_positions([1, 2, 3], 10.0)
    team = Team([1, 2, 3], pos)
    team.run(3.0)
    a = team.links[1].state
    fresh = a.get(3)
    # B's packet from long ago (its old view of C) arrives late
    old = dataclasses.replace(fresh, stamp=fresh.stamp - 2.0, seq=fresh.seq - 4, voc=VOC)
    raw = team.bus.attach()
    raw.send(encode_packet(2, [old]))
    team.links[1].step(team.t)
    assert a.get(3) == fresh


def test_dead_member_ages_out_and_listeners_are_told() -> None:
    pos = line_positions([1, 2, 3], 10.0)
    team = Team([1, 2, 3], pos)
    events: list[LinkEvent] = []
    team.links[1].listeners.append(events.append)
    team.run(2.0)
    assert sorted(e.member for e in events if e.kind == "joined") == [2, 3]
    killed_at = team.t
    # member 3 stops: voc_max periods later (plus a period or two of relaying lag) it is gone everywhere
    team.run(VOC * 0.5 - 1.0, skip=frozenset({3}))
    assert 3 in team.links[1].state.alive()
    team.run(2.5, skip=frozenset({3}))
    assert 3 in team.links[1].state.gone() and 3 in team.links[2].state.gone()
    gone = [e for e in events if e.kind == "gone"]
    assert [e.member for e in gone] == [3]
    assert team.t - killed_at <= VOC * 0.5 + 1.5
    # it reboots: a newer row brings it back
    team.run(1.0)
    assert 3 in team.links[1].state.alive()
    assert [e.member for e in events if e.kind == "joined"][-1] == 3


def test_own_seq_strictly_advances_per_broadcast() -> None:
    team = Team([1, 2], line_positions([1, 2], 10.0))
    seqs = []
    for _ in range(10):
        team.run(0.5)
        seqs.append((team.links[1].state.own().stamp, team.links[1].state.own().seq))
    assert all(b > a for a, b in itertools.pairwise(seqs))
    assert team.links[1].stats.own_echoes == 0  # the memory bus does not echo
    # a clock stepping back does not roll the own row back
    link = team.links[1]
    link._last_send = None
    link.step(team.t - 100.0)
    assert link.state.own().seq == seqs[-1][1] + 1 and link.state.own().stamp == team.t - 100.0


def big_board(stamp: float, seq: int, text_len: int = 0) -> TaskBoard:
    tasks = [TeamTask(id=j, version=1, kind=TaskKind.VISIT, points=((58.39 + j * 1e-3, 15.57, 20.0),),
                      name=f"visit {j}") for j in range(1, 9)]
    if text_len:
        blob = "".join(chr(0x41 + (i * 7919) % 26) + str(i % 97) for i in range(text_len))
        tasks.append(TeamTask(id=9, version=1, kind=TaskKind.TST, points=((58.4, 15.6, 20.0),),
                              tst=json.dumps({"type": "S", "note": blob})))
    return TaskBoard(stamp=stamp, seq=seq, tasks=tuple(tasks))


@pytest.mark.parametrize("text_len", [0, 3000])
def test_board_floods_from_the_station_over_a_relay(text_len: int) -> None:
    pos = line_positions([STATION_ID, 2, 3], 400.0)
    team = Team([STATION_ID, 2, 3], pos, range_m=500.0)
    boards: list[TaskBoard] = []
    team.links[3].listeners.append(lambda e: boards.append(e.board) if e.kind == "board" else None)
    team.run(1.0)
    b1 = big_board(team.t, 1, text_len)
    b1 = team.links[STATION_ID].state.set_board(b1)
    team.run(2.0)
    assert team.links[3].state.board == b1 and boards == [b1]
    b2 = dataclasses.replace(big_board(team.t, 2, text_len), tasks=b1.tasks[:3])
    b2 = team.links[STATION_ID].state.set_board(b2)
    team.run(2.0)
    assert team.links[3].state.board == b2 and boards == [b1, b2]
    # relays send the board only now and then: member 2 much less often than the station
    st, relay = team.links[STATION_ID].stats, team.links[2].stats
    if text_len:
        assert relay.packets_sent - relay.digests_sent < 0.75 * (st.packets_sent - st.digests_sent)


def test_garbage_and_foreign_versions_counted_and_ignored() -> None:
    team = Team([1, 2], line_positions([1, 2], 10.0))
    team.run(1.0)
    link = team.links[1]
    before = link.state.entries()
    raw = team.bus.attach()
    good = encode_packet(7, [row(7, team.t, 1, voc=VOC)])
    foreign = bytearray(good)
    foreign[2] = VERSION + 3
    bad_flags = b"TF" + bytes([VERSION]) + b"\x01\x07" + b"\xff" * 30
    for data in (b"", b"\x00" * 50, b"TF", good[:-1], bytes(foreign), bad_flags):
        raw.send(data)
    link.step(team.t)
    assert link.stats.garbage == 5 and link.stats.foreign_version == 1
    assert link.state.entries() == before


def test_link_survives_a_failing_listener() -> None:
    team = Team([1, 2], line_positions([1, 2], 10.0))

    def bad(_: LinkEvent) -> None:
        raise RuntimeError("listener bug")

    team.links[1].listeners.append(bad)
    team.run(1.0)
    assert 2 in team.links[1].state.alive()


# ------------------------------------------------------------------------------------ lossy transport

def test_lossy_drop_fraction_is_seeded_and_close_to_loss() -> None:
    def run(seed: int) -> tuple[int, int, list[bytes]]:
        bus = MemoryBus()
        src = bus.attach()
        rx = LossyTransport(bus.attach(), loss=0.3, seed=seed)
        got = []
        for i in range(4000):
            src.send(i.to_bytes(2, "big"))
            d = rx.recv(0.0)
            if d is not None:
                got.append(d)
        return rx.dropped_loss, rx.passed, got

    dropped, passed, got = run(1)
    assert dropped + passed == 4000 and abs(dropped / 4000 - 0.3) < 0.03
    assert run(1) == (dropped, passed, got)
    assert run(2)[2] != got


def test_lossy_range_drops_only_far_senders() -> None:
    pos: dict[int, GeoPoint] = {1: (58.39, 15.57, 30.0), 2: (58.3905, 15.57, 30.0), 3: (58.40, 15.57, 30.0)}
    bus = MemoryBus()
    rx = LossyTransport(bus.attach(), range_m=200.0, position_of=pos.get, member=1)
    near, far, unknown = bus.attach(), bus.attach(), bus.attach()
    for _ in range(5):
        near.send(encode_packet(2, [row(2, 1.0, 1)]))
        far.send(encode_packet(3, [row(3, 1.0, 1)]))
        unknown.send(encode_packet(9, [row(9, 1.0, 1)]))  # no position known: kept
        far.send(b"not a team packet")  # no sender to judge by range: kept
    got = []
    while (d := rx.recv(0.0)) is not None:
        got.append(d)
    assert rx.dropped_range == 5 and rx.passed == 15 and len(got) == 15
    pos[3] = (58.3901, 15.57, 30.0)  # member 3 comes near
    far.send(encode_packet(3, [row(3, 2.0, 2)]))
    assert rx.recv(0.0) is not None


def test_lossy_bad_arguments() -> None:
    inner = MemoryBus().attach()
    with pytest.raises(ValueError, match="loss"):
        LossyTransport(inner, loss=1.5)
    with pytest.raises(ValueError, match="position_of"):
        LossyTransport(inner, range_m=100.0)


# ------------------------------------------------------------------------------------ URLs

def test_open_transport_urls() -> None:
    t = open_transport("mem://teamA")
    u = open_transport("mem://teamA")
    try:
        assert isinstance(t, MemoryTransport) and t.bus is u.bus and t.url == "mem://teamA"
        t.send(b"x")
        assert u.recv(0.0) == b"x"
    finally:
        t.close()
        u.close()
    lossy = open_transport("mem://teamB?loss=0.25&seed=3")
    assert isinstance(lossy, LossyTransport) and lossy.loss == 0.25
    lossy.close()
    ranged = open_transport("mem://teamC?range=500", member=1, position_of=lambda m: None)
    assert isinstance(ranged, LossyTransport) and ranged.range_m == 500.0
    ranged.close()


@pytest.mark.parametrize(("url", "part"), [
    ("tcp://239.255.70.1:14650", "scheme"),
    ("udp://239.255.70.1", "no port"),
    ("udp://239.255.70.1:99999", "port"),
    ("udp://:14650", "no host"),
    ("udp://team.example:14650", "not an IPv4"),
    ("udp://239.255.70.1:14650?loss=lots", "loss"),
    ("udp://239.255.70.1:14650?loss=2", "loss"),
    ("udp://239.255.70.1:14650?lossy=0.1", "unknown option 'lossy'"),
    ("udp://239.255.70.1:14650?iface=eth0", "iface"),
    ("bcast://239.255.70.1:14650", "multicast group"),
    ("mem://", "bus name"),
    ("mem://x?range=100", "range"),
    ("mem://x?range=-5", "range"),
])
def test_open_transport_bad_urls_name_the_part(url: str, part: str) -> None:
    with pytest.raises(ValueError, match=part):
        open_transport(url)


# ------------------------------------------------------------------------------------ real UDP

@pytest.mark.parametrize("kind", ["multicast", "broadcast"])
def test_udp_loopback_two_links_in_threads(kind: str) -> None:
    port = free_ports(1, socket.SOCK_DGRAM)[0]
    url = (f"udp://239.255.70.1:{port}?iface=127.0.0.1" if kind == "multicast"
           else f"bcast://127.255.255.255:{port}")
    positions = {1: (58.39, 15.57, 30.0), 2: (58.391, 15.571, 35.0)}
    links = []
    for m in (1, 2):
        tr = open_transport(url)
        assert isinstance(tr, UdpTransport)
        links.append(TeamLink(GroupState(m), tr, period_s=0.1, own=lambda m=m: MemberEntry(
            member=m, stamp=0.0, seq=0, position=positions[m], name=f"udp{m}")))
    joined = threading.Event()
    links[0].listeners.append(lambda e: joined.set() if e.kind == "joined" and e.member == 2 else None)
    try:
        for lk in links:
            lk.start()
        wait_for(lambda: 2 in links[0].state.alive() and 1 in links[1].state.alive(), 20.0,
                 "both links to see each other over UDP")
        assert joined.wait(5.0)
        wait_for(lambda: links[0].stats.own_echoes > 0, 10.0, "the own packets looped back")
        assert links[0].state.get(2).position == pytest.approx(positions[2])
        assert links[0].stats.garbage == 0 and links[0].stats.packets_sent > 0
        # a stranger on the same group/port sends garbage: counted, the link keeps going
        stranger = open_transport(url)
        try:
            stranger.send(b"\x00garbage")
            wait_for(lambda: links[0].stats.garbage >= 1 and links[1].stats.garbage >= 1, 10.0,
                     "the garbage to be counted")
        finally:
            stranger.close()
        seq = links[0].state.get(2).seq
        wait_for(lambda: links[0].state.get(2).seq > seq, 10.0, "member 2's row to keep refreshing")
    finally:
        for lk in links:
            lk.close()


def test_late_member_gets_the_board_from_relays_when_the_station_is_silent() -> None:
    members = [STATION_ID, 2, 3]
    pos = line_positions([*members, 4], 10.0)
    team = Team(members, pos)
    b1 = big_board(team.t, 1)
    b1 = team.links[STATION_ID].state.set_board(b1)
    team.run(2.0)
    assert team.links[3].state.board == b1
    late = TeamLink(GroupState(4), team.bus.attach(), period_s=0.5, clock=lambda: team.t,
                    own=lambda: MemberEntry(member=4, stamp=0.0, seq=0, position=pos[4]))
    team.links[4] = late
    sent_before = team.links[2].stats.packets_sent + team.links[3].stats.packets_sent
    team.run(0.5 * 4 + 0.2, skip=frozenset({STATION_ID}))  # relays send the board every 4th broadcast
    assert late.state.board == b1
    assert team.links[2].stats.packets_sent + team.links[3].stats.packets_sent > sent_before
