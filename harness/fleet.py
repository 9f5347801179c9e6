"""Start a fleet of bundled models in one process (:mod:`autopilot_model.fleet`) on free loopback ports."""

from __future__ import annotations

import os
import random
from pathlib import Path

from taskflight.sitlproc import ModelProcess
from taskflight_common.ports import base_free, model_ports

SPEEDUP = 5.0
N = 3
_rng = random.Random(os.getpid())


ports = model_ports


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
