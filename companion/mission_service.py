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
"""

from __future__ import annotations

import logging
import threading
from typing import TYPE_CHECKING, Any

from companion.tst.delegation import Delegation, delegate
from companion.tst.execution import TstExecutionSystem
from companion.tst.platform import Platform, bundled_platform
from companion.tst.spec import Mission
from companion.tst.status import ExecutionRequestError, NodeExecutionStatus

if TYPE_CHECKING:
    from companion.behaviors.system import ExecutiveLayer
    from companion.flightlog import FlightRecorder
    from companion.node import QuadNode

log = logging.getLogger(__name__)


class MissionService:
    """See module docstring. Thread-safe: the execution system orders requests and ticks."""

    def __init__(self, node: QuadNode, layer: ExecutiveLayer, platform: Platform | None = None,
                 recorder: FlightRecorder | None = None) -> None:
        self.node = node
        self.layer = layer
        self.base_platform = platform or bundled_platform("indoor")
        self.execution = TstExecutionSystem(layer, mark=self._mark)
        self.recorder = recorder
        if recorder is not None:
            recorder.active_node = self.execution.active_node
        self.delegation: Delegation | None = None
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

    # --- the mission ---------------------------------------------------------------------------------------
    def submit(self, mission: Mission) -> Delegation:
        """Delegate ``mission`` to this platform; load it when accepted (nothing changes when rejected)."""
        with self._lock:
            if self.execution.running:
                raise ExecutionRequestError("a mission is running: abort it or let it finish first")
            result = delegate(mission, self.platform())
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
        return self.execution.start(break_in)

    def pause(self, control: str | None = None) -> NodeExecutionStatus:
        return self.execution.pause(control)

    def continue_(self) -> NodeExecutionStatus:
        return self.execution.continue_()

    def enough(self) -> NodeExecutionStatus:
        return self.execution.enough()

    def abort(self, reason: str = "operator") -> NodeExecutionStatus:
        return self.execution.abort(reason)

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
        if self.delegation is not None:
            out["delegation"] = {"seconds": round(self.delegation.seconds, 4),
                                 "waypoints": self.delegation.waypoints}
        return out

    def close(self) -> None:
        """Detach from the executive layer (the recorder belongs to whoever made it)."""
        if self.execution.tick in self.layer.cycle_listeners:
            self.layer.cycle_listeners.remove(self.execution.tick)
