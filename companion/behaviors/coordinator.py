"""The behavior coordinator (seed 001 Sec. 6.1.2, 6.2.2, Fig. 6).

It answers activation and inhibition requests by reconfiguring the set of active behaviors so that
the catalog's compatibility conditions hold:

Activation (``activate``), in the paper's order
    1. the format check against the catalog (:func:`~.activation.check_format`);
    2. the behavior's situation conditions (its execution controller's ``check_activation``);
    3. compatibility: every active behavior incompatible with it (Definition 1, one mutually exclusive
       set; a behavior is incompatible with itself, so a new activation replaces the old one) must
       have a requester of lower or equal priority (Definition 3; emergency > operator > mission >
       default, the catalog's ``requester_priority``), else the request is rejected naming it. A
       behavior that *suspends* the flight (its controller's ``suspends_flight``:
       REQUEST_OPERATOR_ASSISTANCE, Fig. 7, which pauses the queue) keeps the incompatible flight
       behavior active and paused instead of stopping it; while it is active, only a requester of at
       least its priority may start a flight behavior (which then ends both);
    4. precedence (Definition 2), checked in advance also for the default behaviors that stopping
       the incompatible ones would start: every behavior to start needs those ``before`` it active
       (or starting first), and no behavior may be stopped while an active one needs it;
    5. then the incompatible behaviors are stopped (``interrupted``), the defaults started, and the
       behavior's execution controller is asked to start. The *coordination time* of Sec. 7.1.2 is
       measured from the request's arrival to that moment (:attr:`BehaviorCoordinator.coordination_times`).

Inhibition (``inhibit``)
    stops an active behavior (``interrupted``) if the requester's priority is at least that of the
    one who activated it and no active behavior needs it; the defaults it was blocking start.

End of behavior
    :meth:`monitor` (called periodically on the autopilot's clock) asks each execution controller for
    its performance conditions; a behavior that ended is removed and the default behaviors that are
    now possible are started ("activating all default behaviors, which are incompatible with the
    removed behavior"). Defaults whose situation became true (KEEP_HOVERING once flying,
    SELF_LOCALIZE once the estimate is healthy) are started there too.

The one writer of the queue
    With the executive layer on, everything that moves the vehicle goes through here: the flight-command
    path of the control surface (``POST /commands``, ``--commands FILE --run``) is the FLY_COMMANDS
    behavior, activated (or extended, :meth:`fly_commands`) by its caller's requester, and the queue
    verbs are honoured only for a requester with at least the priority of the one who holds the queue
    (:meth:`holder`, :meth:`authority`).

After each reconfiguration the process manager's :meth:`~.processes.ProcessManager.collect` stops the
processes nobody uses (the delayed stop). Every request, start and termination is kept in memory and
written to the log sink as one JSON object (the input of :mod:`.timeline`).
"""

from __future__ import annotations

import itertools
import logging
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from companion.flight import FlightCommand
from companion.flight.codec import commands_to_json
from companion.flight.qapi import QueueError

from .activation import ActivationError, ActivationRequest, check_format, format_activation, request_from
from .catalog import BehaviorCatalog
from .controller import (
    BehaviorContext,
    BehaviorExecutionController,
    FlightBehavior,
    StartError,
    Termination,
    TerminationCause,
    controller_class,
)

log = logging.getLogger(__name__)

_activation_ids = itertools.count(1)
#: the behavior that flies a caller's flight commands (:mod:`.library.fly_commands`)
FLY_COMMANDS = "FLY_COMMANDS"
Sink = Callable[[dict[str, Any]], None]


@dataclass(frozen=True)
class ActivationResult:
    accepted: bool
    reason: str
    activation_id: str | None = None
    behavior: str | None = None
    stopped: tuple[str, ...] = ()
    started_defaults: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        return {"accepted": self.accepted, "reason": self.reason, "activation_id": self.activation_id,
                "behavior": self.behavior, "stopped": list(self.stopped),
                "started_defaults": list(self.started_defaults)}


@dataclass
class Activation:
    """An active behavior: who asked for it, with what, since when (autopilot time)."""

    activation_id: str
    behavior: str
    requester: str
    params: dict[str, Any]
    started_at: float
    controller: BehaviorExecutionController

    def to_dict(self) -> dict[str, Any]:
        return {"activation_id": self.activation_id, "behavior": self.behavior, "requester": self.requester,
                "params": jsonable(self.params), "text": format_activation(self.behavior, self.params),
                "started_at": round(self.started_at, 3), "paused": self.controller.paused,
                **self.controller.status()}


