"""Start a fleet of bundled models in one process (:mod:`autopilot_model.fleet`) on free loopback ports."""

from __future__ import annotations

import os
import random
import socket
from pathlib import Path

from mavlink_support import port_free

from taskflight.sitlproc import ModelProcess

SPEEDUP = 5.0
N = 3
_rng = random.Random(os.getpid())


def ports(instance: int) -> tuple[int, int]:
    """(TCP, UDP) ports of an instance, as ArduPilot SITL numbers them."""
    return 5760 + 10 * instance, 14550 + 10 * instance


def base_free(base: int, n: int) -> bool:
    """Every port of instances base..base+n-1 is free (cf. ``_instance_free`` in autopilot_support)."""
    return all(port_free(socket.SOCK_STREAM, ports(i)[0]) and port_free(socket.SOCK_DGRAM, ports(i)[1])
               for i in range(base, base + n))


def start_fleet(tmp: Path, n: int = N, speedup: float = SPEEDUP) -> tuple[ModelProcess, int]:
    """A fleet of ``n`` on loopback at instances base..base+n-1 (base picked at random in 60..253 where
    every port is free, so parallel runs and ArduCopter's instances 10..59 do not collide); retried on
    another base if a port is taken meanwhile."""
    for _ in range(6):
        base = _rng.randrange(60, 254 - n)
        if not base_free(base, n):
            continue
        proc = ModelProcess(["--vehicles", str(n), "--base-instance", str(base), "--speedup", str(speedup),
                             "--state-dir", str(tmp), "--no-persist",
                             "--mavlink-template", "tcpin:127.0.0.1:{tcp}",
                             "--mavlink-template", "udpin:127.0.0.1:{udp}"],
                            name="fleet", module="autopilot_model.fleet")
        try:
            return proc.start(90.0), base
        except RuntimeError:
            if base_free(base, n):
                raise  # not a port taken meanwhile
    raise RuntimeError("no free block of instance numbers for the fleet")
