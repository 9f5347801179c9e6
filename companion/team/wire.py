"""The team link's wire format (seed 003 Sec. III-A, "Orinoco"): compact, versioned binary packets.

Seed 003 Sec. III-A: each vehicle periodically broadcasts the group state, "the broadcaster's knowledge
of other vehicles is broadcast along with its knowledge of its own state" (controlled flooding). A
packet therefore carries rows of the group state (:class:`~companion.team.types.MemberEntry`, each with
its vote of confidence) and, optionally, a part of the task board (:class:`~companion.team.types.TaskBoard`).

Layout (all integers big-endian, ``struct``)::

    header   magic b"TF" | version u8 (=2) | kind u8 | flags u8 (bit 0: signed) | sender u32
             | epoch u64 (the sender's boot epoch) | stamp f64 (the sender's clock, s) | pseq u32 (the
             sender's packet number in its epoch)
    body     kind STATE (1): n_rows u8, n_rows x row, parts u8 (bit 0: a board part follows, bit 1: a
             digest), [board part], [digest]
             kind BOARD (2): board part
             kind DIGEST (3): digest
    digest   n u8, n x (member u32 | epoch tag u32 (the epoch's low 32 bits) | seq u32 | want u8)
    trailer  unsigned: crc32 u32 of everything before it
             signed: the first 16 bytes of HMAC-SHA256(key, everything before it) (:mod:`.auth`)

    row      member u32 | epoch u64 | stamp f64 | seq u32 | lat i32 (1e-7 deg) | lon i32 (1e-7 deg)
             | alt i32 (cm) | vn ve vd i16 (cm/s, clamped to +-327 m/s) | status u8 | task u32 | voc u8
             | name (u8 length + <= 16 bytes utf-8) | n_claims u8, n_claims x (task u32, version u16,
             cost f64, state u8)
    board    epoch u64 (the station's) | stamp f64 | seq u32 (the board's version) | body crc32 u32
             | part index u8 | part count u8 | chunk length u16 | chunk (a slice of the zlib-compressed
             board body)
    body     n_tasks u16, n_tasks x (id u32, version u16, kind u8, state u8, group u32, group_size u16,
             altitude f64, speed f64, name (u8 length + <= 16 bytes), n_points u16, n_points x (lat i32,
             lon i32, alt i32 cm), tst (u32 length, 0xFFFFFFFF for none, + utf-8 text))

A row is 50 bytes plus its name and 15 bytes a claim: 20 members with one claim and an 8-byte name
take 1460 bytes (two packets); a board of nine tasks of one to six points compresses to about 170
bytes. The board (its whole body zlib-compressed, TST JSON included) travels inline in the last STATE
packet when it fits there in one part; otherwise :func:`encode_packets` cuts the compressed body into
chunks sent as BOARD packets (up to 255 parts), each naming the board's (stamp, seq) and the body's
CRC, so a receiver (:class:`BoardAssembler`) joins parts from any relays as long as they carry the
same body. Rows beyond one packet's room go into further STATE packets (rows are independent). Every
packet is at most ``max_size`` bytes (:data:`MAX_PACKET`, 1400: one Ethernet frame with room for the
IP and UDP headers).

Version 2 (identity, time that survives reboots, authentication): member ids are 32-bit; every row and
every board carries its writer's boot epoch (a random 64-bit number drawn when the link starts: a
companion needs no persistent storage for it, and two boots of one vehicle, or two vehicles with one id,
draw the same epoch with a probability of 2^-64), so freshness is (epoch, seq), never a host clock
(:mod:`.groupstate`); the header says who sent the packet, in which epoch, when by its clock and with
which packet number, and with a team key (:mod:`.auth`) the packet is signed as MAVLink 2 signing does
(HMAC-SHA256 over the whole packet, a time stamp and a per-sender replay window, checked by
:class:`~.auth.ReplayGuard`). Version 1 packets are foreign (counted, never taken).

A digest (:mod:`.gossip`) names, per entry, a member, the (epoch's low 32 bits, seq) of the row the
sender holds for it ((0, 0): none) and whether it wants a newer one; 13 bytes an entry. It rides in the
last STATE packet of a broadcast when it fits there, else in a DIGEST packet, framed, numbered and
signed like every other packet (:func:`encode_digest`).

Names longer than 16 bytes are cut at a character boundary; positions are rounded to 1e-7 deg and 1 cm,
velocities to 1 cm/s. Costs are float64: members compare each other's bids in a conflict (seed 003
Sec. III-B), and a float32 bid would differ from the bidder's own value, so two bidders could each
think the other cheaper. :func:`decode_packet` raises :class:`WireError` (a ``ValueError``) for any
input it cannot take: garbage, truncation, a bad magic, a bad CRC, a foreign version
(:class:`ForeignVersionError`), an unknown kind, status or task kind, bad utf-8, and with a key an
unsigned packet (:class:`UnsignedError`) or a bad signature (:class:`BadSignatureError`); without a key a
signed packet (:class:`UnverifiableError`); never another exception.
"""

