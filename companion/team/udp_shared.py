"""One socket and one receive thread per process for each UDP team group (seed 003 Sec. III-A).

Every member hears every broadcast. A companion host (:mod:`companion.host`) runs K members in one
process; with a socket per member, the kernel copied each datagram K times and woke K threads, each of which
took the interpreter's lock to read it: at 50 vehicles in two hosts, 2,500 wake-ups a second per host for
the team link alone, and ~30 % of the machine's CPU in the kernel. :class:`SharedGroupSocket` is the one
socket of a process for one (group, port, interface, broadcast, TTL): every :class:`~companion.team.transport.
UdpTransport` of the process on that group sends through it, and its one thread reads each datagram once
and hands it to every subscriber in turn (a link's ``handle``: :meth:`TeamLink.start
<companion.team.link.TeamLink.start>`), so the work per datagram is one wake-up and K calls. A member alone
in its process (a real vehicle) has the same socket and one receive thread, as before.

What each member hears is unchanged: its own packets come back once (multicast loopback on the shared
socket), every other member's once. A subscriber that raises is logged and the others still get the datagram.
"""

from __future__ import annotations

import logging
import select
import socket
import threading
from collections.abc import Callable
from typing import ClassVar

log = logging.getLogger(__name__)

Key = tuple[str, int, str, bool, int]
"""(group or broadcast address, port, interface address, broadcast, TTL)."""

#: how long the receive thread waits in one ``select`` before it looks whether it should stop
_POLL_S = 0.2
_MAX_DATAGRAM = 65536


class SharedGroupSocket:
    """The process's socket on one team group, shared by count (:meth:`acquire`, :meth:`release`)."""

    _registry: ClassVar[dict[Key, SharedGroupSocket]] = {}
    _registry_lock = threading.Lock()

    def __init__(self, key: Key, sock: socket.socket) -> None:
        self.key = key
        self.sock = sock
        self.refs = 0
        self.datagrams = 0
        """Datagrams read (each handed to every subscriber)."""
        self._subs: dict[int, Callable[[bytes], None]] = {}
        self._lock = threading.Lock()
        self._closing = threading.Event()
        self._thread: threading.Thread | None = None

    @classmethod
    def acquire(cls, key: Key, opener: Callable[[], socket.socket]) -> SharedGroupSocket:
        """The shared socket for ``key``, opened with ``opener`` (non-blocking, bound, joined) if this
        process has none yet (``opener``'s OSError propagates)."""
        with cls._registry_lock:
            shared = cls._registry.get(key)
            if shared is None:
                shared = cls._registry[key] = cls(key, opener())
            shared.refs += 1
            return shared

    def release(self) -> None:
        """One user fewer; the last one closes the socket and stops the thread."""
        with self._registry_lock:
            self.refs -= 1
            if self.refs > 0:
                return
            if self._registry.get(self.key) is self:
                del self._registry[self.key]
        self._closing.set()
        t = self._thread
        if t is not None and t is not threading.current_thread():
            t.join(timeout=2.0)
        self.sock.close()

    # --- subscribers ---------------------------------------------------------------------------------
    def subscribe(self, token: int, callback: Callable[[bytes], None]) -> None:
        """Hand every datagram read from now on to ``callback`` (replacing ``token``'s earlier one)."""
        with self._lock:
            self._subs[token] = callback
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name=f"team-udp-{self.key[1]}", daemon=True)
                self._thread.start()

    def unsubscribe(self, token: int) -> None:
        with self._lock:
            self._subs.pop(token, None)

    def send(self, data: bytes) -> None:
        """Send ``data`` to the group (OSError when the network refuses it)."""
        self.sock.sendto(data, (self.key[0], self.key[1]))

    # --- the receive thread --------------------------------------------------------------------------
    def _run(self) -> None:
        sock = self.sock
        while not self._closing.is_set():
            try:
                ready, _, _ = select.select([sock], [], [], _POLL_S)
            except (OSError, ValueError):  # closed under us
                return
            if not ready:
                continue
            while True:
                try:
                    data = sock.recv(_MAX_DATAGRAM)
                except BlockingIOError:
                    break
                except OSError as exc:
                    if self._closing.is_set():
                        return
                    log.debug("team udp recv: %s", exc)
                    break
                self.datagrams += 1
                with self._lock:
                    subs = list(self._subs.values())
                for cb in subs:
                    try:
                        cb(data)
                    except Exception:  # one member's failure must not deafen the others
                        log.exception("team udp: a subscriber failed on a datagram")
