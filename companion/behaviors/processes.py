"""The process manager and the execution processes (seed 001 Sec. 6.2.3, Fig. 10).

Execution processes are the in-process services behaviors need (named in the catalog's
``processes``): the motion controller (the flight-command queue executing and streaming), the
trajectory planner, the velocity source of KEEP_MOVING, the joystick feed. Each is an
:class:`ExecutionProcess` with ``start()`` / ``stop()`` and, optionally, ``tick(now_s)`` for work it
does periodically (called by the executive layer's monitor loop while it runs).

:class:`ProcessManager` keeps a reference counter ``r_i`` per process: ``request_start(names, by)``
increments and starts what is not running; ``release(names, by)`` decrements but does **not** stop
("the process is not immediately stopped when the service of informing unused process is called. It
is delayed to keep the process running after the service of requesting start processes is called");
:meth:`ProcessManager.collect` stops every process whose counter is zero. The behavior coordinator
calls ``collect()`` once a reconfiguration (stops, then starts) is complete, so a process released
by one behavior and requested by the next keeps running. Every start and stop is recorded with its
time (:attr:`ProcessManager.trace`) and, when a log is attached, written to it.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

log = logging.getLogger(__name__)


class ProcessError(RuntimeError):
    """A process is unknown, or could not be started."""


class ExecutionProcess:
    """One execution process (override :meth:`on_start`, :meth:`on_stop`, :meth:`tick`)."""

    name = "process"

    def __init__(self) -> None:
        self.running = False
        self.starts = 0

    def start(self) -> None:
        self.on_start()
        self.running = True
        self.starts += 1

    def stop(self) -> None:
        self.running = False
        self.on_stop()

    def on_start(self) -> None:
        """Begin the work (raise :class:`ProcessError` if it cannot)."""

    def on_stop(self) -> None:
        """End the work; must not raise."""

    def tick(self, now_s: float) -> None:
        """Periodic work while running (autopilot time ``now_s``)."""

    def status(self) -> dict[str, Any]:
        return {"running": self.running, "starts": self.starts}


@dataclass(frozen=True)
class ProcessEvent:
    """One start or stop (Fig. 10's red bars begin and end here)."""

    t_s: float
    process: str
    event: str  # "start" | "stop"
    by: str

    def to_dict(self) -> dict[str, Any]:
        return {"t": round(self.t_s, 4), "type": "process", "event": self.event, "process": self.process,
                "by": self.by}


class ProcessManager:
    """Reference-counted processes with the delayed stop (see module docstring). Thread-safe."""

    def __init__(self, processes: Iterable[ExecutionProcess], now: Callable[[], float],
                 sink: Callable[[dict[str, Any]], None] | None = None, keep: int = 5000) -> None:
        self._procs: dict[str, ExecutionProcess] = {}
        for p in processes:
            if p.name in self._procs:
                raise ValueError(f"process {p.name} registered twice")
            self._procs[p.name] = p
        self._refs: dict[str, int] = dict.fromkeys(self._procs, 0)
        self._last_user: dict[str, str] = {}
        self._now = now
        self._sink = sink
        self._keep = keep
        self._lock = threading.RLock()
        self.trace: list[ProcessEvent] = []

    def __contains__(self, name: object) -> bool:
        return name in self._procs

    def get(self, name: str) -> ExecutionProcess:
        try:
            return self._procs[name]
        except KeyError:
            known = ", ".join(sorted(self._procs))
            raise ProcessError(f"unknown process {name!r} (known: {known})") from None

    def names(self) -> list[str]:
        return list(self._procs)

    def check(self, names: Iterable[str]) -> None:
        for n in names:
            self.get(n)

    def request_start(self, names: Iterable[str], by: str) -> None:
        """Count a user of each process and start those not running (Sec. 6.2.3 "requesting start")."""
        names = list(names)
        with self._lock:
            self.check(names)
            counted: list[str] = []
            started: list[str] = []
            try:
                for n in names:
                    proc = self._procs[n]
                    if not proc.running:
                        proc.start()
                        started.append(n)
                        self._record(n, "start", by)
                    self._refs[n] += 1
                    counted.append(n)
                    self._last_user[n] = by
            except Exception:
                for n in counted:  # all or none: undo what this call did
                    self._refs[n] -= 1
                for n in started:
                    if self._refs[n] == 0:
                        self._procs[n].stop()
                        self._record(n, "stop", by)
                raise

    def release(self, names: Iterable[str], by: str) -> None:
        """"Informing unused processes": count one user less; the stop waits for :meth:`collect`."""
        with self._lock:
            for n in names:
                if n in self._refs and self._refs[n] > 0:
                    self._refs[n] -= 1
                    self._last_user[n] = by

    def collect(self) -> list[str]:
        """Stop every running process nobody uses any more; returns their names."""
        stopped = []
        with self._lock:
            for n, proc in self._procs.items():
                if proc.running and self._refs[n] == 0:
                    try:
                        proc.stop()
                    except Exception:
                        log.exception("process %s failed to stop cleanly", n)
                        proc.running = False
                    self._record(n, "stop", self._last_user.get(n, ""))
                    stopped.append(n)
        return stopped

    def tick(self, now_s: float) -> None:
        """Each running process's periodic work."""
        with self._lock:
            running = [p for p in self._procs.values() if p.running]
        for p in running:
            try:
                p.tick(now_s)
            except Exception:
                log.exception("process %s tick failed", p.name)

    def references(self) -> dict[str, int]:
        with self._lock:
            return dict(self._refs)

    def status(self) -> list[dict[str, Any]]:
        with self._lock:
            return [{"process": n, "references": self._refs[n], **p.status()} for n, p in self._procs.items()]

    def _record(self, name: str, event: str, by: str) -> None:
        ev = ProcessEvent(self._now(), name, event, by)
        self.trace.append(ev)
        if len(self.trace) > self._keep:
            del self.trace[: len(self.trace) - self._keep]
        log.info("process %s %s (%s)", name, event, by)
        if self._sink is not None:
            self._sink(ev.to_dict())
