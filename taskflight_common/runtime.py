"""What every long-running ``taskflight`` process does the same way: stop cleanly on SIGTERM / SIGINT, log
in one format, (as a child of ``taskflight up``) stop when its parent dies, and keep its start-up objects
out of the garbage collector's full passes."""

from __future__ import annotations

import ctypes
import gc
import logging
import os
import signal
import sys
import threading
import time
from typing import Any

log = logging.getLogger(__name__)

#: set by :class:`taskflight.children.Child` to the parent's PID: the child stops when that process dies
PARENT_ENV = "TASKFLIGHT_PARENT_PID"
_PR_SET_PDEATHSIG = 1


def die_with_parent() -> bool:
    """In a child started with :data:`PARENT_ENV` (a child of ``taskflight up``): have the kernel send this
    process SIGTERM when its parent dies (Linux ``PR_SET_PDEATHSIG``), so that a ``taskflight up`` killed
    with SIGKILL, which cannot stop its children, leaves none behind: each stops as on Ctrl-C. If the parent
    is already gone, SIGTERM now. The variable is removed from the environment (a grandchild's parent is
    this process). True if armed. The kernel signals when the parent's *thread* that started the child
    ends: start children from a thread that lives as long as they do (``taskflight up``'s main thread)."""
    want = os.environ.pop(PARENT_ENV, None)
    if not want or not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0) != 0:
            log.warning("PR_SET_PDEATHSIG refused (errno %d): this process outlives its parent",
                        ctypes.get_errno())
            return False
    except (OSError, AttributeError) as exc:
        log.warning("no prctl (%s): this process outlives its parent", exc)
        return False
    if str(os.getppid()) != want:  # the parent died before the request took effect
        os.kill(os.getpid(), signal.SIGTERM)
    return True


def stop_on_signals() -> threading.Event:
    """An event set by SIGTERM or SIGINT (handlers installed only from the main thread)."""
    stop = threading.Event()

    def _stop(*_: Any) -> None:
        stop.set()

    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, _stop)
        signal.signal(signal.SIGINT, _stop)
    return stop


def setup_logging(verbose: int, quiet_level: int = logging.WARNING) -> None:
    """``-v`` INFO, ``-vv`` DEBUG, else ``quiet_level``; one format for every process."""
    level = logging.DEBUG if verbose > 1 else logging.INFO if verbose else quiet_level
    logging.basicConfig(level=level, format="%(asctime)s %(levelname)s %(name)s: %(message)s")


def freeze_startup_heap(what: str) -> int:
    """Move every object alive now (the imported modules, the process's long-lived parts) out of the
    garbage collector's sight (:func:`gc.freeze`) and return how many.

    A full collection walks every tracked object and stops every thread while it does: measured on the
    2-core test machine (``bench/bench_collector.py``), 19 ms in the model, 53 ms in the companion
    (~120 000 objects: pymavlink's dialects, FastAPI, pydantic, scipy), 65 ms in the ground service, and
    250-330 ms in a process importing all of them (0.5-0.7 s with the other core busy: a take-off handed
    over seconds late at a 5x simulation speed-up). Frozen, a full collection walks only what was
    allocated since. Call once, after start-up, from a process's main function: the frozen objects are
    never freed, so nothing transient should be alive then."""
    t0 = time.perf_counter()
    gc.collect()
    n = gc.get_freeze_count()
    gc.freeze()
    frozen = gc.get_freeze_count() - n
    log.info("%s: %d start-up objects out of the collector's sight (%.0f ms)", what, frozen,
             (time.perf_counter() - t0) * 1e3)
    return frozen