from __future__ import annotations

import hmac
import math
import struct
import zlib
from collections import OrderedDict
from dataclasses import dataclass

from companion.team import kinds
from companion.team.auth import SIG_LEN, sign
from companion.team.types import (
    Claim,
    ClaimState,
    GeoPoint,
    MemberEntry,
    MemberStatus,
    TaskBoard,
    TaskKind,
    TaskState,
    TeamTask,
)

MAGIC = b"TF"
VERSION = 2
KIND_STATE = 1
KIND_BOARD = 2
#: what a member knows of the rows, a slice of it per packet (:mod:`companion.team.gossip`)
KIND_DIGEST = 3
#: largest packet :func:`encode_packets` makes by default (bytes of UDP payload)
MAX_PACKET = 1400
NAME_MAX = 16
#: the largest board body accepted after decompression (a guard against compression bombs)
BOARD_BODY_MAX = 1 << 20

#: flags bit: the packet ends with a signature, not a CRC
FLAG_SIGNED = 0x01

_HEADER = struct.Struct("!2sBBBIQdI")
#: bytes of a packet's header (the body starts there)
HEADER_SIZE = _HEADER.size
_CRC = struct.Struct("!I")
_ROW = struct.Struct("!IQdIiiihhhBIB")
_CLAIM = struct.Struct("!IHdB")
_PART = struct.Struct("!QdIIBBH")
_TASK = struct.Struct("!IHBBIHdd")
_POINT = struct.Struct("!iii")
_DIGEST = struct.Struct("!IIIB")
_NO_TST = 0xFFFFFFFF
_PART_BOARD = 0x01   #: a STATE packet's parts flags: a board part follows the rows
_PART_DIGEST = 0x02  #: ... and a digest after it

_KIND_CODES: dict[TaskKind, int] = kinds.wire_codes()  #: each kind names its own code
_KINDS = {v: k for k, v in _KIND_CODES.items()}
_STATE_CODES: dict[TaskState, int] = {TaskState.UNASSIGNED: 0, TaskState.ASSIGNED: 1, TaskState.ACTIVE: 2,
                                      TaskState.DONE: 3, TaskState.CANCELLED: 4}
_STATES = {v: k for k, v in _STATE_CODES.items()}


