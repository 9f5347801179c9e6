"""Transports of the team link (seed 003 Sec. III-A: a broadcast, low-bandwidth, lossy channel).

* :class:`UdpTransport`: UDP multicast (default group 239.255.70.1, TTL 1, loopback on so several
  members on one host hear each other, SO_REUSEADDR + SO_REUSEPORT so they share the port) or UDP
  broadcast. A member hears its own packets once (the link drops them by sender id). The members of one
  process share one socket and one receive thread per group (:mod:`companion.team.udp_shared`).
* :class:`MemoryBus` / :class:`MemoryTransport`: many members in one process (the team simulator);
  delivery is immediate and in order, so a run stepped in simulated time is deterministic.
* :class:`LossyTransport`: wraps another transport and drops a seeded fraction of the packets it
  receives and, given a range and the members' positions, every packet from a member farther than the
  range (a radio's reach); each receiver drops independently, as each radio link fades independently.
* :func:`open_transport`: ``udp://239.255.70.1:14650`` (multicast), ``udp://255.255.255.255:14650`` or
  ``bcast://HOST:PORT`` (broadcast), ``mem://NAME`` (a named in-process bus), ``zenoh:`` /
  ``zenoh:tcp/HOST:PORT`` (the fleet bus on Zenoh, :mod:`companion.team.zenoh_transport`: peers and
  routers route, no flooding needed), with query options ``loss``, ``seed``, ``range`` (m), ``iface`` (the
  interface address; by default the one of the default route, :func:`default_iface`, loopback only when
  there is none), ``ttl``; ``team`` and ``mode`` for ``zenoh:``.

Which to choose (docs/team.md, "Which transport"): ``zenoh:`` on a LAN, ``zenoh:tcp/ROUTER:7447`` across
subnets or hosts with a router (``taskflight router``), ``udp://`` for a radio with no IP routing (the
paper's raw broadcast with controlled flooding).
"""

from __future__ import annotations

import abc
import collections
import ipaddress
import logging
import math
import random
import socket
import struct
import threading
from collections.abc import Callable
from typing import ClassVar
from urllib.parse import parse_qsl, urlsplit

from companion.team.types import GeoPoint
from companion.team.udp_shared import Key, SharedGroupSocket
from companion.team.wire import peek_sender

log = logging.getLogger(__name__)

DEFAULT_GROUP = "239.255.70.1"
DEFAULT_PORT = 14650
#: datagrams a UdpTransport read with :meth:`~UdpTransport.recv` keeps before dropping the oldest
PULL_QUEUE = 4096
_EARTH_R = 6371008.8


class Transport(abc.ABC):
    """A broadcast datagram channel: what one member sends, the others may receive."""

    @abc.abstractmethod
    def send(self, data: bytes) -> None:
        """Send one datagram to every member (OSError when the network refuses it)."""

    @abc.abstractmethod
    def recv(self, timeout_s: float) -> bytes | None:
        """The next datagram, waiting up to ``timeout_s`` (0: do not wait); None when none came."""

    @abc.abstractmethod
    def close(self) -> None:
        """Release the channel (idempotent)."""

    @property
    @abc.abstractmethod
    def url(self) -> str:
        """The URL that opens this transport."""

    def subscribe(self, callback: Callable[[bytes], None]) -> bool:
        """Hand every datagram received from now on to ``callback`` (from a thread of the transport's)
        instead of queueing it for :meth:`recv`; False (nothing changed) when this transport cannot."""
        return False


#: a public address toward which the default route is looked up (no packet is sent to it)
_ROUTE_PROBE = ("8.8.8.8", 53)


