"""The team link's wire format (companion/team/wire.py, seed 003 Sec. III-A)."""

from __future__ import annotations

import contextlib
import json
import random
import struct
import zlib

import pytest

from companion.team.types import (
    Claim,
    ClaimState,
    MemberEntry,
    MemberStatus,
    TaskBoard,
    TaskKind,
    TaskState,
    TeamTask,
)
from companion.team.wire import (
    HEADER_SIZE,
    KIND_BOARD,
    KIND_STATE,
    MAX_PACKET,
    VERSION,
    BoardAssembler,
    ForeignVersionError,
    Packet,
    WireError,
    decode_packet,
    encode_packet,
    encode_packets,
)


def row(m: int, *, claims: int = 1, name: str | None = None) -> MemberEntry:
    return MemberEntry(member=m, stamp=1_700_000_000.25 + m, seq=1000 + m,
                       position=((583912345 + m * 1000) / 1e7, (155712345 - m * 1000) / 1e7, 30.25 + m),
                       velocity=(1.25, -2.5, 0.75), status=MemberStatus.BUSY, task=m,
                       claims=tuple(Claim(task=m + k, version=3, cost=123.456789 + k, state=ClaimState.ACTIVE)
                                    for k in range(claims)),
                       voc=7, name=name if name is not None else f"uav-{m:04d}")


def nine_task_board(tst_text: str | None = None) -> TaskBoard:
    kinds = [TaskKind.VISIT, TaskKind.PATROL_LINE, TaskKind.BORDER_PIECE, TaskKind.AREA_PART, TaskKind.TST]
    tasks = []
    for j in range(1, 10):
        kind = kinds[j % len(kinds)]
        npts = {TaskKind.VISIT: 1, TaskKind.PATROL_LINE: 4, TaskKind.BORDER_PIECE: 5, TaskKind.AREA_PART: 6,
                TaskKind.TST: 1}[kind]
        pts = tuple(((583900000 + j * 10000 + k * 2000) / 1e7, (155700000 - k * 3000) / 1e7, 20.0 + k)
                    for k in range(npts))
        tst = (tst_text or json.dumps({"type": "fly-to", "id": f"n{j}", "params": {"speed": "standard"}})
               if kind == TaskKind.TST else None)
        tasks.append(TeamTask(id=j, version=j % 3 + 1, kind=kind, points=pts, state=TaskState.UNASSIGNED,
                              group=7 if kind == TaskKind.AREA_PART else 0, group_size=3, altitude=25.5,
                              speed=2.7, tst=tst, name=f"task {j}"))
    return TaskBoard(stamp=1_700_000_000.5, seq=42, tasks=tuple(tasks))


def test_row_round_trip_exact_at_wire_resolution() -> None:
    rows = [row(m, claims=m % 4) for m in (0, 1, 17, 254, 255)]
    pkt = decode_packet(encode_packet(3, rows))
    assert pkt.sender == 3 and pkt.kind == KIND_STATE and pkt.board_part is None
    assert pkt.rows == tuple(rows)  # 1e-7 deg, cm and cm/s values survive exactly; costs are float64


def test_rounding_and_clamping() -> None:
    e = MemberEntry(member=5, stamp=1.5, seq=0, position=(12.345678912, -170.0000000449, 1.234),
                    velocity=(400.0, -0.004, 1.006))
    (got,) = decode_packet(encode_packet(5, [e])).rows
    assert got.position == pytest.approx((12.3456789, -170.0, 1.23), abs=1e-12)
    assert got.velocity == (327.67, -0.0, 1.01)  # clamped to the int16 cm/s range, rounded to 1 cm/s


def test_long_name_cut_at_a_character_boundary() -> None:
    e = row(9, name="åäö-vehicle-number-nine")  # 26 bytes utf-8
    (got,) = decode_packet(encode_packet(9, [e])).rows
    assert got.name == "åäö-vehicle-n" and len(got.name.encode()) <= 16


