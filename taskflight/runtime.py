"""What every long-running ``taskflight`` process does the same way: stop cleanly on SIGTERM / SIGINT, log
in one format, and (as a child of ``taskflight up``) stop when its parent dies."""

from __future__ import annotations

import ctypes
import logging
import os
import signal
import sys
import threading
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
