"""Autopilot parameters through the companion's own link: read, and set with read-back.

Seed 003 Sec. II (the Process Monitor: "in-flight gain tuning for low-level controllers") and the
MAVLink parameter protocol (https://mavlink.io/en/services/parameter.html): PARAM_REQUEST_READ by name
is answered with PARAM_VALUE; PARAM_SET is answered with the PARAM_VALUE the autopilot now holds, which
is the read-back (an autopilot clamps or refuses a value by answering with the value it kept). A request
without an answer is sent again (``attempts``, every ``timeout_s`` of wall time). ArduPilot keeps
parameter values as float32 and types them MAV_PARAM_TYPE_REAL32 unless the name is an integer one;
the type the autopilot reported is reused when setting.

Guarded writes (:mod:`mission_specs.param_table`): a write is sent only for a name in the table of the
autopilot on the link, inside its range, and, while the vehicle is armed, within 50 % of the value read
first (PARAM_REQUEST_READ, the "old" value) unless forced. Which table: the autopilot's AUTOPILOT_VERSION
(asked once with MAV_CMD_REQUEST_MESSAGE) names the model in ``flight_custom_version`` (``tfmodel``); any
other answer, or none, is ArduCopter (its documented ranges are the stricter default).
"""

from __future__ import annotations

import math
import re
import threading
from dataclasses import dataclass
from typing import Any

from pymavlink import mavutil

from mission_specs.param_table import ParamSpec, ParamTable, ParamWriteError, table

from .connection import MavlinkLink

M = mavutil.mavlink

#: AUTOPILOT_VERSION.flight_custom_version of the Taskflight autopilot model
MODEL_SIGNATURE = b"tfmodel"

#: the protocol's name rule: up to 16 characters, ArduPilot uses A-Z, 0-9 and _
NAME_RE = re.compile(r"^[A-Z][A-Z0-9_]{0,15}$")


class ParamError(RuntimeError):
    """A parameter the autopilot does not answer for, or a value it did not keep."""


@dataclass(frozen=True)
class ParamValue:
    name: str
    value: float
    param_type: int
    index: int
    count: int
    old: float | None = None
    """The value read before a write (None for a read)."""


class ParamClient:
    """Reads and sets the autopilot's parameters over ``link`` (thread-safe; calls block)."""

    def __init__(self, link: MavlinkLink, timeout_s: float = 1.0, attempts: int = 3) -> None:
        self.link = link
        self.timeout_s = timeout_s
        self.attempts = attempts
        self.known: dict[str, ParamValue] = {}
        self._cond = threading.Condition()
        self._serial = threading.Lock()
        self._version: Any = None
        self._table: ParamTable | None = None
        link.listeners.append(self._on_message)

    def _on_message(self, msg: Any) -> None:
        if msg.get_type() == "AUTOPILOT_VERSION":
            with self._cond:
                self._version = msg
                self._cond.notify_all()
            return
        if msg.get_type() != "PARAM_VALUE":
            return
        name = msg.param_id.decode("ascii", "replace") if isinstance(msg.param_id, bytes) else msg.param_id
        name = name.rstrip("\x00")
        with self._cond:
            self.known[name] = ParamValue(name, float(msg.param_value), int(msg.param_type),
                                          int(msg.param_index), int(msg.param_count))
            self._cond.notify_all()

    @staticmethod
    def check_name(name: str) -> str:
        if not NAME_RE.match(name):
            raise ValueError(f"parameter name {name!r}: 1-16 characters A-Z, 0-9 and _, "
                             "starting with a letter")
        return name

    def get(self, name: str) -> ParamValue:
        """The autopilot's value now (asked over the link)."""
        self.check_name(name)
        with self._serial:
            return self._exchange(name, lambda: self.link.send_param_request(name))

    def table(self) -> ParamTable:
        """The table of the autopilot on the link (asked once; ArduCopter's without an answer)."""
        if self._table is not None:
            return self._table
        if self.link.target_system is None:
            raise ParamError("no autopilot heard yet")
        with self._cond:
            self._version = None
        for _ in range(self.attempts):
            self.link._send_command(M.MAV_CMD_REQUEST_MESSAGE, 0,
                                    (float(M.MAVLINK_MSG_ID_AUTOPILOT_VERSION), 0, 0, 0, 0, 0, 0))
            with self._cond:
                if self._cond.wait_for(lambda: self._version is not None, timeout=self.timeout_s):
                    break
        custom = bytes(getattr(self._version, "flight_custom_version", b"") or b"")
        self._table = table("model" if custom.startswith(MODEL_SIGNATURE) else "arducopter")
        return self._table

    def spec(self, name: str) -> ParamSpec | None:
        """``name``'s entry in the autopilot's table (None: not a parameter written through here)."""
        t = self.table()
        return t.params.get(name)

    def set(self, name: str, value: float, force: bool = False) -> ParamValue:
        """Set ``name`` and return the value the autopilot answers with (the read-back; ``old``: the
        value read first). :class:`~mission_specs.param_table.ParamWriteError` (nothing written) for a name
        outside the autopilot's table, a value outside its range, or more than a 50 % change while armed
        without ``force``."""
        self.check_name(name)
        t = self.table()
        t.check(name, value)  # name and range, before anything is asked of the autopilot
        current = self.get(name)  # the old value; unknown names fail here too, before anything is written
        armed = bool(self.link.mirror.snapshot().armed)
        v = t.check(name, value, old=current.value, in_flight=armed, force=force)
        with self._serial:
            answer = self._exchange(name, lambda: self.link.send_param_set(name, v, current.param_type))
        if not math.isclose(answer.value, v, rel_tol=1e-6, abs_tol=1e-6):
            raise ParamError(f"{name}: the autopilot kept {answer.value:g}, not {v:g}")
        return ParamValue(answer.name, answer.value, answer.param_type, answer.index, answer.count,
                          old=current.value)

    def _exchange(self, name: str, send: Any) -> ParamValue:
        if self.link.target_system is None:
            raise ParamError("no autopilot heard yet")
        with self._cond:
            self.known.pop(name, None)
        for _ in range(self.attempts):
            send()
            with self._cond:
                got = self._cond.wait_for(lambda: name in self.known, timeout=self.timeout_s)
                if got:
                    return self.known[name]
        raise ParamError(f"{name}: no PARAM_VALUE from the autopilot after {self.attempts} attempts "
                         f"(unknown parameter?)")


__all__ = ["ParamClient", "ParamError", "ParamValue", "ParamWriteError"]