def test_board_round_trip_inline() -> None:
    board = nine_task_board()
    packets = encode_packets(0, [row(0)], board)
    assert len(packets) == 1
    pkt = decode_packet(packets[0])
    assert pkt.board == board and pkt.rows == (row(0),)


def test_twenty_members_and_nine_tasks_fit_two_packets_under_1400_bytes() -> None:
    rows = [row(m) for m in range(1, 21)]
    packets = encode_packets(1, rows, nine_task_board())
    assert all(len(p) <= MAX_PACKET for p in packets)
    assert len(packets) <= 2
    assert tuple(r for p in packets for r in decode_packet(p).rows) == tuple(rows)
    assembler = BoardAssembler()
    boards = [assembler.add(decode_packet(p).board_part) for p in packets if decode_packet(p).board_part]
    assert boards[-1] == nine_task_board()


def test_big_board_split_into_parts_joined_in_any_order_from_any_relay() -> None:
    rng = random.Random(5)
    # incompressible TST text forces several parts
    text = json.dumps({"type": "seq", "blob": "".join(rng.choice("abcdefghijklmnopqrstuvwxyz0123456789")
                                                       for _ in range(6000))})
    board = nine_task_board(tst_text=text)
    from_a = encode_packets(1, [row(1)], board)
    from_b = encode_packets(2, [row(2)], board)
    parts_a = [decode_packet(p).board_part for p in from_a if decode_packet(p).kind == KIND_BOARD]
    parts_b = [decode_packet(p).board_part for p in from_b if decode_packet(p).kind == KIND_BOARD]
    assert len(parts_a) >= 3 and all(len(p) <= MAX_PACKET for p in from_a)
    assert decode_packet(from_a[0]).board is None  # the state packet does not carry a part board
    mixed = [parts_b[i] if i % 2 else parts_a[i] for i in range(len(parts_a))]
    mixed.reverse()
    asm = BoardAssembler()
    results = [asm.add(p) for p in mixed]
    assert results[:-1] == [None] * (len(mixed) - 1)
    assert results[-1] == board


def test_many_rows_split_over_state_packets() -> None:
    rows = [row(m, claims=3) for m in range(1, 61)]
    packets = encode_packets(1, rows)
    assert len(packets) > 1 and all(len(p) <= MAX_PACKET for p in packets)
    got = [r for p in packets for r in decode_packet(p).rows]
    assert got == rows
    with pytest.raises(WireError, match="use encode_packets"):
        encode_packet(1, rows)


@pytest.mark.parametrize(("entry", "match"), [
    (MemberEntry(member=1 << 32, stamp=0.0, seq=0), "member id"),
    (MemberEntry(member=1, stamp=float("nan"), seq=0), "stamp"),
    (MemberEntry(member=1, stamp=0.0, seq=-1), "seq"),
    (MemberEntry(member=1, stamp=0.0, seq=0, position=(float("inf"), 0.0, 0.0)), "latitude"),
    (MemberEntry(member=1, stamp=0.0, seq=0, claims=(Claim(1, 70000, 1.0),)), "claim version"),
])
def test_unencodable_values_are_clear_errors(entry: MemberEntry, match: str) -> None:
    with pytest.raises(WireError, match=match):
        encode_packet(1, [entry])


def test_garbage_truncation_magic_version_crc() -> None:
    good = encode_packet(4, [row(4), row(5)], nine_task_board())
    with pytest.raises(WireError, match="truncated"):
        decode_packet(b"TF" + bytes([VERSION]))
    with pytest.raises(WireError, match="bad magic"):
        decode_packet(b"XX" + good[2:])
    with pytest.raises(WireError, match="bad CRC"):
        decode_packet(good[:-9] + good[-4:])
    flipped = bytearray(good)
    flipped[40] ^= 0x40
    with pytest.raises(WireError, match="bad CRC"):
        decode_packet(bytes(flipped))
    foreign = bytearray(good)
    foreign[2] = VERSION + 1
    with pytest.raises(ForeignVersionError) as ei:
        decode_packet(bytes(foreign))
    assert ei.value.version == VERSION + 1 and isinstance(ei.value, ValueError)
    with pytest.raises(WireError, match="not bytes"):
        decode_packet("TF")  # type: ignore[arg-type]


