"""Deadlines in wall time for the tests and benches that run the model sped up: :func:`wait_for` (a
condition polled until a deadline) and :func:`wall` (the wall deadline of a simulated duration)."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

#: the speedup the SITL tests run the model at
SPEEDUP = 10.0


def wall(sim_s: float, speedup: float = SPEEDUP, base_s: float = 5.0) -> float:
    """Wall deadline for ``sim_s`` simulated seconds (generous: a loaded 2-core machine)."""
    return base_s + 3.0 * sim_s / speedup


def wait_for(pred: Callable[[], Any], timeout_s: float, what: str | Callable[[], str],
             poll_s: float = 0.005) -> Any:
    """Test ``pred`` until truthy or the wall deadline passes (then AssertionError naming ``what``; a
    callable ``what`` is asked at the deadline, so the message shows the state that failed, not the
    state when the wait began)."""
    end = time.monotonic() + timeout_s
    while True:
        r = pred()
        if r:
            return r
        if time.monotonic() > end:
            raise AssertionError(f"timed out after {timeout_s:.1f} s waiting for "
                                 f"{what() if callable(what) else what}")
        time.sleep(poll_s)
