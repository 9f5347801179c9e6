"""The mission's "do" and "condition" commands and DO_JUMP, as ArduPilot's ``AP_Mission`` runs them.

``AP_Mission`` keeps two pointers: the navigation command being flown, and a "do" command run beside
it. Advancing to the next navigation command (``advance_current_nav_cmd``) walks the plan from the
item after the last one, following DO_JUMPs (:func:`next_cmd`: param1 the target item, param2 the
number of jumps, -1 forever; each jump counted, the counter reset once exhausted), starting the first
do command it passes and then the navigation command. The do commands after that one, up to the next
navigation command, follow one by one (``advance_current_do_cmd``), each started when the previous one
is verified: DO_CHANGE_SPEED and DO_SET_ROI complete at once, CONDITION_DELAY after param1 seconds,
CONDITION_YAW once the heading is within 2 degrees. So a condition holds back the do commands after it,
never the navigation.

:class:`DoCommands` starts and verifies the do commands for a :class:`~.mission.MissionRunner`.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from typing import TYPE_CHECKING

from .mission_items import (
    CONDITION_DELAY,
    CONDITION_YAW,
    DO_CHANGE_SPEED,
    DO_JUMP,
    DO_SET_ROI,
    DO_SET_ROI_LOCATION,
    DO_SET_ROI_NONE,
    MISSION,
    NAV_COMMANDS,
    RELATIVE_FRAMES,
    MissionItem,
)

if TYPE_CHECKING:
    from .mission import MissionRunner
    from .mission_store import MissionStore

log = logging.getLogger("autopilot_model.modules.mission")

JUMP_FOREVER = -1
_MAX_JUMPS = 64  # AP_Mission::get_next_cmd's loop limit


def next_cmd(store: MissionStore, start: int, jumps: dict[int, int], increment: bool,
             say: Callable[[str], None] | None = None) -> MissionItem | None:
    """The first item at or after ``start`` that is not a DO_JUMP, following jumps (``get_next_cmd``).

    ``jumps`` counts the jumps taken per DO_JUMP item; ``increment`` (the navigation walk) counts them,
    the do-command walk only looks (and stops at a jump it has already passed)."""
    n = store.count(MISSION)
    idx = start
    first_jump: int | None = None
    loops = _MAX_JUMPS
    while idx < n:
        it = store.item(idx)
        if it.command != DO_JUMP:
            return it
        loops -= 1
        if loops < 0:
            return None
        target = int(it.param1) if math.isfinite(it.param1) else 0
        if target <= 0 or target >= n:
            return None
        if not increment and first_jump == idx:
            return None
        if first_jump is None:
            first_jump = idx
        times = int(it.param2) if math.isfinite(it.param2) else 0
        done = jumps.get(idx, 0)
        if times == JUMP_FOREVER or done < times:
            if increment:
                jumps[idx] = done + 1
                if say is not None:
                    total = "unlimited" if times == JUMP_FOREVER else str(times)
                    say(f"Mission: {idx} Jump {done + 1}/{total}")
            idx = target
        else:
            if increment:
                jumps[idx] = 0  # loop completed: counted afresh if the plan comes back here
            idx += 1
    return None


class DoCommands:
    """The do command beside the navigation command: start, verify, advance."""

    def __init__(self, runner: MissionRunner) -> None:
        self.r = runner
        self.item: MissionItem | None = None
        self.last_seq: int | None = None
        self.all_done = True
        self._t0 = 0.0

    def reset(self) -> None:
        self.item = None
        self.last_seq = None
        self.all_done = False

    def start(self, item: MissionItem) -> None:
        r = self.r
        self.item = item
        self.last_seq = item.seq
        c = item.command
        log.info("mission: do item %d, command %d", item.seq, c)
        yaw = r.auto_yaw()
        if c == DO_CHANGE_SPEED:
            r.change_speed(item)
        elif c == CONDITION_DELAY:
            self._t0 = r.now()
        elif c == CONDITION_YAW:
            if yaw is not None:
                angle = item.param1 if math.isfinite(item.param1) else 0.0
                yaw.set_fixed(angle, _f(item.param2), _f(item.param3), _f(item.param4) > 0)
        elif c in (DO_SET_ROI, DO_SET_ROI_LOCATION):
            if yaw is not None:
                home_alt = r.home_alt()
                alt = item.z + home_alt if item.frame in RELATIVE_FRAMES else item.z
                yaw.set_roi(item.lat, item.lon, alt)
        elif c == DO_SET_ROI_NONE and yaw is not None:
            yaw.reset()

    def verified(self) -> bool:
        """``verify_command`` of the loaded do command (True when none is loaded)."""
        item = self.item
        if item is None:
            return True
        if item.command == CONDITION_DELAY:
            return self.r.now() - self._t0 > max(0.0, _f(item.param1))
        if item.command == CONDITION_YAW:
            yaw = self.r.auto_yaw()
            return yaw is None or yaw.reached()
        return True

    def advance(self, store: MissionStore, jumps: dict[int, int]) -> None:
        """``advance_current_do_cmd``: the next do command before the next navigation command."""
        if self.all_done:
            return
        nav = self.r.nav_item
        start = (self.last_seq if self.last_seq is not None else nav.seq) + 1
        it = next_cmd(store, start, jumps, increment=False) if start < store.count(MISSION) else None
        if it is None or it.command in NAV_COMMANDS:
            self.all_done = True
            self.item = None
            return
        self.start(it)


def _f(x: float) -> float:
    return x if math.isfinite(x) else 0.0
