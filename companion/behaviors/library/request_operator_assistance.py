"""REQUEST_OPERATOR_ASSISTANCE (seed 001 Sec. 6.2.2, Fig. 7): pause, wait for the operator, resume."""

from __future__ import annotations

import contextlib
from collections.abc import Mapping
from typing import Any

from companion.flight.qapi import QueueStateError

from ..controller import BehaviorExecutionController, StartError, Termination, TerminationCause, register
from ._common import need_flying


@register
class RequestOperatorAssistance(BehaviorExecutionController):
    """Fig. 7: the execution controller pauses the flight behaviors (the queue's ``pause_direct`` with
    the ``control`` pause routine: ``hover``, the vehicle holds, or ``joystick``, the operator flies
    it through the ``ext_vel`` stream: seed 000 Sec. VII's break-in), adds the
    belief ``waiting_for(self, operator)`` and the ``message``, and waits for the operator's
    confirmation (``user_confirm``), after which the paused command resumes and this behavior ends
    with ``goal_achieved``. In the flight maneuvers' mutually exclusive set, but it *suspends* the flight
    behavior instead of stopping it (``suspends_flight``, read by the coordinator): the paused flight
    behavior stays active (its time-out does not count the pause), and no flight behavior of a lower
    requester can start while it holds the vehicle (an operator's break-in outranks the mission). Ended
    otherwise (a flight behavior of a requester at least as high replaced it, or the pause was
    abandoned with ``run``): interrupted."""

    behavior = "REQUEST_OPERATOR_ASSISTANCE"
    #: the coordinator pauses, not stops, the incompatible flight behavior
    suspends_flight = True

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self._generation = 0
        self.control = "hover"

    def situation(self, params: Mapping[str, Any]) -> str | None:
        if self.ctx.queue.routine_id is not None:
            return f"the queue already runs the pause routine {self.ctx.queue.routine_id!r}"
        return need_flying(self)

    def on_start(self, params: Mapping[str, Any]) -> None:
        self.control = str(params.get("control", "hover"))
        queue = self.ctx.queue
        try:
            queue.pause_direct(self.control)
        except QueueStateError as exc:
            raise StartError(str(exc)) from None
        self._generation = queue.status().generation
        self.ctx.beliefs.add("waiting_for(self, operator)")
        message = params.get("message")
        if message:
            self.ctx.beliefs.add(f'operator_message(self, "{_quoted(message)}")')

    def on_stop(self) -> None:
        for b in ("waiting_for(self, operator)",):
            self.ctx.beliefs.remove(b)
        value = self.ctx.beliefs.value("operator_message", "self")
        if value is not None:
            self.ctx.beliefs.remove(f'operator_message(self, "{_quoted(str(value))}")')
        queue = self.ctx.queue
        if queue.routine_id == self.control and queue.status().generation == self._generation:
            with contextlib.suppress(QueueStateError):
                queue.run()  # inhibited: give the flight behavior back

    def performance(self, now_s: float) -> Termination | None:
        queue = self.ctx.queue
        status = queue.status()
        if status.queue_system_status.name == "OVERRIDDEN":
            return Termination(TerminationCause.INTERRUPTED, "the vehicle was taken over")
        if queue.routine_id == self.control:
            return None
        if status.generation != self._generation:
            return Termination(TerminationCause.INTERRUPTED, "a new flight behavior replaced the pause")
        return Termination(TerminationCause.GOAL_ACHIEVED, "the operator confirmed")


def _quoted(text: str) -> str:
    return text.replace("\\", "\\\\").replace('"', '\\"')
