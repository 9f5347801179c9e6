"""The autopilot model in a child process (``python -m autopilot_model.sitl``), as deployed.

A separate process, not a thread: a client in this process (the demo's companion) then does not share
the interpreter's GIL with the model and ticks on time at a speedup, as it would beside a real flight
controller. :class:`ModelProcess` starts the child, waits for its ``READY`` line, keeps its output
drained (each line into the log at debug level, so the child never blocks on a full pipe) and stops it
with SIGTERM, then SIGKILL after a timeout.
"""

from __future__ import annotations

import logging
import os
import subprocess
import sys
import threading
import time
from collections import deque
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from collections.abc import Sequence
    from types import TracebackType

log = logging.getLogger(__name__)

#: the directory holding the ``autopilot_model`` package, put on the child's PYTHONPATH
_ROOT = Path(__file__).resolve().parents[1]


def stop_child(proc: subprocess.Popen[Any], timeout_s: float = 10.0, name: str = "child") -> int:
    """Stop a child process: SIGTERM, wait ``timeout_s``, SIGKILL if it will not; reap it; its status."""
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            log.warning("%s did not stop in %.0f s; killing it", name, timeout_s)
            proc.kill()
            proc.wait(5.0)
        except BaseException:  # e.g. a second Ctrl-C while waiting: do not leave the child behind
            proc.kill()
            raise
    return int(proc.returncode)


class ModelProcess:
    """``python -m autopilot_model.sitl ARGS`` (see :func:`autopilot_model.sitl.add_autopilot_arguments`),
    or another ``module`` printing the same READY line (``autopilot_model.fleet``: many vehicles).

    :meth:`start` returns once the child has printed ``READY`` (RuntimeError, with the child's last
    output in the log, if it exits or stays silent first); :meth:`stop` is idempotent. A context manager:
    leaving the block (normally, on an error or on Ctrl-C) stops the child."""

    def __init__(self, args: Sequence[str], *, name: str = "autopilot-model",
                 module: str = "autopilot_model.sitl") -> None:
        self.args = [sys.executable, "-m", module, *args]
        self.name = name
        self.ready_line = ""
        self.returncode: int | None = None
        self._tail: deque[str] = deque(maxlen=20)
        self._ready = threading.Event()
        self._proc: subprocess.Popen[str] | None = None
        self._reader: threading.Thread | None = None

    def start(self, timeout_s: float = 60.0) -> ModelProcess:
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(p for p in (str(_ROOT), env.get("PYTHONPATH", "")) if p)
        env["PYTHONUNBUFFERED"] = "1"
        log.debug("%s: %s", self.name, " ".join(self.args))
        self._proc = subprocess.Popen(self.args, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                      stderr=subprocess.STDOUT, text=True, bufsize=1)
        self._reader = threading.Thread(target=self._drain, name=f"{self.name}-output", daemon=True)
        self._reader.start()
        end = time.monotonic() + timeout_s
        try:
            while not self._ready.wait(0.05):
                exited = self._proc.poll()
                if exited is not None or time.monotonic() > end:
                    self.stop()
                    tail = "\n".join(self._tail)
                    why = (f"exited with status {exited}" if exited is not None
                           else f"printed no READY line in {timeout_s:g} s")
                    raise RuntimeError(f"{self.name} {why}" + (f"; its last output:\n{tail}" if tail else ""))
        except BaseException:  # Ctrl-C while it starts, too
            self.stop()
            raise
        return self

    def _drain(self) -> None:
        assert self._proc is not None and self._proc.stdout is not None
        for line in self._proc.stdout:  # until the child closes its end (exits)
            text = line.rstrip()
            self._tail.append(text)
            if not self._ready.is_set() and text.startswith("READY"):
                self.ready_line = text
                self._ready.set()
            log.debug("%s: %s", self.name, text)

    @property
    def pid(self) -> int | None:
        return self._proc.pid if self._proc is not None else None

    @property
    def running(self) -> bool:
        return self._proc is not None and self._proc.poll() is None

    def stop(self, timeout_s: float = 10.0) -> int | None:
        """SIGTERM (the model stops its loop and closes its endpoint), wait, SIGKILL if it will not."""
        proc = self._proc
        if proc is None:
            return None
        self.returncode = stop_child(proc, timeout_s, self.name)
        if self._reader is not None and self._reader is not threading.current_thread():
            self._reader.join(2.0)
        if proc.stdout is not None and (self._reader is None or not self._reader.is_alive()):
            proc.stdout.close()
        return self.returncode

    def __enter__(self) -> ModelProcess:
        # ``with proc.start(t):`` enters a started child: starting it again would leave the first behind
        return self if self._proc is not None else self.start()

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.stop()
