"""MAVLink commands (COMMAND_LONG) with ACK tracking and retries (the MAVLink command protocol).

The MAVLink command protocol: send, wait for COMMAND_ACK; with no ACK within ``timeout_s`` of
autopilot time, send again with ``confirmation`` incremented, up to ``attempts`` sends; then the
command has failed and the error is kept for the status. One command per id is outstanding at a time
(a new request of the same id supersedes the old one). MAV_RESULT_IN_PROGRESS keeps waiting.

Threads: :meth:`CommandTracker.on_ack` runs in the receive thread, everything else in the node's
tick thread; one lock guards the table.
"""

from __future__ import annotations

import logging
import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

log = logging.getLogger(__name__)
M = mavlink

RESULT_NAMES = {M.MAV_RESULT_ACCEPTED: "ACCEPTED", M.MAV_RESULT_TEMPORARILY_REJECTED: "TEMPORARILY_REJECTED",
                M.MAV_RESULT_DENIED: "DENIED", M.MAV_RESULT_UNSUPPORTED: "UNSUPPORTED",
                M.MAV_RESULT_FAILED: "FAILED", M.MAV_RESULT_IN_PROGRESS: "IN_PROGRESS"}


def command_name(command: int) -> str:
    entry = M.enums["MAV_CMD"].get(command)
    return entry.name if entry is not None else f"MAV_CMD {command}"


class CommandState(Enum):
    PENDING = "PENDING"
    ACCEPTED = "ACCEPTED"
    REJECTED = "REJECTED"  # an ACK with another result
    TIMEOUT = "TIMEOUT"  # no ACK after every attempt
    SUPERSEDED = "SUPERSEDED"


@dataclass
class CommandRequest:
    """One outstanding (or finished) command."""

    command: int
    params: tuple[float, ...]
    sent_s: float = 0.0
    attempts: int = 0
    state: CommandState = CommandState.PENDING
    result: int | None = None
    on_done: list[Callable[[CommandRequest], None]] = field(default_factory=list)

    @property
    def name(self) -> str:
        return command_name(self.command)

    @property
    def done(self) -> bool:
        return self.state is not CommandState.PENDING

    @property
    def accepted(self) -> bool:
        return self.state is CommandState.ACCEPTED

    def describe(self) -> str:
        if self.state is CommandState.REJECTED:
            return f"{self.name}: {RESULT_NAMES.get(self.result or 0, self.result)}"
        return f"{self.name}: {self.state.value}"


class CommandTracker:
    """Outstanding commands keyed by command id; sends through ``send(command, confirmation, params)``."""

    def __init__(self, send: Callable[[int, int, tuple[float, ...]], None], timeout_s: float = 1.0,
                 attempts: int = 3, max_errors: int = 20) -> None:
        self._send = send
        self.timeout_s = timeout_s
        self.attempts = attempts
        self._lock = threading.Lock()
        self._pending: dict[int, CommandRequest] = {}
        self.errors: deque[str] = deque(maxlen=max_errors)
        self.sent = 0
        self.retries = 0

    def request(self, command: int, params: tuple[float, ...], now_s: float,
                on_done: Callable[[CommandRequest], None] | None = None) -> CommandRequest:
        """Send ``command`` now; returns its :class:`CommandRequest` (watch ``state``)."""
        req = CommandRequest(command, tuple(float(p) for p in params) + (0.0,) * (7 - len(params)))
        if on_done is not None:
            req.on_done.append(on_done)
        with self._lock:
            old = self._pending.pop(command, None)
            self._pending[command] = req
        if old is not None and not old.done:
            old.state = CommandState.SUPERSEDED
        self._transmit(req, now_s)
        return req

    def _transmit(self, req: CommandRequest, now_s: float) -> None:
        req.sent_s = now_s
        confirmation = req.attempts
        req.attempts += 1
        self.sent += 1
        if confirmation:
            self.retries += 1
            log.info("no ACK for %s: retry %d", req.name, confirmation)
        self._send(req.command, confirmation, req.params)

    def on_ack(self, msg: Any) -> None:
        """COMMAND_ACK from the autopilot (receive thread)."""
        with self._lock:
            req = self._pending.get(msg.command)
            if req is None or req.done or msg.result == M.MAV_RESULT_IN_PROGRESS:
                return
            del self._pending[msg.command]
        req.result = msg.result
        if msg.result == M.MAV_RESULT_ACCEPTED:
            req.state = CommandState.ACCEPTED
        else:
            req.state = CommandState.REJECTED
            self._error(req.describe())
        self._finish(req)

    def periodic(self, now_s: float) -> None:
        """Retry what timed out; give up after ``attempts`` sends (tick thread)."""
        with self._lock:
            due = [r for r in self._pending.values()
                   if now_s - r.sent_s >= self.timeout_s or now_s < r.sent_s]
        for req in due:
            if req.attempts < self.attempts:
                self._transmit(req, now_s)
                continue
            with self._lock:
                if self._pending.get(req.command) is req:
                    del self._pending[req.command]
            req.state = CommandState.TIMEOUT
            self._error(f"{req.name}: no COMMAND_ACK after {req.attempts} attempts")
            self._finish(req)

    def _error(self, text: str) -> None:
        log.warning("command failed: %s", text)
        self.errors.append(text)

    @staticmethod
    def _finish(req: CommandRequest) -> None:
        for cb in req.on_done:
            try:
                cb(req)
            except Exception:
                log.exception("command callback failed")

    @property
    def pending(self) -> list[str]:
        with self._lock:
            return [r.name for r in self._pending.values()]
