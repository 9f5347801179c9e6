"""Who flies the vehicle: GUIDED engagement, take-off, landing and override detection.

Seed 000 Sec. V (queue_system_status Overridden: "the backup pilot can override the commands being
executed"). :class:`GuidedSupervisor` decides, tick by tick, whether the queue's setpoint is
streamed, and asks the autopilot for the modes it needs. It relies only on documented ArduCopter
behavior:

* GUIDED accepts SET_POSITION_TARGET_LOCAL_NED only in the air; on the ground a take-off needs
  GUIDED, arming, then MAV_CMD_NAV_TAKEOFF whose param7 is metres **above home**. Home is not the
  EKF origin of LOCAL_POSITION_NED (ArduCopter sets home again at arming, and its HOME_POSITION's
  x, y, z are zero), so the take-off altitude is converted with the pair LOCAL_POSITION_NED.z /
  GLOBAL_POSITION_INT.relative_alt (home's height in the local frame = -z - relative_alt).
* A NAV_TAKEOFF that was accepted is never sent again while the vehicle spools up: ArduCopter
  answers a second one with FAILED once its land detector has cleared ("can't takeoff again!").
  Lift-off is seen on EXTENDED_SYS_STATE (not ON_GROUND) or on a climb of ``LIFTOFF_CLIMB_M``.
  A streamed target replaces the autopilot's own take-off, so streaming starts at lift-off; until
  then the node holds the queue's time still.
* A step the autopilot refuses (arming before its EKF is ready, say) is retried every
  ``RETRY_PAUSE_S`` until the step's deadline (:data:`STEP_DEADLINE_S`); then the take-off is given
  up: the node marks the command FAILED in the QAPI status and, armed on the ground, disarms.
* "Stopped if allowed" (Sec. V): when the queue no longer executes the take-off (stop, reset, a
  pause) before lift-off, the take-off is cancelled: nothing arms, or the vehicle is disarmed on the
  ground (CANCELLING). If it has already lifted off, the autopilot's take-off runs on (a climbing
  take-off is deferred by the queue until it may be stopped; see :mod:`companion.flight.queue`).
* A landing command (allow-landing) whose reference reaches its altitude (``land_now``) switches to
  LAND, retried until the heartbeat shows LAND; ArduCopter lands and disarms by itself.
* Override: while engaged, any mode other than the ones we asked for (a GCS or RC switching to
  LOITER, a failsafe's RTL or LAND) or a disarm we did not cause makes the queue OVERRIDDEN and
  stops streaming. When someone puts the vehicle back into GUIDED the override is lifted; the queue
  then waits for ``run()``.

States: IDLE (not controlling; nothing streamed) -> TAKING_OFF -> ENGAGED (streaming) -> LANDING ->
IDLE; TAKING_OFF -> CANCELLING -> IDLE; any of them -> OVERRIDDEN -> IDLE. All methods run in the
node's tick thread.
"""

from __future__ import annotations

import logging
from collections import deque
from enum import Enum

from companion.flight.setpoint import Setpoint

from .commands import CommandRequest, M
from .connection import MavlinkLink
from .mirror import GUIDED, LAND, MirrorState

log = logging.getLogger(__name__)

#: Autopilot seconds between attempts of a refused step (take-off, LAND, disarm).
RETRY_PAUSE_S = 1.0
#: Autopilot seconds each take-off step may take before the take-off is given up (arming waits for
#: the autopilot's pre-arm checks: ArduCopter SITL needs about 40 s after boot).
STEP_DEADLINE_S = {"mode": 15.0, "arm": 90.0, "takeoff": 30.0}
#: Autopilot seconds an accepted mode change or arming may take to show in the telemetry.
STATE_TIMEOUT_S = 3.0
#: Autopilot seconds an accepted NAV_TAKEOFF may take to lift off before it is sent again.
LIFTOFF_TIMEOUT_S = 10.0
#: A climb of this much above the ground (m) is a lift-off even if the landed state lags behind.
LIFTOFF_CLIMB_M = 0.3
#: Autopilot seconds to disarm a cancelled take-off before giving up.
CANCEL_DEADLINE_S = 15.0


class Phase(Enum):
    IDLE = "IDLE"
    TAKING_OFF = "TAKING_OFF"
    ENGAGED = "ENGAGED"
    LANDING = "LANDING"
    CANCELLING = "CANCELLING"
    OVERRIDDEN = "OVERRIDDEN"


