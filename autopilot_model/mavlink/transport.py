"""Non-blocking MAVLink transports: ``udpin``, ``udpout`` and ``tcpin`` endpoints.

Seed 002 places the datalink among the *event* functions: polled once per main-loop iteration,
never blocking. All sockets of one endpoint are registered with a single ``epoll`` object, so an idle
poll is one system call whatever the number of links (about 0.7 us here); only sockets with data are
read, each until it is empty or the per-poll budget is spent (so a flood cannot stall the loop).

A :class:`Peer` is one party we talk to and is what the protocol layer calls a *link*: one UDP
sender on a ``udpin`` socket (ArduPilot's "answer whoever sends", extended to several senders so a
companion and a ground station can share a port), the configured address of a ``udpout``, or one
accepted TCP client. Each peer has its own frame parser and its own telemetry stream rates, as each
ArduPilot serial port has its own SRx_ rates.

URLs: ``udpin:HOST:PORT`` (bind, answer whoever sends), ``udpout:HOST:PORT`` (send there; replies
to our socket are read too), ``tcpin:HOST:PORT`` (listen; serve one or more clients). ``udp:`` is
accepted as ``udpin:`` and ``tcp:`` as ``tcpin:`` for convenience.
"""

from __future__ import annotations

import contextlib
import errno
import logging
import select
import socket
import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

log = logging.getLogger(__name__)

MAX_UDP_PEERS = 8
MAX_DATAGRAM = 2048
TCP_SEND_BUFFER_LIMIT = 1 << 20


@dataclass(frozen=True)
class EndpointUrl:
    """A parsed ``kind:host:port`` URL."""

    kind: str
    host: str
    port: int

    @classmethod
    def parse(cls, url: str) -> EndpointUrl:
        parts = url.strip().split(":")
        if len(parts) != 3:
            raise ValueError(f"bad MAVLink URL {url!r}: expected udpin:HOST:PORT, udpout:HOST:PORT or "
                             "tcpin:HOST:PORT")
        kind, host, port_s = parts
        kind = {"udp": "udpin", "tcp": "tcpin"}.get(kind.lower(), kind.lower())
        if kind not in ("udpin", "udpout", "tcpin"):
            raise ValueError(f"bad MAVLink URL {url!r}: unknown kind {kind!r}")
        try:
            port = int(port_s)
        except ValueError:
            raise ValueError(f"bad MAVLink URL {url!r}: port {port_s!r} is not a number") from None
        if not 0 <= port <= 65535:
            raise ValueError(f"bad MAVLink URL {url!r}: port {port} out of range")
        return cls(kind, host or "0.0.0.0", port)

    def __str__(self) -> str:
        return f"{self.kind}:{self.host}:{self.port}"


class Peer:
    """One party the endpoint talks to (a *link* to the protocol layer)."""

    def __init__(self, name: str, sender: Callable[[bytes], bool]) -> None:
        self.name = name
        self._sender = sender
        self.active = False  # a valid MAVLink message has been received from it (udpout: always)
        self.parser: Any = None  # set by the endpoint
        self.state: Any = None  # protocol state (stream rates ...), set by the endpoint
        self.last_rx_wall = 0.0
        self.closed = False

    def send_bytes(self, data: bytes) -> bool:
        """Send one write (one or more packets); False when it had to be dropped (socket full or gone: the
        endpoint counts the messages in ``tx_dropped``; a full socket or TCP buffer is also ``tx_full``)."""
        if self.closed:
            return False
        return self._sender(data)

    def __repr__(self) -> str:
        return f"Peer({self.name})"


OnData = Callable[[Peer, bytes], None]


class Transport(ABC):
    """Base: a socket registered with the endpoint's poller, producing data for peers."""

    url: EndpointUrl

    @abstractmethod
    def peers(self) -> list[Peer]:
        """The peers this transport currently talks to."""

    @abstractmethod
    def on_readable(self, fd: int, on_data: OnData, budget_end: float) -> None:
        """Read what ``fd`` has (until empty or the wall-clock ``budget_end``), handing it to ``on_data``."""

    @abstractmethod
    def fds(self) -> list[int]:
        """File descriptors to register with the poller."""

    @abstractmethod
    def close(self) -> None:
        """Close the sockets."""


