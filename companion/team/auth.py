"""Authentication of the team link (issue: a team link fit for the field), after MAVLink 2 signing.

MAVLink 2 signs each frame with the first 48 bits of SHA-256 over a shared secret key, the frame and a
48-bit time stamp, and a receiver keeps, per sender stream, the last time stamp it took, so a replayed
frame is refused. The team link does the same at the packet level (:mod:`.wire`, so every transport that
carries the encoded packets is covered): a packet's header names its sender, the sender's boot epoch, the
sender's clock and a packet number that counts up within the epoch; with a team key the packet ends with
the first :data:`SIG_LEN` bytes of HMAC-SHA256(key, header + body). :class:`ReplayGuard` keeps, per
(sender, epoch), the highest packet number taken and a window of the :data:`REPLAY_WINDOW` before it
(as IPsec's anti-replay window: UDP may reorder a little), and refuses a packet whose stamp is more than
:data:`FUTURE_WINDOW_S` ahead of the *team's clock* (a clock ten years ahead changes nothing). Stamps in
the past are taken: a companion without a real-time clock boots with its clock behind, and freshness is
(epoch, seq), not time (:mod:`.groupstate`). The team's clock is this receiver's clock plus the lower
median of the offsets (stamp - own clock) of the members heard in the last :data:`OFFSET_MEMORY_S`, its
own offset 0 included, when that median is ahead: a member whose clock is an hour behind sees every
other member an hour ahead and takes them (the majority is ahead), while a fleet that hears one member
ten years ahead keeps its own clock (the lower median is the fleet's). With two parties only the lower
one wins (a member behind waits for a third, e.g. the station).

The key is a file (``--team-key FILE`` or ``TASKFLIGHT_TEAM_KEY=FILE``) holding a secret of at least 16
bytes (``taskflight up`` writes 32 random bytes in hex, mode 0600); the HMAC key is SHA-256 of its
stripped contents, as MAVLink derives its key from a passphrase. Known limit: a receiver that has never
heard a (sender, epoch) takes its packets, so a recording of an earlier boot replayed to a receiver that
started after it is taken as that boot, until the real member's current epoch is heard (the identity rule
of :mod:`.groupstate` then keeps the live one); it changes no board (the board follows the station's live
epoch).
"""

from __future__ import annotations

import hashlib
import hmac
import ipaddress
import logging
import os
import secrets
from collections import OrderedDict
from pathlib import Path
from urllib.parse import parse_qsl, urlsplit

log = logging.getLogger(__name__)

#: bytes of the truncated HMAC-SHA256 signature at the end of a signed packet
SIG_LEN = 16
#: a packet stamped further ahead of the receiver's clock than this is refused (s)
FUTURE_WINDOW_S = 30.0
#: packet numbers below the highest one taken from a stream that are still accepted (once each)
REPLAY_WINDOW = 64
#: how long a member's clock offset counts toward the team's clock (s of the receiver's clock)
OFFSET_MEMORY_S = 10.0
#: the environment variable naming the key file when ``--team-key`` is not given
ENV_KEY = "TASKFLIGHT_TEAM_KEY"
_MIN_SECRET = 16


def sign(key: bytes, data: bytes) -> bytes:
    """The signature of ``data`` under ``key``: the first :data:`SIG_LEN` bytes of HMAC-SHA256."""
    return hmac.new(key, data, hashlib.sha256).digest()[:SIG_LEN]


def load_key(path: str | os.PathLike[str]) -> bytes:
    """The HMAC key from the key file ``path`` (SHA-256 of its stripped contents); ValueError naming the
    file when it is missing, unreadable or holds fewer than 16 bytes."""
    p = Path(path)
    try:
        secret = p.read_bytes().strip()
    except OSError as exc:
        raise ValueError(f"team key file {str(p)!r}: {exc.strerror or exc}") from exc
    if len(secret) < _MIN_SECRET:
        raise ValueError(f"team key file {str(p)!r}: holds {len(secret)} bytes, at least {_MIN_SECRET} "
                         "needed")
    try:
        if p.stat().st_mode & 0o077:
            log.warning("team key file %s is readable by other users (chmod 600 it)", p)
    except OSError:
        pass
    return hashlib.sha256(secret).digest()


def key_path(arg: str | None) -> str | None:
    """The key file given (``--team-key``) or named by ``TASKFLIGHT_TEAM_KEY``; None for neither."""
    return arg or os.environ.get(ENV_KEY) or None