class WireError(ValueError):
    """A packet that cannot be encoded or decoded; ``reason`` says why."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


class UnsignedError(WireError):
    """An unsigned packet where a team key is configured (dropped and counted)."""


class BadSignatureError(WireError):
    """A signed packet whose signature does not match (forged, modified, or another key)."""


class UnverifiableError(WireError):
    """A signed packet heard by a link that has no key to check it."""


class ForeignVersionError(WireError):
    """A packet of the team link with another format version (counted apart from garbage)."""

    def __init__(self, version: int) -> None:
        super().__init__(f"foreign format version {version} (this side speaks {VERSION})")
        self.version = version


@dataclass(frozen=True)
class BoardPart:
    """One part of a task board on the wire: a slice of its compressed body."""

    epoch: int
    stamp: float
    seq: int
    body_crc: int
    index: int
    count: int
    chunk: bytes


@dataclass(frozen=True)
class DigestEntry:
    """One line of a digest: the (epoch tag, seq) of the row the sender holds for ``member`` ((0, 0): none;
    the tag is the epoch's low 32 bits, :func:`companion.team.gossip.epoch_tag`); ``want``: the sender asks
    for a newer one (its row went stale, or it never had one)."""

    member: int
    epoch: int
    seq: int
    want: bool = False


@dataclass(frozen=True)
class Packet:
    """A decoded packet: who sent it (member id, boot epoch, its clock's stamp, its packet number in the
    epoch, signed or not), the group-state rows it carries and maybe a board part, or a digest (kind
    DIGEST)."""

    sender: int
    kind: int
    rows: tuple[MemberEntry, ...] = ()
    board_part: BoardPart | None = None
    epoch: int = 0
    stamp: float = 0.0
    pseq: int = 0
    signed: bool = False
    digest: tuple[DigestEntry, ...] = ()

    @property
    def board(self) -> TaskBoard | None:
        """The board when the packet carries all of it in one part (else use a :class:`BoardAssembler`)."""
        p = self.board_part
        if p is None or p.count != 1:
            return None
        return decode_board_body(p.chunk, p.stamp, p.seq, p.body_crc, p.epoch)


# ---------------------------------------------------------------------------------------------- encoding

def _u(value: int, bits: int, what: str) -> int:
    if not isinstance(value, int) or not 0 <= value < (1 << bits):
        raise WireError(f"{what} {value!r} does not fit in an unsigned {bits}-bit field")
    return value


def _finite(x: float, what: str) -> float:
    if not math.isfinite(x):
        raise WireError(f"{what} is not finite: {x!r}")
    return float(x)


def _deg7(x: float, what: str) -> int:
    v = round(_finite(x, what) * 1e7)
    if not -(1 << 31) <= v < (1 << 31):
        raise WireError(f"{what} {x!r} out of range")
    return v


def _i32(x: float, what: str) -> int:
    v = round(_finite(x, what))
    if not -(1 << 31) <= v < (1 << 31):
        raise WireError(f"{what} {x!r} out of range")
    return v


def _cms16(x: float, what: str) -> int:
    return max(-32767, min(32767, round(_finite(x, what) * 100.0)))


def _name(s: str) -> bytes:
    b = s.encode("utf-8")
    if len(b) <= NAME_MAX:
        return bytes([len(b)]) + b
    b = b[:NAME_MAX].decode("utf-8", errors="ignore").encode("utf-8")  # cut at a character boundary
    return bytes([len(b)]) + b


def encode_row(e: MemberEntry) -> bytes:
    """One group-state row."""
    lat, lon, alt = e.position
    vn, ve, vd = e.velocity
    out = [_ROW.pack(_u(e.member, 32, "member id"), _u(e.epoch, 64, "epoch"), _finite(e.stamp, "stamp"),
                     _u(e.seq, 32, "seq"),
                     _deg7(lat, "latitude"), _deg7(lon, "longitude"), _i32(alt * 100.0, "altitude"),
                     _cms16(vn, "velocity north"), _cms16(ve, "velocity east"), _cms16(vd, "velocity down"),
                     _u(int(e.status), 8, "status"), _u(e.task, 32, "task"), _u(e.voc, 8, "voc")),
           _name(e.name), bytes([_u(len(e.claims), 8, "claim count")])]
    for c in e.claims:
        out.append(_CLAIM.pack(_u(c.task, 32, "claim task"), _u(c.version, 16, "claim version"),
                               _finite(c.cost, "claim cost"), _u(int(c.state), 8, "claim state")))
    return b"".join(out)


def encode_board_body(board: TaskBoard) -> bytes:
    """The board's tasks, zlib-compressed (its stamp and seq travel in each part's header)."""
    out = [struct.pack("!H", _u(len(board.tasks), 16, "task count"))]
    for t in board.tasks:
        out.append(_TASK.pack(_u(t.id, 32, "task id"), _u(t.version, 16, "task version"),
                              _KIND_CODES[TaskKind(t.kind)], _STATE_CODES[TaskState(t.state)],
                              _u(t.group, 32, "task group"), _u(t.group_size, 16, "group size"),
                              _finite(t.altitude, "task altitude"), _finite(t.speed, "task speed")))
        out.append(_name(t.name))
        out.append(struct.pack("!H", _u(len(t.points), 16, "point count")))
        for lat, lon, alt in t.points:
            out.append(_POINT.pack(_deg7(lat, "task latitude"), _deg7(lon, "task longitude"),
                                   _i32(alt * 100.0, "task point altitude")))
        if t.tst is None:
            out.append(struct.pack("!I", _NO_TST))
        else:
            tb = t.tst.encode("utf-8")
            out.append(struct.pack("!I", len(tb)) + tb)
    return zlib.compress(b"".join(out), 9)


@dataclass
class _Origin:
    sender: int
    epoch: int
    stamp: float
    pseq: int
    key: bytes | None

    def frame(self, kind: int, body: bytes) -> bytes:
        flags = FLAG_SIGNED if self.key is not None else 0
        data = _HEADER.pack(MAGIC, VERSION, kind, flags, self.sender, self.epoch, self.stamp,
                            self.pseq & 0xFFFFFFFF) + body
        self.pseq += 1
        if self.key is not None:
            return data + sign(self.key, data)
        return data + _CRC.pack(zlib.crc32(data))


def _part_bytes(epoch: int, stamp: float, seq: int, crc: int, index: int, count: int, chunk: bytes) -> bytes:
    return _PART.pack(epoch, stamp, seq, crc, index, count, len(chunk)) + chunk


#: room kept for the header and the longer trailer (a signature)
_OVERHEAD = _HEADER.size + max(_CRC.size, SIG_LEN)


def peek_sender(data: bytes) -> int | None:
    """The sender id in a team-link packet's header (None if it does not look like one), unchecked."""
    if len(data) >= _HEADER.size and data[:2] == MAGIC and data[2] == VERSION:
        return int(_HEADER.unpack_from(data)[4])
    return None


