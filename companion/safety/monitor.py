"""The companion's safety monitor: the one user of the ``emergency`` requester (seed 001 Definition 3).

Seed 001 orders requesters emergency > operator > mission > default; nothing outside the companion may
claim ``emergency`` (it is no token role): this monitor is who asks as it. It watches the autopilot through
the node's public status (:class:`~companion.node.VehicleStatus`), every ``period_s`` of autopilot time on
the executive layer's monitor cycle (one thread with the behavior coordinator and the mission's ticks):

=====================  ==================================================================  =================
trigger                when (thresholds: :class:`~companion.safety.config.SafetyConfig`)    default action
=====================  ==================================================================  =================
``battery``            the charge left (BATTERY_STATUS consumed mAh and SYS_STATUS remaining  RTL; LAND when
                       percent, or the configured capacity) is below the charge the return    even margin 1
                       needs x ``battery_margin``: (distance home / cruise speed + height /   cannot cover it
                       descent speed) x the current drawn now (SYS_STATUS current_battery)
``estimate``           SYS_STATUS's AHRS health bit (the EKF) off for ``estimate_unhealthy_s``  LAND
``link``               the autopilot not heard within the link's time-out, ``link_lost_s``     report
                       more, while it flew
``autopilot_failsafe`` the autopilot left GUIDED for RTL, LAND, SMART_RTL or BRAKE by itself   report
``fence``              the vehicle cannot stop (at the queue's acceleration) within             RTL
                       ``fence_margin_m`` beyond the envelope, or the autopilot's geofence
                       reports a breach
=====================  ==================================================================  =================

A decision is taken when a trigger's action is stronger than what the monitor already did in this flight
(report < RTL < LAND; a reported trigger is reported once per flight); the flight's record is cleared once
the vehicle is on the ground and disarmed. Acting is, in order: tell the layers above (``listeners``: the
team member gives its task back, the mission is aborted with the reason, wired by the builder), then ask
the coordinator for the behavior as ``emergency`` (RTL refused -> LAND). An RTL that ends without its goal
while the vehicle still flies escalates to LAND. Every decision is kept (:meth:`SafetyMonitor.status`,
``GET /safety``), logged, and written to the executive layer's behavior log.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any

from companion.behaviors.controller import TerminationCause
from companion.node import FlightState, VehicleStatus

from .config import Action, SafetyConfig

if TYPE_CHECKING:
    from companion.behaviors.system import ExecutiveLayer
    from companion.node import QuadNode

log = logging.getLogger(__name__)

REQUESTER = "emergency"
#: modes an ArduCopter failsafe (or a ground station's emergency) switches to
FAILSAFE_MODES = frozenset({"RTL", "LAND", "SMART_RTL", "BRAKE", "AUTO_RTL"})


@dataclass(frozen=True)
class Trigger:
    """One check that fired: its name, the action it asks for, and why (for the operator)."""

    check: str
    action: Action
    reason: str


@dataclass(frozen=True)
class SafetyDecision:
    """What the monitor did: the trigger, the behavior asked for (None: report only) and the answer."""

    t: float
    check: str
    action: str
    reason: str
    behavior: str | None
    accepted: bool | None
    answer: str
    activation_id: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return {**asdict(self), "t": round(self.t, 3)}


Listener = Callable[[SafetyDecision], None]


class SafetyMonitor:
    """See the module docstring. ``status_of``: the vehicle's status (default ``node.vehicle_status``)."""

    def __init__(self, node: QuadNode, layer: ExecutiveLayer, config: SafetyConfig | None = None,
                 status_of: Callable[[], VehicleStatus] | None = None) -> None:
        self.node = node
        self.layer = layer
        self.config = config or SafetyConfig()
        self.status_of = status_of or node.vehicle_status
        #: told of every decision before the behavior is asked for (the team member, the mission service)
        self.listeners: list[Listener] = []
        self.decisions: deque[SafetyDecision] = deque(maxlen=100)
        self.last_values: dict[str, Any] = {}
        self.checks = 0
        self._lock = threading.Lock()
        self._next_t: float | None = None
        self._acted = -1  # the strongest action's severity in this flight (-1 none)
        self._reported: set[str] = set()
        self._unhealthy_since: float | None = None
        self._unheard_since: float | None = None  # wall (the autopilot's clock stops with its messages)
        self._wall = time.monotonic
        self._was_armed_in_air = False
        self._activation: str | None = None  # the emergency activation this flight, while it may escalate
        self._current_a: float | None = None
        self._attached = False

    # --- lifecycle -------------------------------------------------------------------------------------
    def attach(self) -> SafetyMonitor:
        """Run on the executive layer's monitor cycle (idempotent)."""
        if not self._attached and self.config.enabled:
            self.layer.cycle_listeners.append(self.on_cycle)
            self._attached = True
            log.info("safety monitor on: %s", ", ".join(self.watching()))
        elif not self.config.enabled:
            log.warning("safety monitor OFF (--no-safety-monitor): nothing on the companion lands or returns "
                        "the vehicle on a low battery, a bad estimate or a fence ahead; only the autopilot's "
                        "own failsafes act")
        return self

    def detach(self) -> None:
        if self._attached:
            self.layer.cycle_listeners.remove(self.on_cycle)
            self._attached = False

    def watching(self) -> list[str]:
        c = self.config
        return [name for name, on in (("battery", c.battery), ("estimate", c.estimate), ("link", c.link),
                                      ("autopilot_failsafe", c.autopilot_failsafe), ("fence", c.fence)) if on]

    # --- the cycle ---------------------------------------------------------------------------------------
    def on_cycle(self, now_s: float) -> None:
        """Called every monitor cycle; checks every ``period_s``."""
        if self._next_t is not None and now_s < self._next_t:
            return
        self._next_t = now_s + self.config.period_s
        try:
            self.check(now_s)
        except Exception:
            log.exception("safety monitor check failed")

    def check(self, now_s: float) -> SafetyDecision | None:
        """One check of every trigger; the decision taken, if any."""
        s = self.status_of()
        self.checks += 1
        if not s.armed and s.link_connected:
            self._new_flight()
            return None
        in_air = s.armed and s.flight in (FlightState.FLYING, FlightState.TAKING_OFF, FlightState.LANDING)
        self._was_armed_in_air = in_air or (self._was_armed_in_air and not s.link_connected)
        if not self._was_armed_in_air:
            return None
        triggers = [t for t in (self._link(s), self._failsafe(s), self._estimate(s, now_s), self._battery(s),
                                self._fence(s)) if t is not None]
        escalation = self._escalation(s)
        if escalation is not None:
            triggers.append(escalation)
        return self._decide(triggers, now_s)

    def _new_flight(self) -> None:
        self._acted, self._reported, self._activation = -1, set(), None
        self._unhealthy_since, self._was_armed_in_air = None, False

    # --- the triggers ------------------------------------------------------------------------------------
    def _link(self, s: VehicleStatus) -> Trigger | None:
        if not self.config.link or s.link_connected:
            self._unheard_since = None
            return None
        now = self._wall()
        since = self._unheard_since = self._unheard_since if self._unheard_since is not None else now
        if now - since < self.config.link_lost_s:
            return None
        return Trigger("link", self.config.link_action,
                       f"the autopilot is not heard (link lost for more than {now - since + 3:.0f} s); "
                       "its own failsafes (GUID_TIMEOUT, FS_*) act")

    def _failsafe(self, s: VehicleStatus) -> Trigger | None:
        if not self.config.autopilot_failsafe or not s.overridden or s.mode not in FAILSAFE_MODES:
            return None
        return Trigger("autopilot_failsafe", self.config.autopilot_failsafe_action,
                       f"the autopilot switched itself to {s.mode} (its failsafe or a ground station)")

    def _estimate(self, s: VehicleStatus, now_s: float) -> Trigger | None:
        if not self.config.estimate or s.estimate_healthy is not False:
            self._unhealthy_since = None
            return None
        since = self._unhealthy_since = self._unhealthy_since if self._unhealthy_since is not None else now_s
        self.last_values["estimate_unhealthy_s"] = round(now_s - since, 2)
        if now_s - since < self.config.estimate_unhealthy_s:
            return None
        return Trigger("estimate", self.config.estimate_action,
                       f"the autopilot's estimate (EKF, SYS_STATUS AHRS) unhealthy for {now_s - since:.1f} s")

    def remaining_mah(self, s: VehicleStatus) -> float | None:
        """The charge left: capacity x percent, or (no capacity configured) ArduPilot's own relation
        remaining % = 100 (1 - consumed / capacity) solved for what is left (None before 5 % is used)."""
        pct = s.battery_remaining
        if pct is None or pct < 0:
            return None
        if self.config.battery_capacity_mah is not None:
            return self.config.battery_capacity_mah * pct / 100.0
        used = s.battery_consumed_mah
        if used is None or pct > 95:
            return None
        return used * pct / (100.0 - pct) if pct < 100 else None

    def needed_mah(self, s: VehicleStatus) -> tuple[float, float] | None:
        """(charge in mAh, seconds) the return needs now: home at cruise speed, then the descent, drawing
        the current measured now (smoothed over a few seconds, never below the latest reading)."""
        if s.position is None or s.battery_current is None:
            return None
        current = s.battery_current
        self._current_a = current if self._current_a is None else 0.8 * self._current_a + 0.2 * current
        amps = max(current, self._current_a)
        cruise = self.config.cruise_speed or self.node.queue.limits.horizontal_speed
        seconds = math.hypot(s.position[0], s.position[1]) / cruise + max(0.0, -s.position[2]) / \
            self.config.descent_speed
        return amps * seconds / 3.6, seconds

    def _battery(self, s: VehicleStatus) -> Trigger | None:
        if not self.config.battery:
            return None
        left, need = self.remaining_mah(s), self.needed_mah(s)
        if left is None or need is None:
            return None
        needed, seconds = need
        margin = self.config.battery_margin
        self.last_values.update(battery_left_mah=round(left, 1), battery_needed_mah=round(needed, 1),
                                return_s=round(seconds, 1), current_a=s.battery_current)
        if left < needed:
            return Trigger("battery", self.config.battery_critical_action,
                           f"the battery cannot bring the vehicle home: {left:.0f} mAh left, the return "
                           f"({seconds:.0f} s) needs {needed:.0f} mAh")
        if left < needed * margin:
            return Trigger("battery", self.config.battery_action,
                           f"battery: {left:.0f} mAh left, the return ({seconds:.0f} s) needs "
                           f"{needed:.0f} mAh x margin {margin:g}")
        return None

    def _fence(self, s: VehicleStatus) -> Trigger | None:
        if not self.config.fence:
            return None
        if s.fence_breached:
            return Trigger("fence", self.config.fence_action, "the autopilot reports its geofence breached")
        if s.position is None or s.overridden:
            return None
        vn, ve = s.velocity[0], s.velocity[1]
        speed = math.hypot(vn, ve)
        if speed < 0.5:
            return None
        stop = speed * speed / (2.0 * self.node.queue.limits.horizontal_acceleration)
        beyond = stop - self.config.fence_margin_m
        if beyond <= 0:
            return None
        point = (s.position[0] + vn / speed * beyond, s.position[1] + ve / speed * beyond)
        if self.node.queue.envelope.contains_ne(point):
            return None
        return Trigger("fence", self.config.fence_action,
                       f"fence ahead: at {speed:.1f} m/s the vehicle stops {stop:.1f} m on, more than "
                       f"{self.config.fence_margin_m:g} m beyond the operational envelope")

    def _escalation(self, s: VehicleStatus) -> Trigger | None:
        """The emergency RTL ended without its goal while the vehicle still flies: LAND."""
        aid = self._activation
        if aid is None or s.flight is not FlightState.FLYING:
            return None
        ended = next((e for e in reversed(self.layer.coordinator.ended) if e.activation_id == aid), None)
        if ended is None or ended.behavior != "RTL" or ended.cause is TerminationCause.GOAL_ACHIEVED:
            return None
        self._activation = None
        return Trigger("rtl_failed", Action.LAND,
                       f"the emergency RTL ended {ended.cause.value}: {ended.detail}")

    # --- deciding and acting -----------------------------------------------------------------------------
    def _decide(self, triggers: list[Trigger], now_s: float) -> SafetyDecision | None:
        fresh = [t for t in triggers if t.action.severity > max(self._acted, 0)
                 or (t.action is Action.REPORT and t.check not in self._reported)]
        if not fresh:
            return None
        top = max(fresh, key=lambda t: t.action.severity)
        if top.action is Action.REPORT:
            self._reported.add(top.check)
            decision = SafetyDecision(now_s, top.check, top.action.value, top.reason, None, None, "reported")
            self._record(decision)
            return decision
        self._acted = top.action.severity
        self._tell(SafetyDecision(now_s, top.check, top.action.value, top.reason, None, None, "acting"))
        decision = self._activate(top, now_s)
        self._record(decision)
        return decision

    def _activate(self, trigger: Trigger, now_s: float) -> SafetyDecision:
        coordinator = self.layer.coordinator
        tries = ["RTL", "LAND"] if trigger.action is Action.RTL else ["LAND"]
        answers: list[str] = []
        for behavior in tries:
            params: dict[str, Any] = {}
            if behavior == "RTL" and self.config.rtl_altitude is not None:
                params["altitude"] = self.config.rtl_altitude
            result = coordinator.activate({"behavior": behavior, "params": params}, REQUESTER)
            answers.append(f"{behavior}: {result.reason}")
            if result.accepted:
                self._activation = result.activation_id
                return SafetyDecision(now_s, trigger.check, trigger.action.value, trigger.reason, behavior,
                                      True, "; ".join(answers), result.activation_id)
        log.error("safety monitor: %s refused (%s)", "/".join(tries), "; ".join(answers))
        return SafetyDecision(now_s, trigger.check, trigger.action.value, trigger.reason, tries[-1], False,
                              "; ".join(answers))

    def _tell(self, decision: SafetyDecision) -> None:
        for fn in list(self.listeners):
            try:
                fn(decision)
            except Exception:
                log.exception("safety monitor: a listener failed")

    def _record(self, decision: SafetyDecision) -> None:
        with self._lock:
            self.decisions.append(decision)
        log.warning("safety monitor: %s -> %s (%s): %s", decision.check, decision.action,
                    decision.behavior or "report", decision.reason)
        self.layer.log({"t": round(decision.t, 4), "type": "safety", **decision.to_dict()})
        if decision.action == Action.REPORT.value:
            self._tell(decision)

    # --- the view ----------------------------------------------------------------------------------------
    def status(self) -> dict[str, Any]:
        """What it watches (thresholds), the last values it computed, its decisions (newest last)."""
        with self._lock:
            decisions = [d.to_dict() for d in self.decisions]
        return {"enabled": self.config.enabled, "watching": self.watching(),
                "thresholds": self.config.thresholds(), "checks": self.checks,
                "values": dict(self.last_values), "last_decision": decisions[-1] if decisions else None,
                "decisions": decisions}
