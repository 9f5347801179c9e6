"""What every long-running ``taskflight`` process does the same way: stop cleanly on SIGTERM / SIGINT, log
in one format."""

from __future__ import annotations

import logging
import signal
import threading
from typing import Any


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
