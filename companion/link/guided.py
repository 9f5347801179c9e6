"""Who flies the vehicle: GUIDED engagement, take-off, landing and override detection.

Issue 4 item 5 and seed 000 Sec. V (queue_system_status Overridden: "the backup pilot can override
the commands being executed"). :class:`GuidedSupervisor` decides, tick by tick, whether the queue's
setpoint is streamed, and asks the autopilot for the modes it needs. It relies only on documented
ArduCopter behaviour:

* GUIDED accepts SET_POSITION_TARGET_LOCAL_NED only in the air; on the ground a take-off needs
  GUIDED, arming, then MAV_CMD_NAV_TAKEOFF (param7: metres above home). A streamed target replaces
  the autopilot's own take-off, so streaming starts once the vehicle has left the ground
  (EXTENDED_SYS_STATE not ON_GROUND); until then the node holds the queue's time still.
* A landing command (allow-landing) whose reference reaches its altitude (``land_now``) switches to
  LAND mode; ArduCopter lands and disarms by itself. Streaming stops.
* Override: while engaged, any mode other than the ones we asked for (a GCS or RC switching to
  LOITER, a failsafe's RTL or LAND) or a disarm we did not cause makes the queue OVERRIDDEN and
  stops streaming. When someone puts the vehicle back into GUIDED the override is lifted; the queue
  then waits for ``run()``.

States: IDLE (not controlling; nothing streamed) -> TAKING_OFF -> ENGAGED (streaming) -> LANDING ->
IDLE; any of them -> OVERRIDDEN -> IDLE. All methods run in the node's tick thread.
"""

from __future__ import annotations

import logging
from collections import deque
from enum import Enum

from companion.flight.setpoint import Setpoint

from .commands import CommandRequest
from .connection import MavlinkLink
from .mirror import GUIDED, LAND, MirrorState

log = logging.getLogger(__name__)

#: Autopilot seconds between attempts of a refused step of the take-off sequence.
RETRY_PAUSE_S = 1.0
#: Attempts of each take-off step before giving up (each attempt is itself retried without ACK).
STEP_ATTEMPTS = 3
#: Autopilot seconds an accepted step may take to show in the telemetry before it is sent again.
STATE_TIMEOUT_S = 3.0


class Phase(Enum):
    IDLE = "IDLE"
    TAKING_OFF = "TAKING_OFF"
    ENGAGED = "ENGAGED"
    LANDING = "LANDING"
    OVERRIDDEN = "OVERRIDDEN"


