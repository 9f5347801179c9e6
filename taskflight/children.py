"""Child processes of ``taskflight up``: started, logged, watched and stopped together.

Each child runs in a process group of its own (in the session of ``taskflight up``: one scheduler
autogroup for the whole fleet, so the models' process competes with its own companions, whose niceness
then means something, rather than each child counting as a user of the machine of its own), with its
output appended to a log file: a Ctrl-C at the terminal reaches ``taskflight up`` alone (the terminal
signals its foreground process group only), which then stops the children in order
(:func:`stop_all`: SIGTERM to all of them at once, one shared deadline, then SIGKILL to each one's whole
process group, so nothing it started is left behind either). A ``taskflight up`` killed with SIGKILL
cannot do that: each child then stops by itself (:func:`taskflight_common.runtime.die_with_parent`, the
kernel's
parent-death signal). :attr:`Child.tail` reads the last lines of the log, for the message when a child dies
during start-up.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import subprocess
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from taskflight_common.runtime import PARENT_ENV

log = logging.getLogger(__name__)


@dataclass
class Child:
    """One child process: ``name``, its command line and the log its output goes to."""

    name: str
    argv: list[str]
    log_path: Path
    env: dict[str, str] | None = None
    cwd: Path | None = None
    proc: subprocess.Popen[bytes] | None = field(default=None, repr=False)

    def start(self) -> Child:
        self.log_path.parent.mkdir(parents=True, exist_ok=True)
        env = dict(os.environ)
        env["PYTHONUNBUFFERED"] = "1"
        env[PARENT_ENV] = str(os.getpid())  # the child stops if this process dies (runtime.die_with_parent)
        if self.env:
            env.update(self.env)
        with open(self.log_path, "ab") as out:  # the child keeps its own descriptor
            self.proc = subprocess.Popen(self.argv, stdin=subprocess.DEVNULL, stdout=out,
                                         stderr=subprocess.STDOUT, env=env, cwd=self.cwd,
                                         process_group=0)
        log.debug("%s: pid %d: %s", self.name, self.proc.pid, " ".join(self.argv))
        return self

    @property
    def pid(self) -> int | None:
        return self.proc.pid if self.proc is not None else None

    @property
    def returncode(self) -> int | None:
        return self.proc.poll() if self.proc is not None else None

    @property
    def running(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def tail(self, lines: int = 15) -> str:
        """The last ``lines`` lines of the child's log (empty if none)."""
        try:
            with open(self.log_path, "rb") as f:
                f.seek(0, os.SEEK_END)
                f.seek(max(0, f.tell() - 16384))
                text = f.read().decode("utf-8", "replace")
        except OSError:
            return ""
        return "\n".join(text.splitlines()[-lines:])

    def signal_group(self, sig: int) -> None:
        """Send ``sig`` to the child's process group (the child and anything it started)."""
        if self.proc is None:
            return
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(self.proc.pid, sig)


def stop_all(children: Sequence[Child], timeout_s: float = 10.0) -> dict[str, int | None]:
    """Stop ``children``: SIGTERM to every one still running, wait until all have exited or
    ``timeout_s`` passed, SIGKILL the process group of any left, reap them all; their exit statuses.

    The group is killed even when the child itself exited (a grandchild it left is stopped too)."""
    running = [c for c in children if c.running]
    for c in running:
        assert c.proc is not None
        with contextlib.suppress(ProcessLookupError):
            c.proc.send_signal(signal.SIGTERM)
    end = time.monotonic() + timeout_s
    for c in running:
        assert c.proc is not None
        try:
            c.proc.wait(max(0.0, end - time.monotonic()))
        except subprocess.TimeoutExpired:
            log.warning("%s (pid %d) did not stop in %.0f s; killing it", c.name, c.proc.pid, timeout_s)
    out: dict[str, int | None] = {}
    for c in children:
        if c.proc is None:
            out[c.name] = None
            continue
        c.signal_group(signal.SIGKILL)
        try:
            c.proc.wait(5.0)
        except subprocess.TimeoutExpired:  # pragma: no cover - SIGKILL cannot be ignored
            log.error("%s (pid %d) survived SIGKILL", c.name, c.proc.pid)
        out[c.name] = c.proc.returncode
    return out


def first_dead(children: Sequence[Child]) -> Child | None:
    """The first child that was started and has exited, if any."""
    return next((c for c in children if c.proc is not None and c.proc.poll() is not None), None)