def team_key(arg: str | None) -> bytes | None:
    """The key of ``--team-key`` (or the environment), None without one; ValueError for a bad file."""
    path = key_path(arg)
    return load_key(path) if path else None


def generate_key_file(path: str | os.PathLike[str]) -> Path:
    """A new key file at ``path`` (32 random bytes in hex, mode 0600), or the one there if it is valid."""
    p = Path(path)
    if p.exists():
        load_key(p)
        return p
    p.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(p, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(secrets.token_hex(32) + "\n")
    return p


def is_local(url: str) -> bool:
    """Does the team URL stay on this host (``mem://``, or an ``iface`` on loopback)?"""
    try:
        u = urlsplit(url)
        if u.scheme.lower() == "mem":
            return True
        iface = dict(parse_qsl(u.query)).get("iface")
        if iface is None and u.scheme.lower().startswith("zenoh"):
            host = u.hostname or ""
            return host in ("127.0.0.1", "localhost")
        return iface is not None and ipaddress.ip_address(iface).is_loopback
    except ValueError:
        return False


def warn_if_unauthenticated(url: str, key: bytes | None, who: str) -> bool:
    """Log a warning when a team runs without a key beyond this host; True when it warned."""
    if key is None and not is_local(url):
        log.warning("%s: the team link %s runs UNAUTHENTICATED beyond this host: anyone on the network can "
                    "forge rows and task boards; give --team-key FILE (or %s=FILE)", who, url, ENV_KEY)
        return True
    return False


class ReplayGuard:
    """Per (sender, epoch) replay window and the future-stamp window (module doc). ``streams`` bounds
    the streams remembered (the least recently heard forgotten first)."""

    def __init__(self, *, window: int = REPLAY_WINDOW, future_s: float = FUTURE_WINDOW_S,
                 streams: int = 4096) -> None:
        self.window, self.future_s, self.streams = window, future_s, streams
        self._seen: OrderedDict[tuple[int, int], tuple[int, int]] = OrderedDict()  # -> (highest, mask)
        self._offsets: OrderedDict[int, tuple[float, float]] = OrderedDict()  # sender -> (offset, heard at)
        self._team_offset = 0.0
        self._computed_at = -float("inf")

    def team_offset(self, now: float) -> float:
        """How far the team's clock is ahead of ``now`` (0 when it is not ahead): the lower median of the
        recent senders' offsets and 0 (this receiver's own), recomputed at most every half second."""
        if abs(now - self._computed_at) >= 0.5:
            recent = [off for off, at in self._offsets.values() if 0.0 <= now - at <= OFFSET_MEMORY_S]
            values = sorted([0.0, *recent])
            self._team_offset = max(0.0, values[(len(values) - 1) // 2])
            self._computed_at = now
        return self._team_offset

    def observe(self, sender: int, stamp: float, now: float) -> None:
        """A verified packet from ``sender`` stamped ``stamp`` heard at ``now``: one voice for the team's
        clock (the latest per sender)."""
        self._offsets[sender] = (stamp - now, now)
        self._offsets.move_to_end(sender)
        while len(self._offsets) > self.streams:
            self._offsets.popitem(last=False)

    def future(self, stamp: float, now: float) -> bool:
        """Is ``stamp`` too far ahead of the team's clock?"""
        return stamp > now + self.team_offset(now) + self.future_s

    def check(self, sender: int, epoch: int, pseq: int, stamp: float, now: float, *,
              replay: bool = True, voice: bool = True) -> str | None:
        """None when the packet may be taken (and it is recorded as taken), else why not: "future" or
        "replayed" (a packet number already taken, or older than the window). Its stamp counts toward
        the team's clock either way (unless not ``voice``: this receiver's own packets)."""
        if voice:
            self.observe(sender, stamp, now)
        if self.future(stamp, now):
            return "future"
        if not replay:
            return None
        key = (sender, epoch)
        got = self._seen.get(key)
        if got is None:
            self._seen[key] = (pseq, 1)
            while len(self._seen) > self.streams:
                self._seen.popitem(last=False)
            return None
        self._seen.move_to_end(key)
        high, mask = got
        if pseq > high:
            shift = pseq - high
            mask = ((mask << shift) | 1) & ((1 << self.window) - 1) if shift < self.window else 1
            self._seen[key] = (pseq, mask)
            return None
        back = high - pseq
        if back >= self.window or mask & (1 << back):
            return "replayed"
        self._seen[key] = (high, mask | (1 << back))
        return None