def encode_packets(sender: int, entries: list[MemberEntry] | tuple[MemberEntry, ...],
                   board: TaskBoard | None = None, *, max_size: int = MAX_PACKET, epoch: int = 0,
                   stamp: float = 0.0, pseq: int = 0, key: bytes | None = None,
                   digest: list[DigestEntry] | tuple[DigestEntry, ...] = ()) -> list[bytes]:
    """The packets that carry ``entries`` (and ``board``) from ``sender`` in its boot ``epoch``, each at
    most ``max_size`` bytes: STATE packets with as many rows as fit, the board inline in the last one
    when it fits whole, else BOARD packets with its parts. Each header carries ``stamp`` (the sender's
    clock) and a packet number (``pseq``, ``pseq + 1``, ... : the caller counts them); with ``key`` every
    packet is signed. A ``digest`` (:mod:`.gossip`) rides in the last STATE packet when it fits there,
    else in a DIGEST packet of its own (one packet's header and signature saved each period). Raises
    :class:`WireError` for a value the format cannot carry (a member id over 32 bits, a NaN position, a
    board over 255 parts, a wrong type...)."""
    try:
        _u(sender, 32, "sender id")
        _u(epoch, 64, "epoch")
        _u(pseq, 32, "packet number")
        origin = _Origin(sender, epoch, _finite(stamp, "packet stamp"), pseq, key)
        return _encode_packets(origin, entries, board, max_size, _digest_bytes(digest) if digest else b"")
    except WireError:
        raise
    except (ValueError, TypeError, KeyError, AttributeError, struct.error, OverflowError) as exc:
        raise WireError(f"not encodable ({type(exc).__name__}: {exc})") from exc