@dataclass(frozen=True)
class Ended:
    """A terminated behavior and its cause (Sec. 5.2.1)."""

    activation_id: str
    behavior: str
    requester: str
    cause: TerminationCause
    detail: str
    started_at: float
    ended_at: float

    def to_dict(self) -> dict[str, Any]:
        return {"activation_id": self.activation_id, "behavior": self.behavior, "requester": self.requester,
                "cause": self.cause.value, "detail": self.detail, "started_at": round(self.started_at, 3),
                "ended_at": round(self.ended_at, 3)}


@dataclass
class _Plan:
    stop: list[Activation] = field(default_factory=list)
    defaults: list[str] = field(default_factory=list)


class BehaviorCoordinator:
    """See module docstring. Thread-safe: one lock around every reconfiguration."""

    def __init__(self, catalog: BehaviorCatalog, ctx: BehaviorContext, sink: Sink | None = None,
                 keep: int = 500) -> None:
        self.catalog = catalog
        self.ctx = ctx
        self._sink = sink
        self._lock = threading.RLock()
        self._active: dict[str, Activation] = {}
        self.ended: deque[Ended] = deque(maxlen=keep)
        self.requests: deque[dict[str, Any]] = deque(maxlen=keep)
        self.coordination_times: list[float] = []  # seconds (wall), one per accepted activation
        self.listeners: list[Callable[[str, Activation], None]] = []  # ("started" | "ended", activation)
        self.record_listeners: list[Sink] = []  # every record the sink gets (requests, starts, ends)
        self._start_error = ""
        self.controllers: dict[str, BehaviorExecutionController] = {}
        for d in catalog:
            cls = controller_class(d.behavior)
            if cls is None:
                raise ValueError(f"{catalog.source}: behavior {d.behavior} has no execution controller "
                                 "(a module in companion/behaviors/library registering one)")
            ctx.processes.check(d.processes)
            self.controllers[d.behavior] = cls(d, ctx)

    # --- the coordinator's services (Sec. 6.2.2) ------------------------------------------------------------
    def check(self, request: ActivationRequest | str | Mapping[str, Any], requester: str | None = None
              ) -> dict[str, Any]:
        """The format check only: the checked parameters, or :class:`ActivationError`."""
        return check_format(self.catalog, request_from(request, requester), self._limits())

    def activate(self, request: ActivationRequest | str | Mapping[str, Any],
                 requester: str | None = None) -> ActivationResult:
        """Requesting behavior activation: accepted (and started) or rejected with the reason."""
        t_received = time.perf_counter()
        try:
            req = request_from(request, requester)
            params = check_format(self.catalog, req, self._limits())
        except ActivationError as exc:
            return self._answer(None, requester or "?", False, f"format: {exc}")
        with self._lock:
            ctrl = self.controllers[req.behavior]
            why = ctrl.check_activation(params)
            if why is not None:
                return self._answer(req, req.requester, False, f"situation: {why}")
            plan, why = self._plan(req.behavior, req.requester)
            if why is not None:
                return self._answer(req, req.requester, False, why)
            for a in plan.stop:
                self._end(a, Termination(TerminationCause.INTERRUPTED,
                                         f"replaced by {req.behavior} ({req.requester})"))
            started = [d for d in plan.defaults if self._start(d, "default", {}, None)]
            aid = f"a{next(_activation_ids)}"
            tau = time.perf_counter() - t_received
            if not self._start(req.behavior, req.requester, params, aid, tau):
                why = self._start_error
                started += self._start_defaults()
                self.ctx.processes.collect()
                return self._answer(req, req.requester, False, f"start: {why}")
            self.ctx.processes.collect()
            return self._answer(req, req.requester, True, "accepted", aid,
                                tuple(a.behavior for a in plan.stop), tuple(started))

    def fly_commands(self, commands: Sequence[FlightCommand], requester: str, hold: bool = False
                     ) -> ActivationResult:
        """The flight-command path through the coordinator: ``commands`` are appended to the active
        :data:`FLY_COMMANDS` of the same requester (it then also waits for them), else a new FLY_COMMANDS
        activation carries them (replacing the flight behavior if ``requester``'s priority allows; a
        refusal names why). ``hold``: queued but not run (the queue stopped until ``run``). The commands
        are checked against the envelope first (QueueError / CommandError: nothing changes)."""
        commands = list(commands)
        if not commands:
            raise QueueError("no commands")
        for c in commands:
            self.ctx.queue.check_command(c)
        with self._lock:
            act = self._active.get(FLY_COMMANDS)
            holder = self.holder()
            if act is not None and holder is act and act.requester == requester:
                ctrl = act.controller
                assert isinstance(ctrl, FlightBehavior)
                ids = self.ctx.queue.add_commands(commands)
                ctrl.command_ids.extend(ids)
                self._emit({"type": "behavior", "event": "extended", "behavior": FLY_COMMANDS,
                            "activation_id": act.activation_id, "requester": requester, "commands": ids})
                return self._answer(None, requester, True, f"added to {act.activation_id}",
                                    act.activation_id, behavior=FLY_COMMANDS)
            params = {"commands": commands_to_json(commands), "hold": hold}
            return self.activate({"behavior": FLY_COMMANDS, "params": params}, requester)

    def holder(self) -> Activation | None:
        """Who holds the queue now: an active behavior that suspends the flight (the operator's
        assistance pause), else the active flight behavior (running or paused), else None."""
        with self._lock:
            acts = list(self._active.values())
            return next((a for a in acts if getattr(a.controller, "suspends_flight", False)), None) or next(
                (a for a in acts if isinstance(a.controller, FlightBehavior)), None)

    def authority(self, requester: str, verb: str) -> str | None:
        """None if ``requester`` may apply the queue verb ``verb`` now (its priority at least that of the
        holder's requester), else why not."""
        if requester not in self.catalog.requester_priority:
            return f"unknown requester {requester!r}"
        with self._lock:
            act = self.holder()
            if act is not None and self.catalog.priority(requester) < self.catalog.priority(act.requester):
                return (f"{verb}: the queue is held by {act.behavior} ({act.activation_id}), requested by "
                        f"{act.requester}, which has priority over {requester}")
        return None

    def inhibit(self, target: str, requester: str = "operator") -> ActivationResult:
        """Requesting behavior inhibition: ``target`` is a behavior name or an activation id."""
        with self._lock:
            act = self._active.get(target) or next(
                (a for a in self._active.values() if a.activation_id == target), None)
            why = self._inhibit_refusal(act, target, requester)
            if why is not None or act is None:
                return self._answer(None, requester, False, why or "", kind="inhibit")
            self._end(act, Termination(TerminationCause.INTERRUPTED, f"inhibited by {requester}"))
            started = self._start_defaults()
            self.ctx.processes.collect()
            return self._answer(None, requester, True, "inhibited", act.activation_id, (act.behavior,),
                                tuple(started), kind="inhibit", behavior=act.behavior)

    def _inhibit_refusal(self, act: Activation | None, target: str, requester: str) -> str | None:
        if act is None:
            return f"{target} is not active"
        if requester not in self.catalog.requester_priority:
            return f"unknown requester {requester!r}"
        if self.catalog.priority(requester) < self.catalog.priority(act.requester):
            return f"{act.behavior} was requested by {act.requester}, which has priority over {requester}"
        needing = [b for b in self._active
                   if b != act.behavior and act.behavior in self.catalog.required_before(b)]
        if needing:
            return f"{', '.join(sorted(needing))} need(s) {act.behavior} active"
        return None

    def monitor(self, now_s: float) -> list[Ended]:
        """Performance monitoring of every active behavior, end-of-behavior and the default behaviors."""
        ended: list[Ended] = []
        with self._lock:
            for act in list(self._active.values()):
                term = act.controller.monitor(now_s)
                if term is not None:
                    ended.append(self._end(act, term))
            started = self._start_defaults()
            if ended or started:
                self.ctx.processes.collect()
        return ended

    # --- views ------------------------------------------------------------------------------------------
    def active(self) -> list[Activation]:
        with self._lock:
            return list(self._active.values())

    def is_active(self, behavior: str) -> bool:
        with self._lock:
            return behavior in self._active

    def activation(self, behavior: str) -> Activation | None:
        with self._lock:
            return self._active.get(behavior)

    def queue_writer(self) -> Activation | None:
        """The running (not paused) flight behavior: the one writer of the flight-command queue (the flight
        maneuvers are mutually exclusive), or None."""
        with self._lock:
            return next((a for a in self._active.values()
                         if isinstance(a.controller, FlightBehavior) and not a.controller.paused), None)

    def status(self) -> dict[str, Any]:
        with self._lock:
            return {"active": [a.to_dict() for a in self._active.values()],
                    "ended": [e.to_dict() for e in list(self.ended)[-50:]],
                    "requests": list(self.requests)[-50:]}

    # --- internals (lock held) ------------------------------------------------------------------------------
    def _limits(self) -> Any:
        """The queue's limits: what the format check holds speeds against (None: no queue limits)."""
        return getattr(self.ctx.queue, "limits", None)

    def _plan(self, behavior: str, requester: str) -> tuple[_Plan, str | None]:
        cat = self.catalog
        prio = cat.priority(requester)
        plan = _Plan()
        suspends = getattr(self.controllers[behavior], "suspends_flight", False)
        for a in self._active.values():
            if cat.incompatible(a.behavior, behavior):
                if cat.priority(a.requester) > prio:
                    return plan, (f"incompatible with {a.behavior} (requested by {a.requester}, which has "
                                  f"priority over {requester})")
                if suspends and a.behavior != behavior and isinstance(a.controller, FlightBehavior):
                    continue  # paused by the new behavior, not stopped (Fig. 7)
                plan.stop.append(a)
        stopping = {a.behavior for a in plan.stop} - {behavior}
        remaining = set(self._active) - stopping - {behavior}
        for b in remaining:
            lost = cat.required_before(b) & stopping
            if lost:
                return plan, f"cannot stop {', '.join(sorted(lost))}: {b} needs it active"
        plan.defaults = self._startable_defaults(remaining | {behavior}, remaining)
        missing = cat.required_before(behavior) - remaining - set(plan.defaults)
        if missing:
            return plan, f"precedence: {behavior} needs {', '.join(sorted(missing))} active first"
        return plan, None

    def _startable_defaults(self, after: set[str], present: set[str]) -> list[str]:
        """Defaults not active, compatible with ``after``, situation true, precedence satisfied."""
        out: list[str] = []
        have = set(present)
        for d in self.catalog.defaults():
            name = d.behavior
            if name in after or any(self.catalog.incompatible(name, b) for b in after | set(out)):
                continue
            if not self.catalog.required_before(name) <= have:
                continue
            if self.controllers[name].check_activation({}) is not None:
                continue
            out.append(name)
            have.add(name)
        return out

    def _start_defaults(self) -> list[str]:
        names = self._startable_defaults(set(self._active), set(self._active))
        return [n for n in names if self._start(n, "default", {}, None)]

    def _start(self, behavior: str, requester: str, params: dict[str, Any], aid: str | None,
               tau: float | None = None) -> bool:
        ctrl = self.controllers[behavior]
        aid = aid or f"a{next(_activation_ids)}"
        self._start_error = ""
        try:
            ctrl.start(params, aid)
        except StartError as exc:
            self._start_error = str(exc)
            log.warning("%s could not start: %s", behavior, exc)
            self._emit({"type": "behavior", "event": "start_failed", "behavior": behavior,
                        "activation_id": aid, "requester": requester, "reason": str(exc)})
            return False
        if tau is not None:
            self.coordination_times.append(tau)
        act = Activation(aid, behavior, requester, params, self.ctx.now(), ctrl)
        self._active[behavior] = act
        log.info("behavior %s started (%s, %s)", format_activation(behavior, params), requester, aid)
        self._emit({"type": "behavior", "event": "started", "behavior": behavior, "activation_id": aid,
                    "requester": requester, "params": jsonable(params)})
        for fn in self.listeners:
            fn("started", act)
        return True

    def _end(self, act: Activation, term: Termination) -> Ended:
        act.controller.stop()
        self._active.pop(act.behavior, None)
        ended = Ended(act.activation_id, act.behavior, act.requester, term.cause, term.detail, act.started_at,
                      self.ctx.now())
        self.ended.append(ended)
        log.info("behavior %s ended: %s %s", act.behavior, term.cause.value, term.detail)
        self._emit({"type": "behavior", "event": "terminated", "behavior": act.behavior,
                    "activation_id": act.activation_id, "cause": term.cause.value, "detail": term.detail})
        for fn in self.listeners:
            fn("ended", act)
        return ended

    def _answer(self, req: ActivationRequest | None, requester: str, accepted: bool, reason: str,
                aid: str | None = None, stopped: tuple[str, ...] = (), started: tuple[str, ...] = (),
                kind: str = "activate", behavior: str | None = None) -> ActivationResult:
        behavior = behavior or (req.behavior if req else None)
        record = {"type": "request", "event": "accepted" if accepted else "rejected", "kind": kind,
                  "behavior": behavior, "requester": requester, "reason": reason, "activation_id": aid}
        if req is not None:
            record["text"] = req.text
        self.requests.append({**record, "t": round(self.ctx.now(), 3)})
        self._emit(record)
        if not accepted:
            log.info("%s %s rejected: %s", kind, behavior, reason)
        return ActivationResult(accepted, reason, aid, behavior, stopped, started)

    def _emit(self, record: dict[str, Any]) -> None:
        stamped = {"t": round(self.ctx.now(), 4), **record}
        if self._sink is not None:
            self._sink(stamped)
        for fn in list(self.record_listeners):
            fn(stamped)


def jsonable(value: Any) -> Any:
    """Parameters as JSON-able data (tuples become lists)."""
    if isinstance(value, Mapping):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, tuple | list):
        return [jsonable(v) for v in value]
    return value
