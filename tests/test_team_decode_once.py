"""One decoding per process of a datagram that several members of a companion host hear."""

from __future__ import annotations

import hashlib

import pytest

from companion.team.decode_once import cache_info, decode_shared
from companion.team.groupstate import GroupState
from companion.team.link import TeamLink
from companion.team.transport import Transport
from companion.team.types import MemberEntry
from companion.team.wire import BadSignatureError, WireError, encode_packet

KEY = hashlib.sha256(b"the host's team key").digest()
POS = (58.39, 15.57, 30.0)


class _Silent(Transport):
    """A transport that hears nothing (the test hands each link its datagrams)."""

    def send(self, data: bytes) -> None:
        pass

    def recv(self, timeout_s: float) -> bytes | None:
        return None

    def close(self) -> None:
        pass

    @property
    def url(self) -> str:
        return "silent://"


def _row(m: int, seq: int) -> MemberEntry:
    return MemberEntry(member=m, epoch=7, stamp=100.0, seq=seq, voc=10, position=POS)


def test_equal_bytes_decode_to_one_packet_and_each_member_merges_it() -> None:
    data = encode_packet(9, [_row(9, 3), _row(4, 2)], epoch=7, stamp=100.0, pseq=1, key=KEY)
    before = cache_info()
    first = decode_shared(bytes(data), KEY)
    again = decode_shared(bytearray(data), KEY)
    assert again is first and cache_info().hits == before.hits + 1
    links = [TeamLink(GroupState(m), _Silent(), key=KEY, clock=lambda: 100.0,
                      own=lambda m=m: MemberEntry(member=m, stamp=0.0, seq=0, position=POS))
             for m in (1, 2, 3)]
    for link in links:
        link.handle(bytes(data))  # a fresh bytes object each, as each socket gives
    for link in links:  # each member's own group state took the rows, and counted the packet
        assert link.state.get(9).seq == 3 and link.state.get(4).seq == 2
        assert link.stats.packets_received == 1 and link.stats.bad_signature == 0
    assert first.rows[0].member == 9  # the shared packet is unchanged


def test_a_forged_packet_is_refused_by_every_member_each_time() -> None:
    data = bytearray(encode_packet(9, [_row(9, 3)], epoch=7, stamp=100.0, key=KEY))
    data[-1] ^= 1
    for _ in range(2):
        with pytest.raises(BadSignatureError):
            decode_shared(bytes(data), KEY)
    links = [TeamLink(GroupState(m), _Silent(), key=KEY, clock=lambda: 100.0) for m in (1, 2)]
    for link in links:
        link.handle(bytes(data))
        assert link.stats.bad_signature == 1 and link.state.get(9) is None
    # the same bytes under another key (another team in the process) are decoded under that key
    with pytest.raises(BadSignatureError):
        decode_shared(encode_packet(9, [_row(9, 3)], epoch=7, stamp=100.0, key=KEY), b"x" * 32)
    with pytest.raises(WireError):
        decode_shared("not bytes", KEY)  # type: ignore[arg-type]