def takeoff_altitude_above_home(target_up_local: float, s: MirrorState) -> float:
    """NAV_TAKEOFF's param7 (m above home) for a target ``target_up_local`` m up in the local frame.

    Home's height in the local frame is ``-z - relative_alt`` (LOCAL_POSITION_NED, GLOBAL_POSITION_INT);
    HOME_POSITION's x, y, z are zero on ArduCopter. Without both messages, home is taken at the origin."""
    if s.position is None or s.global_position is None:
        return target_up_local
    return target_up_local + s.position[2] + s.global_position[3]


class GuidedSupervisor:
    """The take-off / stream / land / override state machine (see module docstring)."""

    def __init__(self, link: MavlinkLink) -> None:
        self.link = link
        self.phase = Phase.IDLE
        self.errors: deque[str] = deque(maxlen=20)
        self.override_reason: str | None = None
        #: set when a take-off was given up (the reason); the node fails the queue's command and clears it
        self.abandoned: str | None = None
        self._req: CommandRequest | None = None
        self._step = ""
        self._step_started = 0.0
        self._wait_until = 0.0
        self._takeoff_alt: float | None = None
        self._takeoff_sent_alt: float | None = None
        self._takeoff_accepted = False
        self._ground_down: float | None = None
        self._seen_guided = False
        self._armed_by_us = False
        self._cancel_started = 0.0
        self._error_once: set[str] = set()

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
        return {"phase": self.phase.value, "takeoff_step": step, "takeoff_altitude_above_home":
                self._takeoff_sent_alt, "override_reason": self.override_reason, "errors": list(self.errors)}

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
        """Advance the state machine (after :meth:`observe`); True if ``sp`` is to be streamed now.

        While TAKING_OFF the node calls :meth:`step_takeoff` instead (the queue is held).
        """
        if self.phase is Phase.CANCELLING:
            self._cancelling(s, now_s)
            return False
        if self.phase is Phase.OVERRIDDEN or sp is None:
            return False
        if self.phase is Phase.IDLE:
            return self._engage(sp, s, now_s)
        if self.phase is Phase.TAKING_OFF:
            return self.step_takeoff(sp.take_off, s, now_s)
        if self.phase is Phase.LANDING:
            self._landing(s, now_s)
            return False
        # ENGAGED
        if sp.allow_landing and sp.land_now:
            log.info("landing command reached its altitude: LAND")
            self.phase = Phase.LANDING
            self._req = self.link.set_mode(LAND, now_s)
            self._wait_until = now_s + RETRY_PAUSE_S
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
        return sp.command_index is not None or sp.routine_id is not None

    def _engage(self, sp: Setpoint, s: MirrorState, now_s: float) -> bool:
        if not self._executing(sp):
            return False
        on_ground = s.landed is True or not s.armed
        if sp.take_off and on_ground:
            self.phase = Phase.TAKING_OFF
            self._takeoff_alt = sp.takeoff_altitude
            self._takeoff_sent_alt = None
            self._takeoff_accepted = False
            self._ground_down = s.position[2] if s.position is not None else None
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

    # --- take-off ------------------------------------------------------------------------------------------
    def _start_step(self, step: str, now_s: float) -> None:
        self._step = step
        self._step_started = now_s
        self._takeoff_accepted = False
        self._req = None
        self._wait_until = now_s

    def _climbed(self, s: MirrorState) -> bool:
        if s.position is None or self._ground_down is None:
            return False
        return self._ground_down - s.position[2] >= LIFTOFF_CLIMB_M

    def step_takeoff(self, wanted: bool, s: MirrorState, now_s: float) -> bool:
        """One tick of the take-off; ``wanted``: the queue still executes the take-off command.

        True once the vehicle has lifted off (the node then streams the queue's setpoint).
        """
        if s.mode == GUIDED:
            self._seen_guided = True
        if self._step == "takeoff" and s.armed and self._takeoff_accepted \
                and (s.landed is False or self._climbed(s)):
            self._req = None
            if not wanted:
                self.takeoff_abandoned_in_the_air()
                return False
            log.info("airborne: streaming setpoints")
            self.phase = Phase.ENGAGED
            return True
        if not wanted:
            self._cancel("the queue no longer executes the take-off", s, now_s)
            return False
        if self._step == "mode" and s.mode == GUIDED:
            self._start_step("arm", now_s)
        if self._step == "arm" and s.armed:
            self._armed_by_us = True
            self._start_step("takeoff", now_s)
        if self._step == "takeoff" and not s.armed:  # disarmed on the ground (DISARM_DELAY): again
            self.errors.append("disarmed before lift-off: arming again")
            self._start_step("arm", now_s)
        req = self._req
        if req is None:
            if now_s >= self._wait_until:
                if now_s - self._step_started > STEP_DEADLINE_S[self._step]:
                    self._abandon(s, now_s)
                    return False
                self._send_step(s, now_s)
            return False
        if not req.done:
            return False
        if req.accepted:
            if self._step == "takeoff":
                self._takeoff_accepted = True
            # accepted: wait for the telemetry to show it; a take-off is never sent twice while it spools
            limit = LIFTOFF_TIMEOUT_S if self._step == "takeoff" else STATE_TIMEOUT_S
            if now_s - req.sent_s > limit:
                self._req = None
            return False
        self.errors.append(f"take-off {self._step}: {req.describe()}")
        self._req = None
        self._wait_until = now_s + RETRY_PAUSE_S
        return False

    def takeoff_abandoned_in_the_air(self) -> None:
        """The queue stopped the take-off just as the vehicle lifted off: the autopilot's own take-off
        (MAV_CMD_NAV_TAKEOFF, already climbing) runs on to its altitude and holds; we stream nothing."""
        log.info("take-off no longer wanted but airborne: the autopilot completes it")
        self.phase = Phase.IDLE
        self._req = None

    def _send_step(self, s: MirrorState, now_s: float) -> None:
        if self._step == "mode":
            self._req = self.link.set_mode(GUIDED, now_s)
        elif self._step == "arm":
            self._req = self.link.arm(now_s)
        elif self._step == "takeoff":
            target = self._takeoff_alt if self._takeoff_alt is not None else 2.5
            alt = max(takeoff_altitude_above_home(target, s), 1.0)
            self._takeoff_sent_alt = alt
            self._req = self.link.takeoff(alt, now_s)

    def _abandon(self, s: MirrorState, now_s: float) -> None:
        text = f"take-off given up at step {self._step!r} after {now_s - self._step_started:.0f} s"
        last = self.errors[-1] if self.errors else None
        if last is not None and last.startswith("take-off"):
            text += f" (last answer: {last})"
        log.error("%s", text)
        self.errors.append(text)
        self.abandoned = text
        self._cancel(text, s, now_s)

    def _cancel(self, why: str, s: MirrorState, now_s: float) -> None:
        """End the take-off: disarm if armed on the ground (CANCELLING), else IDLE."""
        log.info("take-off cancelled (%s)", why)
        if not self._arming(self._req):
            self._req = None  # an arming in flight is kept: if it arms, the vehicle is disarmed again
        self._cancel_started = now_s
        self._wait_until = now_s
        self.phase = Phase.CANCELLING
        self._cancelling(s, now_s)

    @staticmethod
    def _arming(req: CommandRequest | None) -> bool:
        return req is not None and req.command == M.MAV_CMD_COMPONENT_ARM_DISARM and req.params[0] == 1.0

    def _cancelling(self, s: MirrorState, now_s: float) -> None:
        """Disarm on the ground until disarmed; in the air (or past the deadline) give the vehicle back."""
        req = self._req
        if self._arming(req) and req is not None and (
                not req.done or (req.accepted and not s.armed and now_s - req.sent_s <= STATE_TIMEOUT_S)):
            return  # see whether the arming we asked for happens, then undo it
        if not s.armed:
            log.info("take-off cancelled: disarmed on the ground")
            self.phase = Phase.IDLE
            return
        if s.armed and s.landed is False and self._climbed(s):
            log.info("take-off cancelled after lift-off: the autopilot completes its take-off")
            self.phase = Phase.IDLE
            return
        if now_s - self._cancel_started > CANCEL_DEADLINE_S:
            self._error_once_("cancelled take-off: the vehicle could not be disarmed")
            self.phase = Phase.IDLE
            return
        if s.armed and (req is None or self._arming(req) or (req.done and now_s >= self._wait_until)):
            self._req = self.link.disarm(now_s)
            self._wait_until = now_s + RETRY_PAUSE_S

    # --- landing -----------------------------------------------------------------------------------------
    def _landing(self, s: MirrorState, now_s: float) -> None:
        if s.landed is True and not s.armed:
            log.info("landed and disarmed: link idle")
            self.phase = Phase.IDLE
            self._req = None
            return
        if s.mode == LAND:
            return
        req = self._req
        due = req is None or (req.done and not req.accepted and now_s >= self._wait_until) \
            or (req is not None and req.accepted and now_s - req.sent_s > STATE_TIMEOUT_S)
        if due:
            if req is not None and req.done and not req.accepted:
                self.errors.append(f"land: {req.describe()}")
            log.info("LAND not shown yet: asking again")
            self._req = self.link.set_mode(LAND, now_s)
            self._wait_until = now_s + RETRY_PAUSE_S

    def _error_once_(self, text: str) -> None:
        if text not in self._error_once:
            self._error_once.add(text)
            self.errors.append(text)
            log.error("%s", text)