def default_iface() -> str:
    """The IPv4 address of the interface of the default route, found without sending anything: a UDP
    socket ``connect()``-ed to a public address and its ``getsockname()``; 127.0.0.1 when there is no
    default route (the kernel refuses the connect)."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        s.connect(_ROUTE_PROBE)
        addr = s.getsockname()[0]
    except OSError:
        return "127.0.0.1"
    finally:
        s.close()
    return addr if addr and addr != "0.0.0.0" else "127.0.0.1"


class UdpTransport(Transport):
    """UDP multicast (a multicast ``group``) or broadcast (``broadcast=True``, ``group`` the broadcast
    address) on ``port``; ``iface`` is the address of the interface to use (None: the default route's,
    :func:`default_iface`, logged; 127.0.0.1: loopback, one host only)."""

    def __init__(self, group: str = DEFAULT_GROUP, port: int = DEFAULT_PORT, *, iface: str | None = None,
                 broadcast: bool = False, ttl: int = 1) -> None:
        defaulted = iface is None
        if iface is None:
            iface = default_iface()
            log.info("team link %s:%d: interface %s (%s; ?iface=ADDR chooses another)", group, port, iface,
                     "no default route: loopback, this host only" if iface == "127.0.0.1"
                     else "the default route's")
        try:
            addr = ipaddress.IPv4Address(group)
            ipaddress.IPv4Address(iface)
        except ValueError as exc:
            raise ValueError(f"UdpTransport: bad address: {exc}") from exc
        if not 0 < port < 65536:
            raise ValueError(f"UdpTransport: port {port} outside 1..65535")
        if not broadcast and not addr.is_multicast:
            raise ValueError(f"UdpTransport: {group} is not a multicast group (use broadcast=True)")
        self.group, self.port, self.iface, self.broadcast, self.ttl = group, port, iface, broadcast, ttl
        self._closed = False
        self._queue: collections.deque[bytes] = collections.deque(maxlen=PULL_QUEUE)
        self._cond = threading.Condition()
        try:
            self._shared = SharedGroupSocket.acquire(self._key(), self._open)
        except OSError as exc:
            if not defaulted or broadcast or iface == "127.0.0.1":
                raise
            log.warning("team link %s:%d: the default route's interface %s refuses multicast (%s): loopback "
                        "instead, this host only (give ?iface=ADDR)", group, port, iface, exc)
            self.iface = "127.0.0.1"
            self._shared = SharedGroupSocket.acquire(self._key(), self._open)
        self._shared.subscribe(id(self), self._enqueue)

    def _key(self) -> Key:
        return (self.group, self.port, self.iface, self.broadcast, self.ttl)

    def _open(self) -> socket.socket:
        group, port, iface, broadcast, ttl = self.group, self.port, self.iface, self.broadcast, self.ttl
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM, socket.IPPROTO_UDP)
        try:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            if hasattr(socket, "SO_REUSEPORT"):
                s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
            if broadcast:
                s.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
                s.bind(("", port))
            else:
                s.bind((group, port))  # only this group's datagrams reach the socket
                mreq = struct.pack("4s4s", socket.inet_aton(group), socket.inet_aton(iface))
                s.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, mreq)
                s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton(iface))
                s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, ttl)
                s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
            s.setblocking(False)
        except OSError:
            s.close()
            raise
        return s

    @property
    def url(self) -> str:
        scheme = "bcast" if self.broadcast else "udp"
        return f"{scheme}://{self.group}:{self.port}?iface={self.iface}"

    def send(self, data: bytes) -> None:
        if self._closed:
            raise OSError("UdpTransport closed")
        self._shared.send(data)

    def _enqueue(self, data: bytes) -> None:
        with self._cond:
            self._queue.append(data)  # full: the oldest goes, as a full socket buffer drops
            self._cond.notify()

    def subscribe(self, callback: Callable[[bytes], None]) -> bool:
        """Push mode: the process's receive thread for this group calls ``callback`` with each datagram
        (:mod:`companion.team.udp_shared`); :meth:`recv` then only waits."""
        if self._closed:
            return False
        self._shared.subscribe(id(self), callback)
        return True

    def recv(self, timeout_s: float) -> bytes | None:
        with self._cond:
            if not self._queue and timeout_s > 0 and not self._closed:
                self._cond.wait(timeout_s)  # pushed: nothing is queued, this only waits
            return self._queue.popleft() if self._queue else None

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self._shared.unsubscribe(id(self))
            self._shared.release()
            with self._cond:
                self._cond.notify_all()


class MemoryBus:
    """An in-process broadcast medium: every datagram sent by one attached transport is queued at all the
    others, at once and in order. ``MemoryBus.named(name)`` gives one shared bus per name."""

    _named: ClassVar[dict[str, MemoryBus]] = {}
    _named_lock = threading.Lock()

    def __init__(self, name: str = "") -> None:
        self.name = name
        self._members: list[MemoryTransport] = []
        self._lock = threading.Lock()

    @classmethod
    def named(cls, name: str) -> MemoryBus:
        with cls._named_lock:
            bus = cls._named.get(name)
            if bus is None:
                bus = cls._named[name] = MemoryBus(name)
            return bus

    def attach(self) -> MemoryTransport:
        t = MemoryTransport(self)
        with self._lock:
            self._members.append(t)
        return t

    def _detach(self, t: MemoryTransport) -> None:
        with self._lock:
            if t in self._members:
                self._members.remove(t)

    def _deliver(self, src: MemoryTransport, data: bytes) -> None:
        with self._lock:
            members = list(self._members)
        for m in members:
            if m is not src:
                m._put(data)


class MemoryTransport(Transport):
    """One member's end of a :class:`MemoryBus` (make it with :meth:`MemoryBus.attach`)."""

    def __init__(self, bus: MemoryBus) -> None:
        self.bus = bus
        self._queue: collections.deque[bytes] = collections.deque()
        self._cond = threading.Condition()
        self._closed = False

    @property
    def url(self) -> str:
        return f"mem://{self.bus.name}"

    def _put(self, data: bytes) -> None:
        with self._cond:
            self._queue.append(data)
            self._cond.notify()

    def send(self, data: bytes) -> None:
        if self._closed:
            raise OSError("MemoryTransport closed")
        self.bus._deliver(self, bytes(data))

    def recv(self, timeout_s: float) -> bytes | None:
        with self._cond:
            if not self._queue and timeout_s > 0 and not self._closed:
                self._cond.wait(timeout_s)
            return self._queue.popleft() if self._queue else None

    def pending(self) -> int:
        with self._cond:
            return len(self._queue)

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self._queue.clear()
            self._cond.notify_all()
        self.bus._detach(self)