class GuidedSupervisor:
    """The take-off / stream / land / override state machine (see module docstring)."""

    def __init__(self, link: MavlinkLink) -> None:
        self.link = link
        self.phase = Phase.IDLE
        self.errors: deque[str] = deque(maxlen=20)
        self.override_reason: str | None = None
        self._req: CommandRequest | None = None
        self._step = ""
        self._step_attempts = 0
        self._wait_until = 0.0
        self._takeoff_alt: float | None = None
        self._seen_guided = False
        self._armed_by_us = False
        self._error_once: set[str] = set()
        #: set when a take-off was given up; the node stops the queue and clears it
        self.abandoned = False

    # --- queries -----------------------------------------------------------------------------------
    @property
    def holds_queue(self) -> bool:
        """True while the node must not advance the queue (the autopilot is taking off)."""
        return self.phase is Phase.TAKING_OFF

    @property
    def overridden(self) -> bool:
        return self.phase is Phase.OVERRIDDEN

    def status(self) -> dict[str, object]:
        step = self._step if self.phase is Phase.TAKING_OFF else None
        return {"phase": self.phase.value, "takeoff_step": step,
                "override_reason": self.override_reason, "errors": list(self.errors)}

    # --- the per-tick decision ------------------------------------------------------------------------
    def check_override(self, s: MirrorState) -> str | None:
        """A reason if the vehicle was taken from us (only while we control it)."""
        if self.phase not in (Phase.ENGAGED, Phase.TAKING_OFF, Phase.LANDING) or s.mode is None:
            return None
        if self.phase is Phase.LANDING:
            if s.mode not in (GUIDED, LAND):
                return f"mode changed to {s.mode_name} while landing"
            return None
        if self.phase is Phase.TAKING_OFF and not self._seen_guided:
            return None
        if s.mode != GUIDED:
            return f"mode changed to {s.mode_name}"
        if not s.armed and (self.phase is Phase.ENGAGED or self._armed_by_us):
            return "vehicle disarmed"
        return None

    def observe(self, s: MirrorState) -> None:
        """Detect an override, or its end (someone put the vehicle back into GUIDED)."""
        reason = self.check_override(s)
        if reason is not None:
            self.override(reason)
        elif self.phase is Phase.OVERRIDDEN and s.mode == GUIDED:
            log.info("vehicle given back (GUIDED): override lifted")
            self.phase = Phase.IDLE
            self.override_reason = None

    def step(self, sp: Setpoint | None, s: MirrorState, now_s: float) -> bool:
        """Advance the state machine (after :meth:`observe`); True if ``sp`` is to be streamed now."""
        if self.phase is Phase.OVERRIDDEN:
            return False
        if sp is None:
            return False
        if self.phase is Phase.IDLE:
            return self._engage(sp, s, now_s)
        if self.phase is Phase.TAKING_OFF:
            return self._taking_off(sp, s, now_s)
        if self.phase is Phase.LANDING:
            if s.landed is True and not s.armed:
                log.info("landed and disarmed: link idle")
                self.phase = Phase.IDLE
            return False
        # ENGAGED
        if sp.allow_landing and sp.land_now:
            log.info("landing command reached its altitude: LAND")
            self._req = self.link.set_mode(LAND, now_s)
            self.phase = Phase.LANDING
            return False
        return True

    # --- transitions -----------------------------------------------------------------------------------
    def override(self, reason: str) -> None:
        log.warning("overridden: %s", reason)
        self.phase = Phase.OVERRIDDEN
        self.override_reason = reason
        self._req = None
        self.link.sync.clear()

    def _executing(self, sp: Setpoint) -> bool:
        return sp.command_index is not None or sp.behaviour_id is not None

    def _engage(self, sp: Setpoint, s: MirrorState, now_s: float) -> bool:
        if not self._executing(sp):
            return False
        on_ground = s.landed is True or not s.armed
        if sp.take_off and on_ground:
            self.phase = Phase.TAKING_OFF
            self._takeoff_alt = sp.takeoff_altitude
            self._seen_guided = s.mode == GUIDED
            self._armed_by_us = False
            self._start_step("mode", now_s)
            log.info("take-off: GUIDED, arm, MAV_CMD_NAV_TAKEOFF to %.1f m", sp.takeoff_altitude or 0.0)
            return False
        if on_ground:
            self._error_once_("vehicle on the ground and not armed: the first command must be a take-off")
            return False
        if s.mode != GUIDED:
            if self._req is None or (self._req.done and not self._req.accepted and now_s >= self._wait_until):
                self._req = self.link.set_mode(GUIDED, now_s)
                self._wait_until = now_s + RETRY_PAUSE_S
            return False
        log.info("engaged: streaming setpoints in GUIDED")
        self.phase = Phase.ENGAGED
        self._req = None
        return True

    def _start_step(self, step: str, now_s: float) -> None:
        self._step = step
        self._step_attempts = 0
        self._req = None
        self._wait_until = now_s

    def _send_step(self, s: MirrorState, now_s: float) -> None:
        if self._step == "mode":
            self._req = self.link.set_mode(GUIDED, now_s)
        elif self._step == "arm":
            self._req = self.link.arm(now_s)
        elif self._step == "takeoff":
            home_up = -s.home_local[2] if s.home_local is not None else 0.0
            alt = (self._takeoff_alt if self._takeoff_alt is not None else 2.5) - home_up
            self._req = self.link.takeoff(max(alt, 1.0), now_s)
        self._step_attempts += 1

    def _taking_off(self, sp: Setpoint, s: MirrorState, now_s: float) -> bool:
        if s.mode == GUIDED:
            self._seen_guided = True
        if self._step == "mode" and s.mode == GUIDED:
            self._start_step("arm", now_s)
        if self._step == "arm" and s.armed:
            self._armed_by_us = True
            self._start_step("takeoff", now_s)
        if self._step == "takeoff" and s.armed and s.landed is False:
            log.info("airborne: streaming setpoints")
            self.phase = Phase.ENGAGED
            self._req = None
            return True
        req = self._req
        if req is None:
            if now_s >= self._wait_until:
                if self._step_attempts >= STEP_ATTEMPTS:
                    self._abandon()
                    return False
                self._send_step(s, now_s)
            return False
        if not req.done:
            return False
        if req.accepted:
            # accepted: wait for the heartbeat / EXTENDED_SYS_STATE to show it, else try again
            if now_s - req.sent_s > STATE_TIMEOUT_S:
                self._req = None
            return False
        self.errors.append(f"take-off {self._step}: {req.describe()}")
        self._req = None
        self._wait_until = now_s + RETRY_PAUSE_S
        return False

    def _abandon(self) -> None:
        text = f"take-off abandoned at step {self._step!r} after {self._step_attempts} attempts"
        log.error("%s", text)
        self.errors.append(text)
        self.phase = Phase.IDLE
        self.abandoned = True

    def _error_once_(self, text: str) -> None:
        if text not in self._error_once:
            self._error_once.add(text)
            self.errors.append(text)
            log.error("%s", text)