def _digest_bytes(entries: list[DigestEntry] | tuple[DigestEntry, ...]) -> bytes:
    if len(entries) > 255:
        raise WireError(f"{len(entries)} digest entries, at most 255")
    return bytes([len(entries)]) + b"".join(
        _DIGEST.pack(_u(e.member, 32, "digest member"), _u(e.epoch, 32, "digest epoch tag"),
                     _u(e.seq, 32, "digest seq"), 1 if e.want else 0) for e in entries)


def _encode_packets(origin: _Origin, entries: list[MemberEntry] | tuple[MemberEntry, ...],
                    board: TaskBoard | None, max_size: int, digest: bytes = b"") -> list[bytes]:
    if max_size < 200:
        raise WireError(f"max_size {max_size} too small (at least 200 bytes)")
    rows = [encode_row(e) for e in entries]
    room = max_size - _OVERHEAD - 2  # n_rows and has_board
    groups: list[list[bytes]] = [[]]
    used = 0
    for r in rows:
        if len(r) > room:
            raise WireError(f"row of member {int.from_bytes(r[:4], 'big')} is {len(r)} bytes, more than a "
                            "packet holds")
        if used + len(r) > room or len(groups[-1]) == 255:
            groups.append([])
            used = 0
        groups[-1].append(r)
        used += len(r)
    inline = b""
    board_bodies: list[bytes] = []
    if board is not None:
        body = encode_board_body(board)
        crc = zlib.crc32(body)
        stamp, seq = _finite(board.stamp, "board stamp"), _u(board.seq, 32, "board seq")
        bepoch = _u(board.epoch, 64, "board epoch")
        if used + _PART.size + len(body) <= room:
            inline = _part_bytes(bepoch, stamp, seq, crc, 0, 1, body)
        else:
            chunk_max = max_size - _OVERHEAD - _PART.size
            chunks = [body[i:i + chunk_max] for i in range(0, len(body), chunk_max)]
            if len(chunks) > 255:
                raise WireError(f"board of {len(body)} compressed bytes needs more than 255 parts")
            board_bodies = [_part_bytes(bepoch, stamp, seq, crc, i, len(chunks), c)
                            for i, c in enumerate(chunks)]
    if len(digest) > room + 1:
        raise WireError(f"digest of {len(digest)} bytes, more than a packet of {max_size} bytes holds")
    digest_inline = bool(digest) and used + len(inline) + len(digest) <= room
    out = []
    for i, g in enumerate(groups):
        last = i == len(groups) - 1
        parts = (_PART_BOARD if last and inline else 0) | (_PART_DIGEST if last and digest_inline else 0)
        tail = bytes([parts]) + (inline if last else b"") + (digest if last and digest_inline else b"")
        out.append(origin.frame(KIND_STATE, bytes([len(g)]) + b"".join(g) + tail))
    out += [origin.frame(KIND_BOARD, b) for b in board_bodies]
    if digest and not digest_inline:
        out.append(origin.frame(KIND_DIGEST, digest))
    return out