def distance_m(a: GeoPoint, b: GeoPoint) -> float:
    """Great-circle (haversine) distance with the altitude difference (m)."""
    la1, lo1, la2, lo2 = map(math.radians, (a[0], a[1], b[0], b[1]))
    h = math.sin((la2 - la1) / 2) ** 2 + math.cos(la1) * math.cos(la2) * math.sin((lo2 - lo1) / 2) ** 2
    ground = 2 * _EARTH_R * math.asin(min(1.0, math.sqrt(h)))
    return math.hypot(ground, b[2] - a[2])


def _sender_of(data: bytes) -> int | None:
    """The sender id in a team-link packet's header (None if it does not look like one)."""
    return peek_sender(data)


class LossyTransport(Transport):
    """Wraps ``inner``, dropping a seeded fraction ``loss`` of the received packets and, when
    ``range_m`` is given, every packet whose sender (``position_of(sender)``) is farther than
    ``range_m`` from this member (``position_of(member)``); an unknown position is not dropped by
    range. ``dropped_loss``, ``dropped_range`` and ``passed`` count what happened."""

    def __init__(self, inner: Transport, loss: float = 0.0, seed: int | None = None,
                 range_m: float | None = None, position_of: Callable[[int], GeoPoint | None] | None = None,
                 *, member: int | None = None) -> None:
        if not 0.0 <= loss <= 1.0:
            raise ValueError(f"LossyTransport: loss {loss!r} outside 0..1")
        if range_m is not None:
            if not range_m > 0:
                raise ValueError(f"LossyTransport: range {range_m!r} must be positive")
            if position_of is None or member is None:
                raise ValueError("LossyTransport: a range needs position_of and this member's id")
        self.inner, self.loss, self.range_m = inner, loss, range_m
        self.position_of, self.member = position_of, member
        self._rng = random.Random(seed)
        self.dropped_loss = self.dropped_range = self.passed = 0

    @property
    def url(self) -> str:
        return self.inner.url

    def send(self, data: bytes) -> None:
        self.inner.send(data)

    def _out_of_range(self, data: bytes) -> bool:
        if self.range_m is None or self.position_of is None or self.member is None:
            return False
        sender = _sender_of(data)
        if sender is None or sender == self.member:
            return False
        a, b = self.position_of(sender), self.position_of(self.member)
        return a is not None and b is not None and distance_m(a, b) > self.range_m

    def _keep(self, data: bytes) -> bool:
        """Does this receiver hear ``data`` (counted either way)?"""
        if self._out_of_range(data):
            self.dropped_range += 1
            return False
        if self.loss > 0 and self._rng.random() < self.loss:
            self.dropped_loss += 1
            return False
        self.passed += 1
        return True

    def recv(self, timeout_s: float) -> bytes | None:
        wait = timeout_s
        while True:
            data = self.inner.recv(wait)
            if data is None:
                return None
            wait = 0.0  # a dropped packet does not restart the wait
            if self._keep(data):
                return data

    def subscribe(self, callback: Callable[[bytes], None]) -> bool:
        return self.inner.subscribe(lambda data: callback(data) if self._keep(data) else None)

    def close(self) -> None:
        self.inner.close()


