"""Several hosts on one machine, for the tests: Linux network namespaces joined by a bridge.

:class:`Lan` makes one namespace per host and a switch (a namespace holding a bridge), joined by veth pairs
("cables"): each host has ``eth0`` with an address on one /24, loopback up, a default route and a multicast
route on ``eth0``, and nothing else: no route to the machine's own network, so what reaches a host came over
the bridge. :meth:`Lan.unplug` / :meth:`Lan.plug` take a host's switch port down and up (a partition: its
radio out of range). :meth:`Lan.popen` runs a command in a host (``ip netns exec``); :class:`InHost` runs
Python callables on a thread that entered a host's namespace, so that the sockets they open (an HTTP client,
a pymavlink ground station) live there.

Names are unique per run (the test process's id and a random tag), so a crashed run never blocks the next;
:meth:`Lan.close` ends every process left in its namespaces (by id) and deletes them, and a new
:class:`Lan` deletes namespaces of this prefix whose creating process is gone. Needs root (``ip netns``).
"""

from __future__ import annotations

import contextlib
import ctypes
import logging
import os
import secrets
import signal
import subprocess
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any, TypeVar

log = logging.getLogger(__name__)

T = TypeVar("T")
PREFIX = "tfnet"
CLONE_NEWNET = 0x40000000


def netns_unavailable() -> str | None:
    """Why namespaces cannot be made here (None when they can): the reason a test skips with."""
    if os.geteuid() != 0:
        return "needs root: network namespaces joined by a bridge (ip netns); CI runs as root"
    try:
        subprocess.run(["ip", "netns", "list"], check=True, capture_output=True, timeout=10)
    except (OSError, subprocess.SubprocessError) as exc:
        return f"ip netns unusable here: {exc}"
    return None


def _ip(*args: str, ns: str | None = None, check: bool = True) -> subprocess.CompletedProcess[str]:
    argv = ["ip", *(["-n", ns] if ns else []), *args]
    r = subprocess.run(argv, capture_output=True, text=True, timeout=30)
    if check and r.returncode != 0:
        raise RuntimeError(f"{' '.join(argv)}: {r.stderr.strip()}")
    return r


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _sweep_stale() -> None:
    """Delete namespaces of this prefix left by a run whose process is gone (a crash)."""
    out = _ip("netns", "list", check=False).stdout
    for line in out.splitlines():
        name = line.split()[0] if line.split() else ""
        parts = name.split("-")
        if len(parts) >= 3 and parts[0] == PREFIX and parts[1].isdigit() and not _pid_alive(int(parts[1])):
            _kill_in(name)
            _ip("netns", "del", name, check=False)
            log.info("netns: deleted %s, left by a run that ended", name)


def _kill_in(ns: str) -> None:
    """SIGKILL every process still in namespace ``ns`` (all of them started by the run that made it)."""
    r = subprocess.run(["ip", "netns", "pids", ns], capture_output=True, text=True, timeout=10)
    for pid in r.stdout.split():
        with contextlib.suppress(ProcessLookupError, ValueError):
            os.kill(int(pid), signal.SIGKILL)


