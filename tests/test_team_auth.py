"""Time that survives reboots, identity and authentication on the team link (companion/team/auth.py,
wire.py format 2, groupstate.py's identity rule, link.py's receive path), in process over real UDP."""

from __future__ import annotations

import dataclasses
import hashlib
import stat
import time
from pathlib import Path

import pytest

from companion.team.auth import ReplayGuard, generate_key_file, is_local, load_key, team_key
from companion.team.groupstate import GroupState
from companion.team.link import TeamLink
from companion.team.station import TeamControlStation
from companion.team.tasks import TaskDef
from companion.team.transport import UdpTransport, open_transport
from companion.team.types import STATION_ID, MemberEntry, MemberStatus, TaskBoard, TaskKind, TeamTask
from companion.team.wire import (
    HEADER_SIZE,
    BadSignatureError,
    UnsignedError,
    UnverifiableError,
    WireError,
    decode_packet,
    encode_packet,
    encode_packets,
)
from harness.team import new_team_url
from harness.timing import wait_for

KEY = hashlib.sha256(b"a team key of the test fleet").digest()
OTHER_KEY = hashlib.sha256(b"somebody else's key").digest()
POS = (58.39, 15.57, 30.0)


def row(m: int, seq: int, epoch: int, stamp: float = 100.0, voc: int = 10, **kw: object) -> MemberEntry:
    return MemberEntry(member=m, epoch=epoch, stamp=stamp, seq=seq, voc=voc, position=POS, **kw)  # type: ignore[arg-type]


# ------------------------------------------------------------------------------------------- the codec

def test_signed_packet_round_trip_and_header() -> None:
    data = encode_packet(70000, [row(70000, 5, epoch=2**63 + 9)], epoch=2**63 + 9, stamp=1234.5, pseq=77,
                         key=KEY)
    pkt = decode_packet(data, key=KEY)
    assert (pkt.sender, pkt.epoch, pkt.stamp, pkt.pseq, pkt.signed) == (70000, 2**63 + 9, 1234.5, 77, True)
    assert pkt.rows[0].member == 70000 and pkt.rows[0].epoch == 2**63 + 9  # ids wider than one byte


def test_forged_byte_wrong_key_unsigned_and_keyless_are_refused() -> None:
    data = encode_packet(3, [row(3, 5, epoch=8)], epoch=8, stamp=10.0, key=KEY)
    for i in (0 + 5, HEADER_SIZE, HEADER_SIZE + 20, len(data) - 1):  # header, body, signature
        forged = bytearray(data)
        forged[i] ^= 0x01
        with pytest.raises(BadSignatureError):
            decode_packet(bytes(forged), key=KEY)
    with pytest.raises(BadSignatureError):
        decode_packet(data, key=OTHER_KEY)
    with pytest.raises(UnsignedError):
        decode_packet(encode_packet(3, [row(3, 5, epoch=8)], epoch=8), key=KEY)
    with pytest.raises(UnverifiableError):
        decode_packet(data)
    assert all(isinstance(e, WireError) for e in (UnsignedError("x"), BadSignatureError("x")))


def test_replay_guard_window_and_future() -> None:
    g = ReplayGuard(window=8, future_s=30.0)
    assert g.check(1, 5, 10, 0.0, 0.0) is None
    assert g.check(1, 5, 10, 0.0, 0.0) == "replayed"
    assert g.check(1, 5, 12, 0.0, 0.0) is None
    assert g.check(1, 5, 11, 0.0, 0.0) is None  # reordered within the window: taken once
    assert g.check(1, 5, 11, 0.0, 0.0) == "replayed"
    assert g.check(1, 5, 3, 0.0, 0.0) == "replayed"  # older than the window
    assert g.check(1, 6, 10, 0.0, 0.0) is None  # another epoch is another stream
    assert g.check(2, 5, 10, 0.0 - 3600.0, 0.0) is None  # a clock an hour behind is fine
    assert g.check(2, 5, 11, 31.0, 0.0) == "future"
    assert g.check(2, 5, 11, 29.0, 0.0) is None


