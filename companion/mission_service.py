"""The companion's mission layer in one place (seed 000 Sec. III, VII): delegation and execution of TSTs.

:class:`MissionService` joins, for one vehicle,

* the platform description (:class:`~companion.tst.platform.Platform`: envelope, speeds, sensors,
  endurance), completed from what the vehicle says over MAVLink (its home, its battery),
* delegation (:func:`~companion.tst.delegation.delegate`): a submitted mission is checked, its free
  parameters fixed and its scan-ground nodes expanded, or it is rejected with the reasons,
* the TST execution system (:class:`~companion.tst.execution.TstExecutionSystem`) ticked by the
  executive layer's monitor cycle, its executors asking the behavior coordinator for behaviors,
* the flight log (:class:`~companion.flightlog.FlightRecorder`, optional): every streamed setpoint with
  the measured position and the active node, and the mission's events.

It says yes only to what it can fly: a mission is refused (:class:`NotReadyError`, HTTP 503) while the
autopilot is not ready (:meth:`MissionService.readiness`: the link hears no heartbeat, no home, no healthy
position estimate), and a mission whose ``on_failure`` asks for a behavior the executive layer does not
have is rejected by delegation. A failed or aborted mission can be resumed from a node
(:meth:`MissionService.resume`): the part left (:func:`~companion.tst.resume.remainder`) is delegated
again and started.
"""

from __future__ import annotations

import logging
import threading
from typing import TYPE_CHECKING, Any

from companion.tst.delegation import Delegation, delegate
from companion.tst.events import EventStream
from companion.tst.execution import TstExecutionSystem
from companion.tst.platform import Platform, bundled_platform
from companion.tst.resume import first_leaf, remainder
from companion.tst.spec import Mission
from companion.tst.status import ExecutionRequestError, NodeExecutionStatus

if TYPE_CHECKING:
    from companion.behaviors.system import ExecutiveLayer
    from companion.flightlog import FlightRecorder
    from companion.node import QuadNode

log = logging.getLogger(__name__)

#: the behavior each ``on_failure`` policy asks for (hover: the default KEEP_HOVERING, nothing to ask)
POLICY_BEHAVIORS = {"land": "LAND", "rtl": "RTL"}


class NotReadyError(ExecutionRequestError):
    """The autopilot is not ready to fly a mission (no link, no home, no healthy estimate): HTTP 503."""


