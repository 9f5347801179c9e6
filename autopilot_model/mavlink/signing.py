"""MAVLink 2 message signing for the autopilot model's endpoint.

With a secret key configured, an incoming packet is acted on only if it carries a valid signature
whose timestamp moves its stream forward; everything else is dropped and counted. Outgoing packets
are signed with the same key (pymavlink does the signing when ``mav.signing.sign_outgoing`` is set).

The key is 32 bytes. MAVProxy's ``signing setup PASSPHRASE`` derives it as ``sha256(passphrase)``;
:func:`key_from_passphrase` does the same so that a MAVProxy or pymavlink ground station configured
with the same passphrase talks to the model.

The check is done here rather than by pymavlink's own ``check_signature`` because pymavlink records
a stream's timestamp *before* it compares the signature, so one forged packet with a timestamp in the
far future would lock the genuine sender out. Here the signature is verified first.
"""

from __future__ import annotations

import hashlib
import hmac
import struct
import time
from dataclasses import dataclass, field

#: MAVLink signing timestamps count 10 microsecond units since 2015-01-01 00:00:00 UTC.
SIGNING_EPOCH_UNIX_S = 1420070400
SIGNATURE_LEN = 13  # link id (1), timestamp (6), signature (6)
#: A new stream may start at most one minute behind our own timestamp (MAVLink signing spec).
NEW_STREAM_WINDOW = 60 * 100_000


def key_from_passphrase(passphrase: str) -> bytes:
    """The 32-byte secret key MAVProxy's ``signing setup`` derives from a passphrase."""
    return hashlib.sha256(passphrase.encode("utf-8")).digest()


def parse_key(text: str) -> bytes:
    """A key given on the command line: 64 hex digits, or else a passphrase."""
    t = text.strip()
    if len(t) == 64:
        try:
            return bytes.fromhex(t)
        except ValueError:
            pass
    return key_from_passphrase(text)


def wall_timestamp() -> int:
    """Current signing timestamp (10 us units since 2015) from the wall clock.

    Signing timestamps are wall (UTC) time by the MAVLink specification, not simulated time: a
    signed link must keep working when the simulation restarts at time zero.
    """
    return max(0, int((time.time() - SIGNING_EPOCH_UNIX_S) * 100_000))


@dataclass
class SigningStats:
    """Counters of the signature check."""

    accepted: int = 0
    unsigned_rejected: int = 0
    bad_signature: int = 0
    replayed: int = 0

    def as_dict(self) -> dict[str, int]:
        return dict(self.__dict__)


@dataclass
class Signing:
    """Verifies incoming signatures; configures a pymavlink encoder to sign outgoing packets."""

    key: bytes | None = None
    link_id: int = 0
    stats: SigningStats = field(default_factory=SigningStats)
    _streams: dict[tuple[int, int, int], int] = field(default_factory=dict)
    _timestamp: int = 0

    def __post_init__(self) -> None:
        if self.key is not None and len(self.key) != 32:
            raise ValueError("a MAVLink signing key is 32 bytes")
        self._timestamp = wall_timestamp()

    @property
    def enabled(self) -> bool:
        return self.key is not None

    def set_key(self, key: bytes | None) -> None:
        if key is not None and len(key) != 32:
            raise ValueError("a MAVLink signing key is 32 bytes")
        self.key = key
        self._streams.clear()

    def raise_timestamp(self, timestamp: int) -> None:
        """Move our signing timestamp forward to ``timestamp`` (SETUP_SIGNING's initial timestamp)."""
        self._timestamp = max(self._timestamp, timestamp)

    def configure_encoder(self, mav: object) -> None:
        """Make a pymavlink ``MAVLink`` object sign what it packs (or stop signing)."""
        sig = mav.signing  # type: ignore[attr-defined]
        sig.secret_key = self.key
        sig.sign_outgoing = self.key is not None
        sig.link_id = self.link_id
        sig.timestamp = max(sig.timestamp, wall_timestamp(), self._timestamp)

    def accept(self, frame: bytes | bytearray | memoryview, signed: bool, sysid: int, compid: int) -> bool:
        """Whether a received frame (whole, signature included) may be acted on.

        Always true without a key. With one: the frame must be signed, its signature must match, and
        its timestamp must be newer than the last one seen on the same (link id, system, component)
        stream (replay protection).
        """
        if self.key is None:
            return True
        if not signed:
            self.stats.unsigned_rejected += 1
            return False
        sig_block = bytes(frame[-SIGNATURE_LEN:])
        link_id = sig_block[0]
        lo, hi = struct.unpack_from("<IH", sig_block, 1)
        timestamp = lo | (hi << 32)
        digest = hashlib.sha256(self.key + bytes(frame[:-6])).digest()[:6]
        if not hmac.compare_digest(digest, sig_block[7:]):
            self.stats.bad_signature += 1
            return False
        key = (link_id, sysid, compid)
        last = self._streams.get(key)
        if last is not None:
            if timestamp <= last:
                self.stats.replayed += 1
                return False
        else:
            now = max(self._timestamp, wall_timestamp())
            if timestamp + NEW_STREAM_WINDOW < now:
                self.stats.replayed += 1
                return False
        self._streams[key] = timestamp
        self._timestamp = max(self._timestamp, timestamp)
        self.stats.accepted += 1
        return True