def encode_digest(sender: int, entries: list[DigestEntry] | tuple[DigestEntry, ...], *, epoch: int = 0,
                  stamp: float = 0.0, pseq: int = 0, key: bytes | None = None) -> bytes:
    """One DIGEST packet from ``sender`` in its boot ``epoch`` (at most 255 entries, 13 bytes each), framed
    and signed as :func:`encode_packets` does; :class:`WireError` if not encodable."""
    try:
        _u(sender, 32, "sender id")
        _u(epoch, 64, "epoch")
        _u(pseq, 32, "packet number")
        origin = _Origin(sender, epoch, _finite(stamp, "packet stamp"), pseq, key)
        return origin.frame(KIND_DIGEST, _digest_bytes(entries))
    except WireError:
        raise
    except (ValueError, TypeError, struct.error, OverflowError) as exc:
        raise WireError(f"digest not encodable ({type(exc).__name__}: {exc})") from exc


def encode_packet(sender: int, entries: list[MemberEntry] | tuple[MemberEntry, ...],
                  board: TaskBoard | None = None, *, max_size: int = MAX_PACKET, epoch: int = 0,
                  stamp: float = 0.0, pseq: int = 0, key: bytes | None = None) -> bytes:
    """One packet carrying all of ``entries`` (and ``board``); :class:`WireError` if they need more
    than one (use :func:`encode_packets`)."""
    packets = encode_packets(sender, entries, board, max_size=max_size, epoch=epoch, stamp=stamp, pseq=pseq,
                             key=key)
    if len(packets) != 1:
        raise WireError(f"{len(entries)} rows{' and the board' if board else ''} need {len(packets)} "
                        f"packets of at most {max_size} bytes; use encode_packets")
    return packets[0]


# ---------------------------------------------------------------------------------------------- decoding

class _Reader:
    def __init__(self, data: bytes, start: int, end: int) -> None:
        self.data, self.pos, self.end = data, start, end

    def take(self, n: int, what: str) -> bytes:
        if self.pos + n > self.end:
            raise WireError(f"truncated in {what} (needs {n} bytes at offset {self.pos}, "
                            f"{self.end - self.pos} left)")
        b = self.data[self.pos:self.pos + n]
        self.pos += n
        return b

    def unpack(self, s: struct.Struct, what: str) -> tuple:
        return s.unpack(self.take(s.size, what))

    def u8(self, what: str) -> int:
        return self.take(1, what)[0]

    def text(self, n: int, what: str) -> str:
        try:
            return self.take(n, what).decode("utf-8")
        except UnicodeDecodeError as exc:
            raise WireError(f"{what} is not utf-8") from exc

    def name(self, what: str) -> str:
        n = self.u8(what)
        if n > NAME_MAX:
            raise WireError(f"{what} length {n} over {NAME_MAX}")
        return self.text(n, what)


def _status(code: int) -> MemberStatus:
    try:
        return MemberStatus(code)
    except ValueError as exc:
        raise WireError(f"unknown member status {code}") from exc


def _claim_state(code: int) -> ClaimState:
    try:
        return ClaimState(code)
    except ValueError as exc:
        raise WireError(f"unknown claim state {code}") from exc


def _finite_in(x: float, what: str) -> float:
    if not math.isfinite(x):
        raise WireError(f"{what} is not finite")
    return x


def _read_row(r: _Reader) -> MemberEntry:
    (member, epoch, stamp, seq, lat, lon, alt, vn, ve, vd, status, task, voc) = r.unpack(_ROW, "row")
    name = r.name("member name")
    claims = []
    for _ in range(r.u8("claim count")):
        ct, cv, cost, cs = r.unpack(_CLAIM, "claim")
        claims.append(Claim(task=ct, version=cv, cost=_finite_in(cost, "claim cost"), state=_claim_state(cs)))
    return MemberEntry(member=member, epoch=epoch, stamp=_finite_in(stamp, "stamp"), seq=seq,
                       position=(lat / 1e7, lon / 1e7, alt / 100.0),
                       velocity=(vn / 100.0, ve / 100.0, vd / 100.0),
                       status=_status(status), task=task, claims=tuple(claims), voc=voc, name=name)


