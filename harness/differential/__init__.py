"""The differential scenarios: one ground station's script flown on the bundled model and on ArduPilot's
copter SITL, returning what the station saw, so the tests compare the two (docs/conformance.md).

:func:`observed` flies one scenario on one autopilot once per test run (the ``seen`` fixture of
``tests/conftest.py`` and the scenario fixtures of ``tests/test_differential_modes.py`` read it)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from harness.autopilot import Autopilot, start_autopilot

Observation = dict[str, Any]

_cache: dict[tuple[str, Callable[[Autopilot], Observation]], Observation] = {}


def observed(kind: str, observe: Callable[[Autopilot], Observation], state_dir: Callable[[str], Path],
             speedup: float) -> Observation:
    """What ``observe`` saw on autopilot ``kind`` at ``speedup``: flown on the first call (on an autopilot
    started in ``state_dir(name)``, closed after), the same observations on every later call (pytest may
    set a module-scoped parametrised fixture up again when it reorders the tests)."""
    key = (kind, observe)
    if key not in _cache:
        ap = start_autopilot(kind, state_dir(f"{observe.__name__}_{kind}"), speedup)
        try:
            _cache[key] = observe(ap)
        finally:
            ap.close()
    return _cache[key]