def _udp_socket() -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.setblocking(False)
    try:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 1 << 20)
    except OSError:  # pragma: no cover
        pass
    return s


class _UdpBase(Transport):
    def __init__(self, url: EndpointUrl, stats: dict[str, int]) -> None:
        self.url = url
        self.stats = stats
        self.sock = _udp_socket()
        self._peers: dict[tuple[str, int], Peer] = {}

    def _sendto(self, addr: tuple[str, int]) -> Callable[[bytes], bool]:
        sock = self.sock
        stats = self.stats

        def send(data: bytes) -> bool:
            try:
                sock.sendto(data, addr)
                return True
            except (BlockingIOError, InterruptedError):
                stats["tx_full"] += 1
                return False
            except OSError as exc:  # e.g. ECONNREFUSED reported for an earlier datagram
                if exc.errno not in (errno.ECONNREFUSED, errno.ENOBUFS, errno.EHOSTUNREACH,
                                     errno.ENETUNREACH):
                    log.debug("udp send to %s failed: %s", addr, exc)
                return False
        return send

    def peers(self) -> list[Peer]:
        return list(self._peers.values())

    def fds(self) -> list[int]:
        return [self.sock.fileno()]

    def _peer_for(self, addr: tuple[str, int]) -> Peer:
        peer = self._peers.get(addr)
        if peer is None:
            if len(self._peers) >= MAX_UDP_PEERS:  # forget the one heard from longest ago
                oldest = min(self._peers, key=lambda a: self._peers[a].last_rx_wall)
                self._peers.pop(oldest).closed = True
                self.stats["peers_evicted"] += 1
            peer = Peer(f"{self.url.kind}:{self.url.port}<-{addr[0]}:{addr[1]}", self._sendto(addr))
            self._peers[addr] = peer
        return peer

    def on_readable(self, fd: int, on_data: OnData, budget_end: float) -> None:
        recv = self.sock.recvfrom
        while True:
            try:
                data, addr = recv(MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:  # ICMP errors surface here on Linux; nothing to read
                return
            peer = self._peer_for(addr)
            peer.last_rx_wall = time.monotonic()
            on_data(peer, data)
            # checked after every datagram (~0.1 us against ~50 us to handle one), so a flood can
            # overrun the budget by one datagram at most
            if time.perf_counter() > budget_end:
                return

    def close(self) -> None:
        for p in self._peers.values():
            p.closed = True
        self.sock.close()


class UdpIn(_UdpBase):
    """Bind HOST:PORT and answer whoever sends (up to :data:`MAX_UDP_PEERS` senders)."""

    def __init__(self, url: EndpointUrl, stats: dict[str, int]) -> None:
        super().__init__(url, stats)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.sock.bind((url.host, url.port))

    @property
    def port(self) -> int:
        return self.sock.getsockname()[1]


class UdpOut(_UdpBase):
    """Send to HOST:PORT from an ephemeral port; read what comes back to it."""

    def __init__(self, url: EndpointUrl, stats: dict[str, int]) -> None:
        super().__init__(url, stats)
        host = "127.0.0.1" if url.host in ("", "0.0.0.0") else url.host
        self.addr = (socket.gethostbyname(host), url.port)
        self.sock.bind(("0.0.0.0", 0))
        peer = Peer(f"udpout:{host}:{url.port}", self._sendto(self.addr))
        peer.active = True
        self._peers[self.addr] = peer

    def _peer_for(self, addr: tuple[str, int]) -> Peer:
        return self._peers[self.addr]  # a udpout link has exactly one peer


class _TcpClient:
    def __init__(self, sock: socket.socket, addr: tuple[str, int], url: EndpointUrl,
                 stats: dict[str, int]) -> None:
        self.sock = sock
        self.stats = stats
        self.pending = bytearray()
        self.peer = Peer(f"tcpin:{url.port}<-{addr[0]}:{addr[1]}", self.send)

    def send(self, data: bytes) -> bool:
        if self.pending:
            self.flush()
        if self.pending:
            if len(self.pending) + len(data) > TCP_SEND_BUFFER_LIMIT:
                self.stats["tx_full"] += 1
                return False
            self.pending += data
            return True
        try:
            n = self.sock.send(data)
        except (BlockingIOError, InterruptedError):
            n = 0
        except OSError:
            self.peer.closed = True
            return False
        if n < len(data):
            self.pending += data[n:]
        return True

    def flush(self) -> None:
        try:
            n = self.sock.send(self.pending)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            self.peer.closed = True
            self.pending.clear()
            return
        del self.pending[:n]


class TcpIn(Transport):
    """Listen on HOST:PORT and serve every client that connects."""

    def __init__(self, url: EndpointUrl, stats: dict[str, int], poller: Any) -> None:
        self.url = url
        self.stats = stats
        self.poller = poller
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.sock.setblocking(False)
        self.sock.bind((url.host, url.port))
        self.sock.listen(8)
        self.clients: dict[int, _TcpClient] = {}

    @property
    def port(self) -> int:
        return self.sock.getsockname()[1]

    def peers(self) -> list[Peer]:
        return [c.peer for c in self.clients.values()]

    def fds(self) -> list[int]:
        return [self.sock.fileno()]

    def on_readable(self, fd: int, on_data: OnData, budget_end: float) -> None:
        if fd == self.sock.fileno():
            self._accept()
            return
        client = self.clients.get(fd)
        if client is None:
            return
        if client.pending:
            client.flush()
        for _ in range(64):
            try:
                data = client.sock.recv(65536)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                data = b""
            if not data:
                self._drop(fd)
                return
            on_data(client.peer, data)
            if time.perf_counter() > budget_end:
                return

    def _accept(self) -> None:
        while True:
            try:
                sock, addr = self.sock.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:  # pragma: no cover
                log.warning("tcp accept failed: %s", exc)
                return
            sock.setblocking(False)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            client = _TcpClient(sock, addr, self.url, self.stats)
            client.peer.active = True
            self.clients[sock.fileno()] = client
            self.poller.register(sock.fileno(), self)
            self.stats["tcp_accepted"] += 1
            log.info("MAVLink TCP client %s:%s connected", *addr)

    def _drop(self, fd: int) -> None:
        client = self.clients.pop(fd, None)
        if client is None:
            return
        client.peer.closed = True
        self.poller.unregister(fd)
        with contextlib.suppress(OSError):
            client.sock.close()
        log.info("MAVLink TCP client %s disconnected", client.peer.name)

    def close(self) -> None:
        for fd in list(self.clients):
            self._drop(fd)
        self.sock.close()


class Poller:
    """One ``epoll`` over every socket of the endpoint; ``poll()`` never blocks."""

    def __init__(self) -> None:
        self._ep = select.epoll()
        self._owners: dict[int, Transport] = {}

    def register(self, fd: int, owner: Transport) -> None:
        self._owners[fd] = owner
        self._ep.register(fd, select.EPOLLIN)

    def unregister(self, fd: int) -> None:
        self._owners.pop(fd, None)
        with contextlib.suppress(OSError, ValueError):
            self._ep.unregister(fd)

    def poll(self, on_data: OnData, budget_s: float) -> int:
        """Read what is waiting (at most ``budget_s`` of wall time); returns the ready socket count."""
        events = self._ep.poll(0)
        if not events:
            return 0
        return self.dispatch(events, on_data, budget_s)

    @property
    def epoll_poll(self) -> Callable[[float], list[tuple[int, int]]]:
        """The bare ``epoll.poll`` (callers on the hot path test for an empty result themselves)."""
        return self._ep.poll

    def dispatch(self, events: list[tuple[int, int]], on_data: OnData, budget_s: float) -> int:
        end = time.perf_counter() + budget_s
        for fd, _ev in events:
            owner = self._owners.get(fd)
            if owner is not None:
                owner.on_readable(fd, on_data, end)
        return len(events)

    def close(self) -> None:
        self._ep.close()


def open_transport(url: str | EndpointUrl, stats: dict[str, int], poller: Poller) -> Transport:
    """Open one endpoint URL and register its sockets with ``poller``."""
    u = url if isinstance(url, EndpointUrl) else EndpointUrl.parse(url)
    t: Transport
    if u.kind == "udpin":
        t = UdpIn(u, stats)
    elif u.kind == "udpout":
        t = UdpOut(u, stats)
    else:
        t = TcpIn(u, stats, poller)
    for fd in t.fds():
        poller.register(fd, t)
    return t