class MissionService:
    """See module docstring. Thread-safe: the execution system orders requests and ticks."""

    def __init__(self, node: QuadNode, layer: ExecutiveLayer, platform: Platform | None = None,
                 recorder: FlightRecorder | None = None) -> None:
        self.node = node
        self.layer = layer
        self.base_platform = platform or bundled_platform("indoor")
        self.execution = TstExecutionSystem(layer, mark=self._mark, readiness=self.node_readiness)
        self.recorder = recorder
        if recorder is not None:
            recorder.active_node = self.execution.active_node
        self.delegation: Delegation | None = None
        self.submitted: Mission | None = None  # the mission as given (resume builds the rest from it)
        self._lock = threading.Lock()
        layer.cycle_listeners.append(self.execution.tick)

    def _mark(self, event: str, **fields: Any) -> None:
        if self.recorder is not None:
            self.recorder.mark(event, **fields)

    def platform(self) -> Platform:
        """The platform as the vehicle is now: its home and its battery from the MAVLink mirror."""
        p = self.base_platform
        s = self.node.link.mirror.snapshot()
        if s.home is not None:
            p = p.with_home(s.home[0], s.home[1])
        if s.battery_remaining is not None and s.battery_remaining >= 0:
            p = p.with_battery(float(s.battery_remaining))
        return p

    def node_readiness(self, node_id: str, seconds_left: float) -> str | None:
        """Fig. 3 prepare()'s re-check before node ``node_id`` starts: the autopilot link, the estimate,
        and the battery against the ``seconds_left`` of the plan from that node; None when ready."""
        if not self.node.link.connected:
            return "the link to the autopilot is lost"
        if self.layer.beliefs.holds("localization(self, unhealthy)"):
            return "the autopilot's position estimate is unhealthy"
        endurance = self.platform().endurance_s
        if seconds_left > endurance:
            return (f"battery: {seconds_left:.0f} s of plan left from {node_id}, {endurance:.0f} s of "
                    f"endurance ({self.platform().endurance_source})")
        return None

    # --- readiness ----------------------------------------------------------------------------------------
    def readiness(self) -> str | None:
        """Why the vehicle cannot fly a mission now (None: it can): the link to the autopilot hears no
        heartbeat, the autopilot has not told its home, or its position estimate is not healthy (the
        executive layer's SELF_LOCALIZE, which every motion behavior needs, is not active)."""
        link = self.node.link
        if not link.connected:
            heard = link.target_system is not None
            return (f"the autopilot link ({link.url}) is not connected: "
                    + ("no heartbeat for more than 3 s" if heard else "no heartbeat heard yet"))
        s = link.mirror.snapshot()
        if s.home is None:
            return "the autopilot has not reported its home yet (HOME_POSITION)"
        if s.position is None:
            return "no position estimate from the autopilot yet (LOCAL_POSITION_NED)"
        if not self.layer.coordinator.is_active("SELF_LOCALIZE"):
            return ("the autopilot's position estimate is not healthy (SELF_LOCALIZE is not active: no "
                    "recent LOCAL_POSITION_NED)")
        return None

    def _require_ready(self, what: str) -> None:
        why = self.readiness()
        if why is not None:
            raise NotReadyError(f"{what} refused: {why}")

    # --- the mission ---------------------------------------------------------------------------------------
    def submit(self, mission: Mission) -> Delegation:
        """Delegate ``mission`` to this platform; load it when accepted (nothing changes when rejected).
        :class:`NotReadyError` while the autopilot is not ready (:meth:`readiness`)."""
        with self._lock:
            if self.execution.running:
                raise ExecutionRequestError("a mission is running: abort it or let it finish first")
            self._require_ready("mission")
            result = self._delegate(mission)
            if result.accepted:
                self.submitted = mission
            return result

    def check(self, mission: Mission) -> Delegation:
        """Delegation's answer for ``mission`` on this platform now, loading nothing (seed 000 Sec. IV:
        the answer a directed mission gets before the vehicle is taken from its team task)."""
        behavior = POLICY_BEHAVIORS.get(mission.on_failure)
        if behavior is not None and behavior not in self.layer.catalog:
            reason = (f"on_failure: {mission.on_failure} needs the {behavior} behavior, which this "
                      "companion's behavior catalog does not have")
            return Delegation(False, [reason], mission, {}, None, 0.0, platform=self.base_platform.name)
        return delegate(mission, self.platform(), catalog=self.layer.catalog)

    def _delegate(self, mission: Mission) -> Delegation:
        result = self.check(mission)
        if result.accepted:
            self.execution.load(result.mission, result.plans)
            self.delegation = result
            self._mark("plan", mission=mission.name, **self._plan_fields(result))
        verdict = "accepted" if result.accepted else "rejected: " + "; ".join(result.reasons)
        log.info("mission %s delegated in %.1f ms: %s", mission.name, result.seconds * 1000, verdict)
        return result

    @staticmethod
    def _plan_fields(result: Delegation) -> dict[str, Any]:
        area: list[list[float]] = []
        waypoints: list[list[float]] = []
        for plan in result.plans.values():  # the scans' areas and waypoints (other plans have none)
            area = area or [list(p) for p in plan.area_ne]
            waypoints += [list(w) for w in plan.waypoints_neu]
        nodes = [{"id": n.id, "type": n.type} for n in result.mission.root.iter()]
        return {"area_ne": area, "waypoints_neu": waypoints, "nodes": nodes}

    def start(self, break_in: str = "joystick") -> NodeExecutionStatus:
        self._require_ready("mission start")
        return self.execution.start(break_in)

    def pause(self, control: str | None = None) -> NodeExecutionStatus:
        return self.execution.pause(control)

    def continue_(self) -> NodeExecutionStatus:
        return self.execution.continue_()

    def enough(self) -> NodeExecutionStatus:
        return self.execution.enough()

    def abort(self, reason: str = "operator", policy: str | None = None) -> NodeExecutionStatus:
        """Abort; then the mission's ``on_failure`` policy (or ``policy``) is applied."""
        return self.execution.abort(reason, policy)

    def resume(self, node_id: str | None = None, take_off: bool = False,
               break_in: str = "joystick") -> Delegation:
        """Fly the rest of the failed or aborted mission from ``node_id`` (None: the node that failed):
        the part left is delegated again and, when accepted, started. ``take_off``: fly a take-off first
        (the vehicle is on the ground and the rest does not begin with one). A refusal
        (:class:`ExecutionRequestError` naming why, :class:`~companion.tst.resume.ResumeError` for a bad
        node) changes nothing."""
        with self._lock:
            ex = self.execution
            root = ex.root_status()
            if ex.running:
                raise ExecutionRequestError("resume refused: the mission is running")
            if self.submitted is None or root is None or root.succeeded:
                raise ExecutionRequestError("resume refused: no failed or aborted mission to resume")
            self._require_ready("resume")
            node_id = node_id or ex.failed_node()
            if node_id is None:
                raise ExecutionRequestError("resume refused: no node failed or was aborted")
            outcome = {k: r.status.state for k, r in ex.runs.items()}
            rest = remainder(self.submitted, node_id, outcome.get)
            begins = first_leaf(rest.root)
            on_ground = self.node.vehicle_status().on_ground
            if take_off and not on_ground:
                raise ExecutionRequestError("resume refused: take_off: the vehicle is flying")
            if take_off and begins is not None and begins.type == "take-off":
                raise ExecutionRequestError(f"resume refused: take_off: the rest begins with a take-off "
                                            f"({begins.id})")
            if on_ground and not take_off and (begins is None or begins.type != "take-off"):
                raise ExecutionRequestError(
                    f"resume refused: the vehicle is on the ground and the rest begins with "
                    f"{begins.type if begins else 'nothing'} ({begins.id if begins else node_id}): resume "
                    "with take_off: true, or from a take-off node")
            if take_off:
                rest = remainder(self.submitted, node_id, outcome.get, take_off={"type": "take-off"})
            result = self._delegate(rest)
            if not result.accepted:
                return result
            self.submitted = rest  # a later resume continues from this part
            ex.mark("mission_resumed", mission=rest.name, node=node_id, take_off=take_off)
            ex.start(break_in)
            return result

    @property
    def events(self) -> EventStream:
        """The mission's events (:class:`~companion.tst.events.EventStream`)."""
        return self.execution.events

    def safety_report(self, reason: str) -> None:
        """The companion's safety monitor reports what it saw without acting (the mission's log says it)."""
        self._mark("safety", reason=reason, action="report")

    def safety_stop(self, reason: str) -> None:
        """The companion's safety monitor takes the vehicle: a running mission is aborted with the monitor's
        reason (its status and the flight log say why), before the emergency behavior replaces its own."""
        self._mark("safety", reason=reason)
        if not self.execution.running:
            return
        try:
            self.execution.abort(f"safety monitor: {reason}")
        except ExecutionRequestError as exc:  # not abortable: it fails once its behavior is replaced
            log.warning("safety monitor: the mission was not aborted: %s", exc)

    def status(self) -> dict[str, Any]:
        out = self.execution.status()
        out["readiness"] = self.readiness() or "ready"
        if self.delegation is not None:
            out["delegation"] = {"seconds": round(self.delegation.seconds, 4),
                                 "waypoints": self.delegation.waypoints}
        return out

    def close(self) -> None:
        """Detach from the executive layer (the recorder belongs to whoever made it)."""
        if self.execution.tick in self.layer.cycle_listeners:
            self.layer.cycle_listeners.remove(self.execution.tick)