def _reframe(body: bytes, kind: int = KIND_STATE) -> bytes:
    """A packet with a valid header and CRC around ``body`` (reaches the parser past the CRC)."""
    data = struct.pack("!2sBBBIQdI", b"TF", VERSION, kind, 0, 9, 1, 0.0, 0) + body
    return data + struct.pack("!I", zlib.crc32(data))


def test_valid_crc_but_bad_contents() -> None:
    good = encode_packet(4, [row(4)])
    body = good[HEADER_SIZE:-4]
    with pytest.raises(WireError, match="unknown packet kind"):
        decode_packet(_reframe(body, kind=9))
    with pytest.raises(WireError, match="truncated"):
        decode_packet(_reframe(body[:-6]))
    with pytest.raises(WireError, match="trailing"):
        decode_packet(_reframe(body + b"\x00"))
    bad_status = bytearray(body)
    bad_status[1 + 42] = 99  # the status byte of the first row (after n_rows and 42 bytes)
    with pytest.raises(WireError, match="status"):
        decode_packet(_reframe(bytes(bad_status)))


def _check(data: bytes) -> Packet | None:
    try:
        return decode_packet(data)
    except WireError:
        return None


def test_fuzz_random_bytes_and_mutations_never_raise_anything_else() -> None:
    rng = random.Random(2024)
    board = nine_task_board()
    seeds = [encode_packet(1, [row(m) for m in range(1, 8)], board),
             *encode_packets(2, [row(2)], nine_task_board(tst_text="x" * 3000 + "y" * 7))]
    decoded = 0
    for i in range(4000):
        if i % 4 == 0:
            data = bytes(rng.getrandbits(8) for _ in range(rng.randrange(0, 300)))
            if i % 8 == 0:
                data = b"TF" + bytes([VERSION]) + data
        else:
            base = bytearray(rng.choice(seeds))
            for _ in range(rng.randrange(1, 6)):
                op = rng.randrange(4)
                if op == 0 and base:
                    base[rng.randrange(len(base))] = rng.getrandbits(8)
                elif op == 1 and base:
                    del base[rng.randrange(len(base)):]
                elif op == 2:
                    base.insert(rng.randrange(len(base) + 1), rng.getrandbits(8))
                else:
                    base += bytes(rng.getrandbits(8) for _ in range(rng.randrange(1, 20)))
            data = bytes(base)
            if i % 3 == 0:  # also reach the parser behind the CRC with mutated contents
                data = _reframe(data[HEADER_SIZE:-4] if len(data) > HEADER_SIZE + 4 else data,
                                kind=data[3] if len(data) > 3 else 1)
        pkt = _check(data)
        if pkt is not None:
            decoded += 1
            assert isinstance(pkt, Packet)
            if pkt.board_part is not None:
                with contextlib.suppress(WireError):
                    BoardAssembler().add(pkt.board_part)
    assert decoded < 4000  # most mutations are caught (the CRC), none escaped as another exception


def test_wrong_types_are_wire_errors_too() -> None:
    bad_kind = TeamTask(id=1, version=1, kind="teleport", points=())  # type: ignore[arg-type]
    with pytest.raises(WireError, match="not encodable"):
        encode_packet(1, [row(1)], TaskBoard(stamp=1.0, seq=1, tasks=(bad_kind,)))
    with pytest.raises(WireError):
        encode_packet(1, [MemberEntry(member=1, stamp=0.0, seq=0, position=("a", 0.0, 0.0))])  # type: ignore[arg-type]
