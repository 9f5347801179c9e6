"""The test process's garbage collector, kept from pausing the flights that run inside it.

The flight tests run a companion in the pytest process, its setpoint stream paced on a model sped up
five times: a pause of the whole process costs five times as much simulated time. A full collection
walks every tracked object; with the suite's modules imported (~130 000 objects) it took 250-330 ms
here (0.5-0.7 s with the other core busy), enough to hand a take-off over seconds late (a CI failure:
the vehicle 1.5 m below its take-off altitude when the take-off ended). So, as the product's processes
do (:func:`taskflight_common.runtime.freeze_startup_heap`):

* once every test module is imported, the objects alive then are frozen out of the collector's sight;
* after each test, FastAPI's callable-classification caches (bounded at 4096 entries, keyed by the
  endpoint functions) are emptied: each control server's endpoints are closures over its node, so
  the cache would otherwise keep up to a hundred finished flight sessions alive and make every full
  collection walk them;
* the longest collector pauses are printed at the end of the run (a flaky flight test's first suspect).
"""

from __future__ import annotations

import gc
import time
from collections.abc import Iterator
from typing import Any

import pytest

_pauses: list[tuple[float, int, str]] = []  # (seconds, generation, test) of the pauses over PAUSE_KEPT_S
_started: list[float] = []
_current = [""]
PAUSE_KEPT_S = 0.02


def _on_gc(phase: str, info: dict[str, Any]) -> None:
    if phase == "start":
        _started[:] = [time.perf_counter()]
    elif _started:
        took = time.perf_counter() - _started[0]
        if took >= PAUSE_KEPT_S:
            _pauses.append((took, int(info.get("generation", -1)), _current[0]))


def pytest_collection_finish(session: pytest.Session) -> None:
    gc.collect()
    gc.freeze()
    gc.callbacks.append(_on_gc)


def _clear_fastapi_caches() -> None:
    try:
        from fastapi.dependencies import models
    except ImportError:
        return
    for name in dir(models):
        fn = getattr(models, name)
        if name.endswith("_cached") and hasattr(fn, "cache_clear"):
            fn.cache_clear()


@pytest.fixture(autouse=True)
def _collector_hygiene(request: pytest.FixtureRequest) -> Iterator[None]:
    _current[0] = request.node.nodeid
    yield
    _clear_fastapi_caches()


def pytest_terminal_summary(terminalreporter: Any) -> None:
    if not _pauses:
        return
    worst = sorted(_pauses, reverse=True)[:3]
    text = "; ".join(f"{took * 1e3:.0f} ms (generation {gen}) in {test or 'collection'}"
                     for took, gen, test in worst)
    terminalreporter.write_line(f"longest garbage-collector pauses: {text}")
