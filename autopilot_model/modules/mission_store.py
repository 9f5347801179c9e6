"""The stored mission plans of the autopilot model (:class:`MissionStore`): one list per mission type
(MISSION, FENCE, RALLY), the current flight-plan item, persisted per instance. Re-exported by
:mod:`.mission`.
"""

from __future__ import annotations

import json
import logging
import os
from collections.abc import Callable, Iterable
from dataclasses import replace
from pathlib import Path

from .mission_items import ACCEPTED, MISSION, MISSION_TYPES, MissionItem, validate_item, validate_plan

log = logging.getLogger("autopilot_model.modules.mission")


class MissionStore:
    """The stored plans, one list per mission type, and the current flight-plan item.

    ``replace`` swaps a whole plan at once (the protocol uploads into a staging list and calls it only
    when the upload succeeded), so a failed upload never leaves a half-written plan. With a path, the
    plans are loaded from it and every change is written back (atomically), one file per instance.
    """

    def __init__(self, path: str | Path | None = None) -> None:
        self._plans: dict[int, list[MissionItem]] = {t: [] for t in MISSION_TYPES}
        self.current = 0
        self.running = False
        """True while AUTO executes the flight plan (set by :class:`MissionRunner`)."""
        self._listeners: list[Callable[[int], None]] = []
        self._current_listeners: list[Callable[[int], None]] = []
        self._path = Path(path) if path is not None else None
        if self._path is not None:
            self._load()

    # --- reading --------------------------------------------------------------------------------
    @property
    def items(self) -> list[MissionItem]:
        """The flight plan (mission type MISSION), item 0 being home."""
        return list(self._plans[MISSION])

    def get(self, mission_type: int = MISSION) -> list[MissionItem]:
        return list(self._plans[mission_type])

    def count(self, mission_type: int = MISSION) -> int:
        return len(self._plans[mission_type])

    def item(self, seq: int, mission_type: int = MISSION) -> MissionItem:
        return self._plans[mission_type][seq]

    # --- writing --------------------------------------------------------------------------------
    def replace(self, mission_type: int, items: Iterable[MissionItem]) -> None:
        """Swap in a whole plan (seq renumbered 0..n-1, mission_type set) and persist it."""
        new = [replace(it, seq=i, mission_type=mission_type) for i, it in enumerate(items)]
        self._plans[mission_type] = new
        if mission_type == MISSION and self.current >= len(new):
            self.current = 0
        log.info("stored %d item(s) of mission type %d", len(new), mission_type)
        self._save()
        for cb in list(self._listeners):
            cb(mission_type)

    def clear(self, mission_type: int) -> None:
        self.replace(mission_type, [])

    def set_current(self, seq: int) -> bool:
        """Make ``seq`` the current flight-plan item; False (unchanged) if out of range."""
        if not 0 <= seq < self.count(MISSION):
            return False
        if seq != self.current:
            self.current = seq
            self._save()
            for cb in list(self._current_listeners):
                cb(seq)
        return True

    def on_change(self, callback: Callable[[int], None]) -> None:
        """Call ``callback(mission_type)`` after a plan is replaced or cleared."""
        self._listeners.append(callback)

    def on_current(self, callback: Callable[[int], None]) -> None:
        """Call ``callback(seq)`` when the current item changes."""
        self._current_listeners.append(callback)

    # --- persistence ----------------------------------------------------------------------------
    def _load(self) -> None:
        assert self._path is not None
        if not self._path.exists():
            return
        try:
            data = json.loads(self._path.read_text(encoding="utf-8"))
            plans = {int(t): [MissionItem.from_dict(d) for d in items]
                     for t, items in data.get("plans", {}).items() if int(t) in MISSION_TYPES}
            current = int(data.get("current", 0))
        except (OSError, ValueError, TypeError, AttributeError) as exc:
            log.warning("ignoring unreadable mission file %s: %s", self._path, exc)
            return
        for t, items in plans.items():
            bad = next((r for r in (validate_item(i) for i in items) if r != ACCEPTED), ACCEPTED)
            if bad != ACCEPTED or validate_plan(t, items) != ACCEPTED:
                log.warning("%s: stored plan of type %d is invalid (%d); dropped", self._path, t, bad)
                continue
            self._plans[t] = items
        self.current = current if 0 <= current < max(1, len(self._plans[MISSION])) else 0

    def _save(self) -> None:
        if self._path is None:
            return
        data = {"version": 1, "current": self.current,
                "plans": {str(t): [i.to_dict() for i in items] for t, items in self._plans.items()}}
        self._path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self._path.with_suffix(".tmp")
        tmp.write_text(json.dumps(data, indent=1), encoding="utf-8")
        os.replace(tmp, self._path)