def _read_part(r: _Reader) -> BoardPart:
    epoch, stamp, seq, crc, index, count, n = r.unpack(_PART, "board part")
    if count == 0 or index >= count:
        raise WireError(f"board part {index} of {count}")
    return BoardPart(epoch=epoch, stamp=_finite_in(stamp, "board stamp"), seq=seq, body_crc=crc, index=index,
                     count=count, chunk=r.take(n, "board chunk"))


def decode_packet(data: bytes, *, key: bytes | None = None) -> Packet:
    """The packet in ``data``; :class:`WireError` (never another exception) when it is not one. With
    ``key`` only a packet signed with that key is taken (:class:`UnsignedError`,
    :class:`BadSignatureError`); without, a signed packet is :class:`UnverifiableError`."""
    try:
        return _decode(data, key)
    except WireError:
        raise
    except Exception as exc:  # a guard: any slip in the parser is still a counted drop, not a crash
        raise WireError(f"undecodable packet ({type(exc).__name__}: {exc})") from exc


def _decode(data: bytes, key: bytes | None) -> Packet:
    if not isinstance(data, bytes | bytearray | memoryview):
        raise WireError(f"not bytes: {type(data).__name__}")
    data = bytes(data)
    if len(data) >= 3 and data[:2] == MAGIC and data[2] != VERSION:
        raise ForeignVersionError(data[2])
    if len(data) < _HEADER.size + _CRC.size:
        raise WireError(f"truncated: {len(data)} bytes, shorter than a header and CRC "
                        f"({_HEADER.size + _CRC.size})")
    magic, _version, code, flags, sender, epoch, stamp, pseq = _HEADER.unpack_from(data)
    if magic != MAGIC:
        raise WireError(f"bad magic {magic!r} (not a team-link packet)")
    if flags & ~FLAG_SIGNED:
        raise WireError(f"unknown header flags {flags:#x}")
    signed = bool(flags & FLAG_SIGNED)
    if signed:
        if len(data) < _HEADER.size + SIG_LEN:
            raise WireError("truncated: shorter than a header and a signature")
        if key is None:
            raise UnverifiableError("a signed packet and no team key to check it")
        if not hmac.compare_digest(sign(key, data[:-SIG_LEN]), data[-SIG_LEN:]):
            raise BadSignatureError("bad signature (forged, modified, or signed with another key)")
        end = len(data) - SIG_LEN
    else:
        if key is not None:
            raise UnsignedError("an unsigned packet and a team key is configured")
        (crc,) = _CRC.unpack_from(data, len(data) - _CRC.size)
        if zlib.crc32(data[:-_CRC.size]) != crc:
            raise WireError("bad CRC (corrupt or truncated packet)")
        end = len(data) - _CRC.size
    r = _Reader(data, _HEADER.size, end)
    digest: tuple[DigestEntry, ...] = ()
    if code == KIND_STATE:
        rows = tuple(_read_row(r) for _ in range(r.u8("row count")))
        parts = r.u8("parts flags")
        if parts & ~(_PART_BOARD | _PART_DIGEST):
            raise WireError(f"parts flags {parts:#x}")
        part = _read_part(r) if parts & _PART_BOARD else None
        if parts & _PART_DIGEST:
            digest = _read_digest_list(r)
    elif code == KIND_BOARD:
        rows, part = (), _read_part(r)
    elif code == KIND_DIGEST:
        rows, part = (), None
        digest = _read_digest_list(r)
    else:
        raise WireError(f"unknown packet kind {code}")
    if r.pos != r.end:
        raise WireError(f"{r.end - r.pos} trailing bytes")
    return Packet(sender=sender, kind=code, rows=rows, board_part=part, epoch=epoch,
                  stamp=_finite_in(stamp, "packet stamp"), pseq=pseq, signed=signed,
                  digest=digest)


def _read_digest_list(r: _Reader) -> tuple[DigestEntry, ...]:
    return tuple(_read_digest(r) for _ in range(r.u8("digest count")))


