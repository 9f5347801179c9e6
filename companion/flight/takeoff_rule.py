"""The take-off's "stopped if allowed" rule of the QAPI (seed 000 Sec. V), as a part of the queue.

"Stopped if allowed" during a take-off (Sec. V)
    A take-off that has not yet left the ground (its execution has not advanced: the link holds the
    queue's time while the autopilot arms and lifts off; the link marks the lift-off with
    ``mark_takeoff_airborne``) stops at once; the link then cancels the take-off (nothing arms, or it
    disarms). Once climbing, it may not be stopped until its reference is ``takeoff_min_hold_m``
    above where it started: ``stop``, ``pause_direct``, ``reset`` and ``replace_commands`` given in
    that window are *deferred* (status ``deferred``, a DEFERRED event) and carried out there, so the
    vehicle never hovers armed a few centimetres above the ground. ``run()`` cancels a deferred stop
    or pause; a later ``reset`` or ``replace_commands`` supersedes a deferred one (its commands are
    CANCELLED).

:class:`TakeoffStopRule` holds the methods; :class:`~.queue.CommandQueue` inherits them and owns
the state they read and write (one writer: the queue, under its lock).
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

from .events import EventKind
from .qapi import QueueState, QueueStateError

if TYPE_CHECKING:
    from .pause_routines import PauseRoutine
    from .setpoint import VehicleState

log = logging.getLogger(__name__)

#: A climbing take-off may not be stopped below this height above where it started (m).
TAKEOFF_MIN_HOLD_M = 1.0
#: Without word from the link, a take-off whose reference rose this much (m) has left the ground.
TAKEOFF_CLIMBING_M = 0.05


class TakeoffStopRule:
    """The rule's methods (call the private ones with the queue's lock held)."""

    def _takeoff_unstoppable(self) -> bool:
        """A climbing take-off still below its minimum hold height (module docstring).

        Climbing: the link said it lifted off (:meth:`mark_takeoff_airborne`), or, with no link (a
        simulation), its reference has left the start altitude."""
        ex = self._exec
        if ex is None or self._routine is not None or self._state is not QueueState.RUNNING \
                or not ex.command.vertical.take_off or ex.ended or self._ref is None:
            return False
        climbing = ex.airborne or self._ref.altitude - ex.start_altitude >= TAKEOFF_CLIMBING_M
        return climbing and self._ref.altitude < ex.start_altitude + self.takeoff_min_hold_m

    def mark_takeoff_airborne(self, vehicle: VehicleState | None = None) -> bool:
        """Called by the link when the vehicle lifted off for the executing take-off; False when the
        take-off is no longer executing (stopped, reset or paused meanwhile). Atomic with the verbs: a
        stop after it is deferred, a stop before it makes it answer False.

        With ``vehicle``, the reference restarts at the measured state (the autopilot's own take-off
        has already climbed by the time the lift-off is seen): the first streamed setpoint continues
        the climb where the vehicle is, instead of pulling it back to the ground it left."""
        with self._lock:
            ex = self._active_execution()
            if ex is None or self._routine is not None or not ex.command.vertical.take_off or ex.ended:
                return False
            ex.airborne = True
            if vehicle is not None and self._ref is not None:
                self._ref = self._gen.initial(self._ref.t_s, vehicle.p, vehicle.v, vehicle.yaw)
                ex.resume(self._ref)
                self._last_setpoint = None
            return True

    def _defer_if_taking_off(self, verb: str, routine: PauseRoutine | None) -> bool:
        if not self._takeoff_unstoppable():
            return False
        pending = self._deferred[0] if self._deferred is not None else None
        if pending in ("reset", "replace") and verb not in ("reset", "replace"):
            raise QueueStateError(f"{verb}: a {pending} is already deferred until the take-off may stop")
        if pending == "replace":  # superseded: its commands never run
            for e in self._deferred_entries:
                self._emit(EventKind.CANCELLED, e, None, f"superseded by a later {verb}")
            self._deferred_entries = []
        self._deferred = (verb, routine)
        text = f"{verb} deferred until the take-off is {self.takeoff_min_hold_m:g} m up"
        log.info("%s", text)
        self._emit(EventKind.DEFERRED, self._current_entry(), self._index, text)
        return True

    def _drop_deferred(self, why: str) -> None:
        for e in self._deferred_entries:
            self._emit(EventKind.CANCELLED, e, None, why)
        self._deferred_entries = []
        self._deferred = None

    def _apply_deferred(self) -> None:
        if self._deferred is None or self._takeoff_unstoppable():
            return
        verb, routine = self._deferred
        self._deferred = None
        log.info("carrying out the deferred %s", verb)
        if verb == "stop":
            self._do_stop()
        elif verb == "reset":
            self._do_reset()
        elif verb == "replace":
            entries, self._deferred_entries = self._deferred_entries, []
            self._do_replace(entries)
        elif verb == "pause_direct" and routine is not None and self._routine is None:
            self._start_routine(routine, continuing=self._state is QueueState.RUNNING)