class Lan:
    """See module docstring. ``hosts``: short names (letters/digits); host i gets ``SUBNET.(10+i)``."""

    SUBNET = "10.99.0"

    def __init__(self, hosts: list[str]) -> None:
        _sweep_stale()
        self.tag = f"{PREFIX}-{os.getpid()}-{secrets.token_hex(2)}"
        self.hosts = list(hosts)
        self.switch = f"{self.tag}-sw"
        self.made: list[str] = []
        self.procs: list[subprocess.Popen[bytes]] = []
        try:
            self._build()
        except BaseException:
            self.close()
            raise

    def ns(self, host: str) -> str:
        return f"{self.tag}-{host}"

    def addr(self, host: str) -> str:
        return f"{self.SUBNET}.{10 + self.hosts.index(host)}"

    def _port(self, host: str) -> str:
        return f"p{self.hosts.index(host)}"

    def _add_ns(self, name: str) -> None:
        _ip("netns", "add", name)
        self.made.append(name)
        _ip("link", "set", "lo", "up", ns=name)

    def _build(self) -> None:
        self._add_ns(self.switch)
        _ip("link", "add", "br0", "type", "bridge", ns=self.switch)
        # no IGMP snooping: with no querier on the segment the bridge floods multicast, as a plain switch
        _ip("link", "set", "br0", "type", "bridge", "mcast_snooping", "0", ns=self.switch, check=False)
        _ip("link", "set", "br0", "up", ns=self.switch)
        for h in self.hosts:
            ns = self.ns(h)
            self._add_ns(ns)
            _ip("link", "add", "eth0", "type", "veth", "peer", "name", self._port(h), "netns", self.switch,
                ns=ns)
            _ip("link", "set", self._port(h), "master", "br0", ns=self.switch)
            _ip("link", "set", self._port(h), "up", ns=self.switch)
            _ip("addr", "add", f"{self.addr(h)}/24", "dev", "eth0", ns=ns)
            _ip("link", "set", "eth0", "up", ns=ns)
            _ip("route", "add", "default", "dev", "eth0", ns=ns)
            _ip("route", "add", "224.0.0.0/4", "dev", "eth0", ns=ns)

    # --- the cables --------------------------------------------------------------------------------
    def unplug(self, host: str) -> None:
        """The host's switch port down: it hears nobody and nobody hears it."""
        _ip("link", "set", self._port(host), "down", ns=self.switch)

    def plug(self, host: str) -> None:
        _ip("link", "set", self._port(host), "up", ns=self.switch)

    # --- processes ---------------------------------------------------------------------------------
    def popen(self, host: str, argv: list[str], log_path: Path, env: dict[str, str] | None = None,
              cwd: Path | None = None) -> subprocess.Popen[bytes]:
        """``argv`` in ``host`` (its own session), output to ``log_path``."""
        out = open(log_path, "ab")  # noqa: SIM115 - the child owns it
        try:
            p = subprocess.Popen(["ip", "netns", "exec", self.ns(host), *argv], stdout=out,
                                 stderr=subprocess.STDOUT, env={**os.environ, **(env or {})}, cwd=cwd,
                                 start_new_session=True)
        finally:
            out.close()
        self.procs.append(p)
        return p

    def stop(self, p: subprocess.Popen[bytes], timeout_s: float = 20.0) -> None:
        """SIGTERM (``taskflight up`` stops its children), then SIGKILL of its process group."""
        if p.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                p.send_signal(signal.SIGTERM)
            try:
                p.wait(timeout_s)
            except subprocess.TimeoutExpired:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(p.pid, signal.SIGKILL)
                p.wait(10)

    def close(self) -> None:
        """Every process stopped, every namespace deleted (idempotent)."""
        for p in reversed(self.procs):
            try:
                self.stop(p)
            except Exception as exc:  # go on: the namespaces must go
                log.warning("netns: stopping %s: %s", p.args, exc)
        self.procs = []
        for ns in reversed(self.made):
            _kill_in(ns)
        deadline = time.monotonic() + 10
        for ns in reversed(self.made):
            while _ip("netns", "pids", ns, check=False).stdout.strip() and time.monotonic() < deadline:
                time.sleep(0.1)
            _ip("netns", "del", ns, check=False)
        self.made = []


def _enter(ns: str) -> None:
    libc = ctypes.CDLL(None, use_errno=True)
    fd = os.open(f"/run/netns/{ns}", os.O_RDONLY)
    try:
        if libc.setns(fd, CLONE_NEWNET) != 0:
            err = ctypes.get_errno()
            raise OSError(err, f"setns({ns}): {os.strerror(err)}")
    finally:
        os.close(fd)


class InHost:
    """Callables run on one thread that entered a host's network namespace (sockets opened there live
    there, also when read from other threads)."""

    def __init__(self, lan: Lan, host: str) -> None:
        self._pool = ThreadPoolExecutor(1, thread_name_prefix=f"in-{host}", initializer=_enter,
                                        initargs=(lan.ns(host),))

    def call(self, fn: Callable[..., T], *args: Any, **kwargs: Any) -> T:
        return self._pool.submit(fn, *args, **kwargs).result()

    def close(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)