def test_team_clock_follows_the_majority_not_one_member_far_ahead() -> None:
    behind = ReplayGuard()  # this member's clock is an hour behind the team's
    assert behind.check(0, 1, 1, 3600.0, 0.0) == "future"  # one voice ahead: not yet the team's clock
    assert behind.check(2, 1, 1, 3600.6, 0.6) is None  # a second voice: the majority is an hour ahead
    assert behind.check(0, 1, 2, 3601.2, 1.2) is None
    fleet = ReplayGuard()  # a fleet on time hears one member ten years ahead
    for m in (0, 2, 3):
        assert fleet.check(m, 1, 1, 5.0, 5.0) is None
    for k in range(5):
        assert fleet.check(9, 1, 1 + k, 5.0 + 3.2e8 + k, 5.0 + k) == "future"


def test_key_files(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    p = generate_key_file(tmp_path / "k" / "team.key")
    assert stat.S_IMODE(p.stat().st_mode) == 0o600 and len(load_key(p)) == 32
    assert generate_key_file(p) == p and load_key(p) == load_key(p)  # kept, not regenerated
    short = tmp_path / "short.key"
    short.write_text("abc\n")
    with pytest.raises(ValueError, match=r"short\.key.*at least 16"):
        load_key(short)
    with pytest.raises(ValueError, match=r"missing\.key"):
        load_key(tmp_path / "missing.key")
    monkeypatch.setenv("TASKFLIGHT_TEAM_KEY", str(p))
    assert team_key(None) == load_key(p)
    monkeypatch.delenv("TASKFLIGHT_TEAM_KEY")
    assert team_key(None) is None
    assert is_local("mem://x") and is_local("udp://239.255.70.1:14650?iface=127.0.0.1")
    assert not is_local("udp://239.255.70.1:14650?iface=192.168.1.5") and not is_local("zenoh:")


# ------------------------------------------------------------------------------------- the identity rule

def test_reboot_new_epoch_taken_once_the_old_is_stale_never_while_alive() -> None:
    g = GroupState(1, voc_max=10)
    g.merge([row(3, 500, epoch=11, stamp=5000.0)], sender=3)
    # another epoch of member 3 while the held one is alive: counted, never taken
    res = g.merge([row(3, 1, epoch=22, stamp=1400.0)], sender=3)
    assert res.other_epoch == (3,) and g.get(3).epoch == 11
    g.tick()  # member 3 heard this interval
    for _ in range(2):
        g.tick()
        assert g.merge([row(3, 2, epoch=22, stamp=1401.0)], sender=3).other_epoch == (3,)
    g.tick()  # three intervals without epoch 11's owner: stale
    res = g.merge([row(3, 3, epoch=22, stamp=1402.0)], sender=3)  # its clock an hour behind
    assert res.replaced == 1 and res.joined == (3,) and g.get(3).epoch == 22 and 3 in g.alive()
    # a late relay of the old epoch changes nothing now
    assert g.merge([row(3, 501, epoch=11, stamp=5001.0, voc=10)], sender=2).other_epoch == (3,)
    assert g.get(3).epoch == 22


def test_board_follows_the_station_epoch_not_its_stamp() -> None:
    member = GroupState(4)
    old = TaskBoard(stamp=1e12, seq=900, epoch=5, tasks=(TeamTask(1, 1, TaskKind.VISIT, (POS,)),))
    assert member.merge_board(old)
    # a restarted station (new epoch, clock behind, version from 1): taken once its row is taken
    new = TaskBoard(stamp=10.0, seq=1, epoch=6)
    assert not member.merge_board(new)
    member.merge([row(STATION_ID, 1, epoch=6, status=MemberStatus.STATION)], sender=STATION_ID)
    assert member.merge_board(new) and member.board == new
    assert not member.merge_board(old)


# ------------------------------------------------------------------------------------ links over real UDP

class Fleet:
    """A keyed station and two keyed member links on one real UDP multicast group (loopback)."""

    def __init__(self, url: str, key: bytes | None = KEY) -> None:
        self.url = url
        self.station = TeamControlStation(open_transport(url), period_s=0.2, key=key).start()
        self.members = [TeamLink(GroupState(m), UdpTransport(*_group(url)), period_s=0.2, key=key,
                                 own=lambda m=m: MemberEntry(member=m, stamp=0.0, seq=0, position=POS,
                                                             name=f"m{m}"))
                        for m in (1, 2)]
        for link in self.members:
            link.start()
        wait_for(lambda: all(set(link.state.alive()) >= {0, 1, 2} for link in self.members), 20,
                 "the members hear each other and the station")

    def boards(self) -> list[tuple[int, tuple[tuple[int, str], ...]]]:
        """Each member's board: the station epoch and the live tasks (id, name)."""
        return [(link.state.board.epoch, tuple((t.id, t.name) for t in link.state.board.live()))
                for link in self.members]

    def close(self) -> None:
        for link in self.members:
            link.close()
        self.station.close()


def _group(url: str) -> tuple[str, int]:
    host, port = url.removeprefix("udp://").split(":")
    return host, int(port)


@pytest.fixture
def fleet() -> Fleet:
    f = Fleet(new_team_url())
    yield f  # type: ignore[misc]
    f.close()


def _visit() -> TaskDef:
    return TaskDef(kind="visit", points=[[58.3905, 15.5705, 20.0]], name="v")


def test_attacks_on_a_keyed_team_change_nothing(fleet: Fleet) -> None:
    """Unsigned, forged, replayed packets and a stamp ten years ahead are dropped and counted; the board
    the members hold never changes (sampled), and the 1e12-stamped board that froze the old format does
    not freeze this one."""
    fleet.station.add(_visit())
    wait_for(lambda: all(b[1] for b in fleet.boards()), 10, "the members take the board")
    before = fleet.boards()
    sock = UdpTransport(*_group(fleet.url))
    raw = UdpTransport(*_group(fleet.url))  # hears the station's real signed packets, to replay them
    heard: list[bytes] = []
    end = time.monotonic() + 2.0
    while time.monotonic() < end:
        d = raw.recv(0.1)
        if d is not None and decode_packet(d, key=KEY).sender == STATION_ID:
            heard.append(d)
    assert heard
    evil = TaskBoard(stamp=1e12, seq=2**32 - 1, epoch=fleet.station.state.epoch, tasks=())
    station_row = MemberEntry(member=0, epoch=fleet.station.state.epoch, stamp=1e12, seq=2**32 - 1,
                              status=MemberStatus.STATION)
    now = time.time()
    attacks = {
        "unsigned": encode_packets(0, [station_row], evil, epoch=fleet.station.state.epoch, stamp=now),
        "bad_signature": [bytes(p[:-1]) + bytes([p[-1] ^ 1]) for p in heard[:3]]
        + encode_packets(0, [station_row], evil, epoch=fleet.station.state.epoch, stamp=now, key=OTHER_KEY),
        "replayed": heard,
        "future": encode_packets(0, [station_row], evil, epoch=fleet.station.state.epoch,
                                 stamp=now + 10 * 365 * 86400.0, pseq=2**31, key=KEY),
    }
    counts0 = {k: [getattr(link.stats, k) for link in fleet.members] for k in attacks}
    samples = []
    for _ in range(3):
        for packets in attacks.values():
            for p in packets:
                sock.send(p)
        samples.append(fleet.boards())
        time.sleep(0.3)
    end = time.monotonic() + 2.0
    while time.monotonic() < end:
        samples.append(fleet.boards())
        time.sleep(0.1)
    assert all(s == before for s in samples)
    for k in attacks:
        for i, link in enumerate(fleet.members):
            assert getattr(link.stats, k) > counts0[k][i], (k, link.stats)
    # the real station still publishes: a new task reaches every member
    fleet.station.add(dataclasses.replace(_visit(), name="w"))
    wait_for(lambda: all(len(b[1]) == 2 for b in fleet.boards()), 10, "a later real board is taken")
    sock.close()
    raw.close()


def test_a_station_without_the_key_or_ten_years_ahead_changes_nothing(fleet: Fleet) -> None:
    fleet.station.add(_visit())
    wait_for(lambda: all(b[1] for b in fleet.boards()), 10, "the members take the board")
    before = fleet.boards()
    keyless = TeamControlStation(open_transport(fleet.url), period_s=0.2).start()
    ahead = TeamControlStation(open_transport(fleet.url), period_s=0.2, key=KEY,
                               clock=lambda: time.time() + 10 * 365 * 86400.0).start()
    intruder = TeamLink(GroupState(9), UdpTransport(*_group(fleet.url)), period_s=0.2,
                        own=lambda: MemberEntry(member=9, stamp=0.0, seq=0, position=POS))
    intruder.start()
    try:
        for s in (keyless, ahead):
            for j in range(3):
                s.add(dataclasses.replace(_visit(), name=f"evil{j}"), force=True)
        samples = []
        end = time.monotonic() + 3.0
        while time.monotonic() < end:
            samples.append(fleet.boards())
            time.sleep(0.1)
        assert all(s == before for s in samples)
        assert all(9 not in link.state.entries() for link in fleet.members)
        wait_for(lambda: all(link.stats.unsigned > 0 and link.stats.future > 0 for link in fleet.members), 10,
                 "the members count the keyless and the future packets")
        wait_for(lambda: keyless.link.stats.unverifiable > 0, 10, "the keyless station hears the fleet")
        assert fleet.boards() == before
    finally:
        intruder.close()
        keyless.close()
        ahead.close()


def test_two_links_with_one_id_the_second_refuses_the_first_keeps_its_row() -> None:
    url = new_team_url()
    fleet = Fleet(url, key=None)
    try:
        first_epoch = fleet.members[0].epoch
        wait_for(lambda: fleet.members[0].state.own().seq >= 5, 10, "the first has published its row a while")
        second = TeamLink(GroupState(1), UdpTransport(*_group(url)), period_s=0.2,
                          own=lambda: MemberEntry(member=1, stamp=0.0, seq=0, position=(1.0, 2.0, 3.0)))
        events = []
        second.listeners.append(events.append)
        second.start()
        samples = []
        end = time.monotonic() + 3.0
        while time.monotonic() < end:
            samples.append((fleet.station.state.get(1).epoch, fleet.members[1].state.get(1).epoch))
            time.sleep(0.05)
        assert set(samples) == {(first_epoch, first_epoch)}
        assert second.refused is not None and "duplicate id 1" in second.refused
        assert [e.kind for e in events if e.kind == "refused"] == ["refused"]
        assert fleet.members[0].refused is None and fleet.members[0].stats.duplicates > 0
        dup = [e for e in fleet.station.log.entries if e["event"] == "duplicate"]
        assert dup and dup[0]["member"] == 1 and "duplicate" in dup[0]["message"]
        # a refused link sends no row any more: only its empty beacon, so that the duplicate stays visible
        sent, sent_bytes = second.stats.packets_sent, second.stats.bytes_sent
        wait_for(lambda: second.stats.packets_sent >= sent + 3, 10, "the refused link's beacons")
        second.close()
        beacon = len(encode_packets(1, [], None, epoch=second.epoch, stamp=0.0)[0])
        assert second.stats.bytes_sent - sent_bytes == beacon * (second.stats.packets_sent - sent)
    finally:
        fleet.close()


def test_echo_is_not_a_duplicate() -> None:
    url = new_team_url()
    link = TeamLink(GroupState(5), UdpTransport(*_group(url)), period_s=0.1,
                    own=lambda: MemberEntry(member=5, stamp=0.0, seq=0, position=POS))
    link.start()
    try:
        wait_for(lambda: link.stats.own_echoes >= 5, 10, "own packets heard back (multicast loopback)")
        assert link.refused is None and link.stats.duplicates == 0
    finally:
        link.close()



def test_the_ground_service_shows_a_duplicate_id_as_an_event(tmp_path: Path) -> None:
    """The station's "duplicate" entry becomes a ground event whose text says "duplicate" (the alert)."""
    from companion.team.link import LinkEvent
    from companion.team.transport import MemoryBus
    from groundstation.auth import Tokens
    from groundstation.service import GroundService

    svc = GroundService(str(tmp_path / "g.db"), Tokens({"operator": ["op-token-0123456789"]}),
                        transport=MemoryBus().attach())
    try:
        svc.station._on_link(LinkEvent("duplicate", member=7))
        (ev,) = svc.db.events(kind="duplicate_id")
        assert ev["vehicle"] == 7 and ev["severity"] == "warning" and "duplicate member id 7" in ev["message"]
    finally:
        svc.close()