_OPTIONS = {"loss", "seed", "range", "iface", "ttl", "team", "mode"}


def open_transport(url: str, *, member: int | None = None,
                   position_of: Callable[[int], GeoPoint | None] | None = None) -> Transport:
    """The transport ``url`` names (module doc); ValueError naming the bad part of a bad URL.
    ``member`` and ``position_of`` are needed only for a ``range`` option."""
    try:
        u = urlsplit(url)
    except ValueError as exc:
        raise ValueError(f"team URL {url!r}: {exc}") from exc
    opts: dict[str, str] = {}
    for k, v in parse_qsl(u.query, keep_blank_values=True):
        if k not in _OPTIONS:
            raise ValueError(f"team URL {url!r}: unknown option {k!r} (known: {', '.join(sorted(_OPTIONS))})")
        opts[k] = v

    def num(key: str, kind: type, default: object) -> object:
        if key not in opts:
            return default
        try:
            return kind(opts[key])
        except ValueError as exc:
            raise ValueError(f"team URL {url!r}: option {key}={opts[key]!r} is not a "
                             f"{kind.__name__}") from exc

    loss = num("loss", float, 0.0)
    seed = num("seed", int, None)
    range_m = num("range", float, None)
    ttl = num("ttl", int, 1)
    iface = opts.get("iface")
    if not 0.0 <= loss <= 1.0:  # type: ignore[operator]
        raise ValueError(f"team URL {url!r}: option loss={loss} outside 0..1")
    if range_m is not None and not range_m > 0:  # type: ignore[operator]
        raise ValueError(f"team URL {url!r}: option range={range_m} must be positive")
    if range_m is not None and (position_of is None or member is None):
        raise ValueError(f"team URL {url!r}: option range needs the members' positions (not available here)")
    scheme = u.scheme.lower()
    if scheme != "zenoh" and ({"team", "mode"} & opts.keys()):
        raise ValueError(f"team URL {url!r}: team and mode are options of zenoh:, not {scheme}://")
    inner: Transport
    if scheme in ("udp", "bcast"):
        host = u.hostname
        if not host:
            raise ValueError(f"team URL {url!r}: no host (e.g. udp://{DEFAULT_GROUP}:{DEFAULT_PORT})")
        try:
            port = u.port
        except ValueError as exc:
            raise ValueError(f"team URL {url!r}: bad port: {exc}") from exc
        if port is None or port == 0:
            raise ValueError(f"team URL {url!r}: no port (e.g. udp://{DEFAULT_GROUP}:{DEFAULT_PORT})")
        try:
            addr = ipaddress.IPv4Address(host)
        except ValueError as exc:
            raise ValueError(f"team URL {url!r}: host {host!r} is not an IPv4 address") from exc
        try:
            if iface is not None:
                ipaddress.IPv4Address(iface)
        except ValueError as exc:
            raise ValueError(f"team URL {url!r}: option iface={iface!r} is not an IPv4 address") from exc
        broadcast = scheme == "bcast" or not addr.is_multicast
        if scheme == "bcast" and addr.is_multicast:
            raise ValueError(f"team URL {url!r}: host {host} is a multicast group, not a broadcast address")
        inner = UdpTransport(host, port, iface=iface, broadcast=broadcast, ttl=ttl)  # type: ignore[arg-type]
    elif scheme == "mem":
        name = (u.netloc + u.path).strip("/")
        if not name:
            raise ValueError(f"team URL {url!r}: mem:// needs a bus name (mem://NAME)")
        inner = MemoryBus.named(name).attach()
    elif scheme == "zenoh":
        from companion.team.zenoh_transport import ZenohBus, ZenohTransport, parse_zenoh_url

        if "iface" in opts or "ttl" in opts:
            raise ValueError(f"team URL {url!r}: iface and ttl are options of udp://, not zenoh:")
        inner = ZenohTransport(ZenohBus(parse_zenoh_url(url, frozenset(_OPTIONS))), member)
    else:
        raise ValueError(f"team URL {url!r}: unknown scheme {u.scheme!r} (udp, bcast, mem, zenoh)")
    if loss or range_m is not None:
        return LossyTransport(inner, loss, seed, range_m, position_of, member=member)  # type: ignore[arg-type]
    return inner
