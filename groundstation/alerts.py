"""Alerts the ground derives from what it reads of each vehicle (seed 000 Sec. VII: the operator is told
what needs him; seed 003 Sec. II: the fleet list shows each UAV's most recent communication).

:class:`AlertWatch` looks at every fleet record (:meth:`groundstation.fleet.Fleet.snapshot`) once a
period and emits an event on each crossing, once (not on every look):

* ``battery_low`` / ``battery_critical``: the remaining charge below :data:`~.fleet.BATTERY_LOW` /
  :data:`~.fleet.BATTERY_CRITICAL` (back above the threshold plus :data:`BATTERY_HYSTERESIS` re-arms it);
* ``link_lost`` (nothing heard from the vehicle for :data:`~.fleet.LOST_S`) and ``link_restored``;
* ``duplicate_id``: the vehicle's companion says its id is taken by another member (its status's
  ``team.duplicate_id``; the team link refuses to join a second member with one id).

The failsafe (the autopilot switched to a failsafe mode), override (QAPI ``OVERRIDDEN``) and
confirmation-required events come from the poller (:meth:`~.fleet.Fleet._watch`), the team link's
``gone`` from the station. The alert kinds the UI lists are :data:`ALERT_KINDS`.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from .fleet import BATTERY_CRITICAL, BATTERY_LOW, LOST_S

#: the event kinds that are alerts (listed in the UI, acknowledged by an operator)
ALERT_KINDS = ("failsafe", "override", "link_lost", "battery_low", "battery_critical", "duplicate_id",
               "confirmation_required", "detection", "conflict")
#: percent above a threshold before the battery alert re-arms
BATTERY_HYSTERESIS = 3.0

Emit = Callable[..., None]


@dataclass
class _State:
    battery: str = "ok"          #: ok, low, critical
    lost: bool = False
    duplicate: bool = False


class AlertWatch:
    """See module docstring. ``emit(kind, message, severity=, vehicle=, data=)``."""

    def __init__(self, emit: Emit) -> None:
        self.emit = emit
        self._state: dict[int, _State] = {}
        self._lock = threading.Lock()

    def look(self, records: list[dict[str, Any]], duplicates: dict[int, Any] | None = None) -> None:
        """One look at the fleet (``duplicates``: vehicle -> what its companion says of a duplicate id)."""
        with self._lock:
            for rec in records:
                self._look(rec, (duplicates or {}).get(rec["id"]))

    def _look(self, rec: dict[str, Any], duplicate: Any) -> None:
        vid = rec["id"]
        st = self._state.setdefault(vid, _State())
        name = rec.get("name") or f"vehicle {vid}"
        batt = rec.get("battery")
        if isinstance(batt, int | float) and batt >= 0:
            level = "critical" if batt < BATTERY_CRITICAL else "low" if batt < BATTERY_LOW else "ok"
            order = {"ok": 0, "low": 1, "critical": 2}
            if order[level] > order[st.battery]:
                st.battery = level
                self.emit(f"battery_{level}", f"{name} ({vid}): battery {batt:.0f} %",
                          severity="error" if level == "critical" else "warning", vehicle=vid,
                          data={"battery": batt})
            elif level != st.battery:
                threshold = BATTERY_CRITICAL if st.battery == "critical" else BATTERY_LOW
                if batt >= threshold + BATTERY_HYSTERESIS:
                    st.battery = level
        age = rec.get("age_s")
        lost = isinstance(age, int | float) and age > LOST_S
        if lost and not st.lost:
            self.emit("link_lost", f"{name} ({vid}): nothing heard for {age:.1f} s", severity="warning",
                      vehicle=vid, data={"age_s": age, "reason": "not heard"})
        elif st.lost and not lost and age is not None:
            self.emit("link_restored", f"{name} ({vid}) heard again", vehicle=vid)
        st.lost = lost
        if duplicate and not st.duplicate:
            self.emit("duplicate_id", f"{name} ({vid}): duplicate id: another member uses id {vid} "
                                      f"({duplicate})", severity="error", vehicle=vid,
                      data={"duplicate": duplicate})
        st.duplicate = bool(duplicate)
