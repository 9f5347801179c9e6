"""Loopback ports for the processes of a simulated fleet: ArduPilot SITL's numbering of an instance's
MAVLink ports, whether a port is free, and a free block of instance numbers (for ``taskflight up``, the
benches and the tests, which must not collide with each other or with ArduCopter SITL's instances)."""

from __future__ import annotations

import random
import socket


def model_ports(instance: int) -> tuple[int, int]:
    """(TCP, UDP) MAVLink ports of an instance, as ArduPilot SITL numbers them: 5760+10i, 14550+10i."""
    return 5760 + 10 * instance, 14550 + 10 * instance


def port_free(kind: int, port: int, host: str = "127.0.0.1") -> bool:
    """Nothing holds ``port`` (SOCK_STREAM or SOCK_DGRAM) on ``host``."""
    with socket.socket(socket.AF_INET, kind) as sock:
        if kind == socket.SOCK_STREAM:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as a listener binds it
        try:
            sock.bind((host, port))
        except OSError:
            return False
    return True


def free_ports(n: int, kind: int = socket.SOCK_STREAM, host: str = "127.0.0.1") -> list[int]:
    """``n`` distinct free ports (bound at the same time, so no two are the same)."""
    socks = [socket.socket(socket.AF_INET, kind) for _ in range(n)]
    try:
        for s in socks:
            s.bind((host, 0))
        return [s.getsockname()[1] for s in socks]
    finally:
        for s in socks:
            s.close()


def base_free(base: int, n: int) -> bool:
    """Every MAVLink port of instances base..base+n-1 is free."""
    return all(port_free(socket.SOCK_STREAM, tcp) and port_free(socket.SOCK_DGRAM, udp)
               for tcp, udp in map(model_ports, range(base, base + n)))


def free_base(n: int, rng: random.Random | None = None) -> int:
    """A base instance in 60..254-n whose n instances' ports are all free (ArduCopter's tests use 10..59)."""
    rng = rng or random.Random()
    for _ in range(100):
        base = rng.randrange(60, 255 - n)
        if base_free(base, n):
            return base
    raise RuntimeError(f"no block of {n} free instance numbers")
