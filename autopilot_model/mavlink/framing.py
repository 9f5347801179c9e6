"""Turning received bytes into MAVLink messages, robustly and fast.

A :class:`FrameParser` belongs to one peer (one UDP sender or one TCP client). It finds MAVLink 1
(0xFE) and MAVLink 2 (0xFD) frames in the bytes it is fed, checks length, incompatibility flags and
CRC (with the dialect's CRC_EXTRA), hands signed frames to the :class:`~.signing.Signing` check and
decodes the payload into pymavlink ``ardupilotmega`` message objects (MAVLink 2 zero-truncated
payloads are padded back). Nothing it is fed can raise: garbage bytes, truncated frames, bad CRCs,
unknown message ids and rejected signatures are skipped and counted in the ``stats`` dict it shares
with the endpoint.

It does the work of pymavlink's ``MAVLink.parse_buffer`` at roughly a third of the cost (no
per-byte state machine, CRC by ``fastcrc`` when installed), which matters for the flood bench.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, MutableMapping
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from .signing import SIGNATURE_LEN, Signing

_mcrf4xx: Callable[[bytes, int | None], int] | None
try:  # pymavlink's own CRC picks fastcrc when present; so do we.
    from fastcrc.crc16 import mcrf4xx as _mcrf4xx
except Exception:  # pragma: no cover - the pure Python fallback
    _mcrf4xx = None

STX_V1 = 0xFE
STX_V2 = 0xFD
HDR_V1 = 6
HDR_V2 = 10
IFLAG_SIGNED = 0x01
_MAP: dict[int, Any] = mavlink2.mavlink_map
_Header = mavlink2.MAVLink_header
_MAX_TCP_BUFFER = 1 << 16
_PLAIN: dict[Any, bool] = {}  # message class -> has no array fields


def _crc_slow(data: bytes | bytearray | memoryview, crc: int = 0xFFFF) -> int:
    for b in bytes(data):
        tmp = b ^ (crc & 0xFF)
        tmp = (tmp ^ (tmp << 4)) & 0xFF
        crc = (crc >> 8) ^ (tmp << 8) ^ (tmp << 3) ^ (tmp >> 4)
    return crc & 0xFFFF


def crc_x25(data: bytes | bytearray | memoryview, crc: int = 0xFFFF) -> int:
    """MAVLink's CRC-16/MCRF4XX."""
    if _mcrf4xx is not None:
        return _mcrf4xx(bytes(data), crc)
    return _crc_slow(data, crc)


def _decode_payload(msgtype: Any, payload: bytes) -> Any:
    """Build the pymavlink message object from a (possibly zero-truncated) payload."""
    size = msgtype.unpacker.size
    if len(payload) < size:
        payload = payload + bytes(size - len(payload))
    elif len(payload) > size:
        payload = payload[:size]
    t = msgtype.unpacker.unpack(payload)
    lengths = msgtype.lengths
    orders = msgtype.orders
    plain = _PLAIN.get(msgtype)
    if plain is None:
        plain = _PLAIN[msgtype] = sum(lengths) == len(lengths)
    if plain:
        args = [t[o] for o in orders]
    else:
        args = []
        for order in orders:
            n = lengths[order]
            tip = sum(lengths[:order])
            fld = t[tip]
            if n == 1 or isinstance(fld, bytes):
                args.append(fld)
            else:
                args.append(list(t[tip:tip + n]))
    for i, a in enumerate(args):
        if isinstance(a, bytes):
            args[i] = a.rstrip(b"\x00")
    return msgtype(*args)


class FrameParser:
    """Frame finder, checker and decoder for one peer's byte stream or datagrams."""

    def __init__(self, stats: MutableMapping[str, int], signing: Signing | None = None,
                 stream: bool = False) -> None:
        self.stats = stats
        self.signing = signing
        self.stream = stream  # TCP: keep an incomplete tail for the next call
        self._tail = b""

    def feed(self, data: bytes) -> list[Any]:
        """Parse ``data`` (one datagram, or the next chunk of a TCP stream); return the messages."""
        if self._tail:
            data = self._tail + data
            self._tail = b""
        out: list[Any] = []
        stats = self.stats
        n = len(data)
        i = 0
        while i < n:
            b0 = data[i]
            if b0 != STX_V2 and b0 != STX_V1:
                # skip a run of garbage up to the next possible start byte
                j = i + 1
                while j < n and data[j] != STX_V2 and data[j] != STX_V1:
                    j += 1
                stats["garbage"] += 1
                i = j
                continue
            hdr = HDR_V2 if b0 == STX_V2 else HDR_V1
            if n - i < hdr + 2:
                self._incomplete(data, i)
                break
            plen = data[i + 1]
            if b0 == STX_V2:
                iflags = data[i + 2]
                if iflags & ~IFLAG_SIGNED:
                    stats["garbage"] += 1
                    i += 1
                    continue
                signed = bool(iflags & IFLAG_SIGNED)
                seq, sysid, compid = data[i + 4], data[i + 5], data[i + 6]
                msgid = data[i + 7] | (data[i + 8] << 8) | (data[i + 9] << 16)
            else:
                iflags = 0
                signed = False
                seq, sysid, compid, msgid = data[i + 2], data[i + 3], data[i + 4], data[i + 5]
            total = hdr + plen + 2 + (SIGNATURE_LEN if signed else 0)
            if n - i < total:
                self._incomplete(data, i)
                break
            msgtype = _MAP.get(msgid)
            if msgtype is None:
                stats["unknown"] += 1
                i += total
                continue
            end_payload = i + hdr + plen
            crc = crc_x25(data[i + 1:end_payload])
            crc = crc_x25(bytes((msgtype.crc_extra,)), crc)
            if crc != (data[end_payload] | (data[end_payload + 1] << 8)):
                stats["bad_crc"] += 1
                i += 1  # resynchronise just after this false start byte
                continue
            frame = data[i:i + total]
            i += total
            if self.signing is not None and self.signing.enabled and not self.signing.accept(
                    frame, signed, sysid, compid):
                stats["bad_signature"] += 1
                continue
            try:
                msg = _decode_payload(msgtype, data[i - total + hdr:end_payload])
            except (struct.error, TypeError, ValueError, UnicodeDecodeError):  # pragma: no cover
                stats["undecodable"] += 1
                continue
            msg._header = _Header(msgid, iflags, 0, plen, seq, sysid, compid)
            msg._msgbuf = frame
            msg._signed = signed
            out.append(msg)
        return out

    def _incomplete(self, data: bytes, i: int) -> None:
        if self.stream and len(data) - i < _MAX_TCP_BUFFER:
            self._tail = data[i:]
        else:
            self.stats["truncated"] += 1