def _read_digest(r: _Reader) -> DigestEntry:
    member, epoch, seq, want = _DIGEST.unpack(r.take(_DIGEST.size, "digest entry"))
    if want not in (0, 1):
        raise WireError(f"digest want flag {want}")
    return DigestEntry(member, epoch, seq, bool(want))


def decode_board_body(body: bytes, stamp: float, seq: int, body_crc: int, epoch: int = 0) -> TaskBoard:
    """The board from its compressed body (checked against ``body_crc``); :class:`WireError` if bad."""
    try:
        return _decode_board(body, stamp, seq, body_crc, epoch)
    except WireError:
        raise
    except Exception as exc:
        raise WireError(f"undecodable board ({type(exc).__name__}: {exc})") from exc


def _decode_board(body: bytes, stamp: float, seq: int, body_crc: int, epoch: int) -> TaskBoard:
    if zlib.crc32(body) != body_crc:
        raise WireError("board body CRC mismatch")
    d = zlib.decompressobj()
    try:
        raw = d.decompress(body, BOARD_BODY_MAX)
    except zlib.error as exc:
        raise WireError(f"board body does not decompress: {exc}") from exc
    if d.unconsumed_tail or not d.eof:
        raise WireError("board body over the size limit or incomplete")
    r = _Reader(raw, 0, len(raw))
    (n,) = r.unpack(struct.Struct("!H"), "task count")
    tasks = []
    for _ in range(n):
        tid, ver, kind, state, group, gsize, altitude, speed = r.unpack(_TASK, "task")
        if kind not in _KINDS:
            raise WireError(f"unknown task kind {kind}")
        if state not in _STATES:
            raise WireError(f"unknown task state {state}")
        name = r.name("task name")
        (npts,) = r.unpack(struct.Struct("!H"), "point count")
        pts: list[GeoPoint] = []
        for _ in range(npts):
            lat, lon, alt = r.unpack(_POINT, "task point")
            pts.append((lat / 1e7, lon / 1e7, alt / 100.0))
        (tlen,) = r.unpack(struct.Struct("!I"), "tst length")
        tst = None if tlen == _NO_TST else r.text(tlen, "tst text")
        tasks.append(TeamTask(id=tid, version=ver, kind=_KINDS[kind], points=tuple(pts), state=_STATES[state],
                              group=group, group_size=gsize, altitude=_finite_in(altitude, "task altitude"),
                              speed=_finite_in(speed, "task speed"), tst=tst, name=name))
    if r.pos != r.end:
        raise WireError(f"{r.end - r.pos} trailing bytes in the board body")
    return TaskBoard(stamp=stamp, seq=seq, tasks=tuple(tasks), epoch=epoch)


class BoardAssembler:
    """Joins a board's parts (from any senders carrying the same body) into a :class:`TaskBoard`.

    Keeps at most ``pending`` boards in assembly (the oldest dropped first)."""

    def __init__(self, pending: int = 4) -> None:
        self._pending = pending
        self._parts: OrderedDict[tuple[int, float, int, int, int], dict[int, bytes]] = OrderedDict()

    def add(self, part: BoardPart) -> TaskBoard | None:
        """The board once ``part`` completes it (else None); :class:`WireError` if the joined body is bad."""
        if part.count == 1:
            return decode_board_body(part.chunk, part.stamp, part.seq, part.body_crc, part.epoch)
        key = (part.epoch, part.stamp, part.seq, part.body_crc, part.count)
        got = self._parts.get(key)
        if got is None:
            got = self._parts[key] = {}
            while len(self._parts) > self._pending:
                self._parts.popitem(last=False)
        got[part.index] = part.chunk
        if len(got) < part.count:
            return None
        del self._parts[key]
        body = b"".join(got[i] for i in range(part.count))
        return decode_board_body(body, part.stamp, part.seq, part.body_crc, part.epoch)
