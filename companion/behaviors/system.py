"""The executive layer of one vehicle (seed 001 Fig. 4): coordinator, beliefs, updaters, processes.

:class:`ExecutiveLayer` assembles, over a :class:`~companion.node.QuadNode` (or any queue with a
clock and a vehicle-state source, for tests):

* the belief memory and its updaters (the common belief updater reads the node's vehicle status; the
  :class:`QueueBeliefUpdater` says who controls the vehicle),
* the process manager with the bundled execution processes (:mod:`.services`) and the simulated
  downward camera (:mod:`companion.sensing.camera`; a ``scenario`` of objects to see, none by default),
* the behavior coordinator with the catalog's execution controllers,
* the *monitor cycle*: at ``monitor_hz`` of the autopilot's clock the coordinator's performance
  monitoring and the running processes' periodic work, run by the belief updaters' runner as one more
  periodic job (one thread for both),
* the flight log: every request, behavior start and termination and process start and stop as one
  JSON object per line (``log_path``), the input of ``taskflight behaviors timeline``.

Nothing here sends MAVLink: behaviors act on the command queue, the link streams it.
"""

from __future__ import annotations

import json
import logging
import threading
from collections.abc import Callable
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

from companion.flight.queue import CommandQueue
from companion.flight.setpoint import VehicleState
from companion.sensing.camera import DownwardCamera
from companion.sensing.scenario import Scenario

from .beliefs import BeliefMemory
from .catalog import BehaviorCatalog, load_catalog
from .controller import BehaviorContext
from .coordinator import BehaviorCoordinator
from .processes import ProcessManager
from .services import JoystickFeed, bundled_processes
from .updaters import BeliefUpdater, BeliefUpdaterRunner, CommonBeliefUpdater

if TYPE_CHECKING:
    from companion.node import QuadNode

log = logging.getLogger(__name__)

DEFAULT_MONITOR_HZ = 20.0
#: the simulated downward camera's field of view (degrees, square)
DEFAULT_CAMERA_FOV_DEG = 60.0


class QueueBeliefUpdater(BeliefUpdater):
    """``control(self, companion | elsewhere)`` from the queue's status (OVERRIDDEN: a pilot or GCS)."""

    name = "queue"

    def __init__(self, queue: CommandQueue, period_s: float = 0.2) -> None:
        self.queue = queue
        self.period_s = period_s

    def update(self, memory: BeliefMemory, now_s: float) -> None:
        overridden = self.queue.status().queue_system_status.name == "OVERRIDDEN"
        memory.add(f"control(self, {'elsewhere' if overridden else 'companion'})")


class FlightLog:
    """JSON lines, one writer lock; kept in memory too (the last ``keep`` records)."""

    def __init__(self, path: str | Path | None = None, keep: int = 20000) -> None:
        self.path = Path(path) if path is not None else None
        self._file: IO[str] | None = self.path.open("a", encoding="utf-8") if self.path else None
        self._lock = threading.Lock()
        self.records: list[dict[str, Any]] = []
        self._keep = keep

    def __call__(self, record: dict[str, Any]) -> None:
        with self._lock:
            self.records.append(record)
            if len(self.records) > self._keep:
                del self.records[: len(self.records) - self._keep]
            if self._file is not None:
                self._file.write(json.dumps(record, separators=(",", ":")) + "\n")
                self._file.flush()

    def close(self) -> None:
        with self._lock:
            if self._file is not None:
                self._file.close()
                self._file = None


class ExecutiveLayer:
    """See module docstring."""

    def __init__(self, queue: CommandQueue, now: Callable[[], float],
                 vehicle: Callable[[], VehicleState | None], *, catalog: BehaviorCatalog | None = None,
                 updaters: list[Any] | None = None, wall_until: Callable[[float], float] | None = None,
                 ready: Callable[[], bool] | None = None, log_path: str | Path | None = None,
                 monitor_hz: float = DEFAULT_MONITOR_HZ, scenario: Scenario | None = None,
                 camera_fov_deg: float = DEFAULT_CAMERA_FOV_DEG) -> None:
        if not 1.0 <= monitor_hz <= 100.0:
            raise ValueError(f"monitor rate {monitor_hz:g} Hz outside 1..100 Hz")
        self.queue = queue
        self.now = now
        self.catalog = catalog or load_catalog()
        self.log = FlightLog(log_path)
        self.beliefs = BeliefMemory()
        self.camera = DownwardCamera(scenario or Scenario(), camera_fov_deg, self.beliefs, vehicle)
        self.processes = ProcessManager([*bundled_processes(queue, queue.envelope), self.camera], now,
                                        sink=self.log)
        self.ctx = BehaviorContext(queue, self.beliefs, self.processes, now, vehicle)
        self.coordinator = BehaviorCoordinator(self.catalog, self.ctx, sink=self.log)
        self.period_s = 1.0 / monitor_hz
        self.monitor_cycles = 0
        #: called with the autopilot time at the end of every monitor cycle (the TST execution system)
        self.cycle_listeners: list[Callable[[float], None]] = []
        jobs = [QueueBeliefUpdater(queue), *(updaters or []),
                _MonitorCycle(self, self.period_s, ready or (lambda: True))]
        self.updaters = BeliefUpdaterRunner(self.beliefs, jobs, now, wall_until)

    @classmethod
    def for_node(cls, node: QuadNode, **kw: Any) -> ExecutiveLayer:
        """The executive layer over a running companion node (its queue, clock and vehicle status)."""
        common = CommonBeliefUpdater(node.vehicle_status, node.clock.now, period_s=0.2)
        # the camera looks at 20 Hz: the vehicle state alone, not the whole status built around it
        return cls(node.queue, node.clock.now, node.vehicle_state,
                   updaters=[common], wall_until=node.clock.wall_until, ready=lambda: node.clock.synced, **kw)

    # --- lifecycle -------------------------------------------------------------------------------------
    def start(self) -> ExecutiveLayer:
        """Start the one thread: the belief updaters and the monitor cycle, each at its own period."""
        self.updaters.start()
        return self

    def close(self) -> None:
        self.updaters.close()
        self.log.close()

    def __enter__(self) -> ExecutiveLayer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def awaits_operator(self) -> bool:
        """The queue's command waits for the operator's confirmation (QAPI ``confirmation_required_status``,
        seed 000 Sec. IV-A: E_User) because someone asked for it, not merely because the vehicle is idle: the
        *default* flight behavior (KEEP_HOVERING, seed 001 Sec. 5.1.2) also ends on E_User, but asks nobody
        anything (another behavior replaces it)."""
        if not self.queue.status().confirmation_required_status:
            return False
        writer = self.coordinator.queue_writer()
        return writer is None or writer.requester != "default"

    # --- one monitor cycle ---------------------------------------------------------------------------
    def step(self, now_s: float) -> None:
        """Performance monitoring, defaults, the processes' periodic work (the monitor cycle)."""
        self.coordinator.monitor(now_s)
        self.processes.tick(now_s)
        for fn in list(self.cycle_listeners):
            fn(now_s)
        self.monitor_cycles += 1

    # --- conveniences --------------------------------------------------------------------------------
    @property
    def joystick(self) -> JoystickFeed:
        feed = self.processes.get("joystick_feed")
        assert isinstance(feed, JoystickFeed)
        return feed

    def status(self) -> dict[str, Any]:
        return {**self.coordinator.status(), "processes": self.processes.status(),
                "monitor_cycles": self.monitor_cycles}


class _MonitorCycle:
    """The executive layer's monitor cycle as a periodic job of the updaters' runner (same thread, so a
    cycle always sees the beliefs of the last completed update)."""

    name = "behavior_monitor"

    def __init__(self, layer: ExecutiveLayer, period_s: float, ready: Callable[[], bool]) -> None:
        self.layer = layer
        self.period_s = period_s
        self.ready = ready

    def update(self, memory: BeliefMemory, now_s: float) -> None:
        if self.ready():
            try:
                self.layer.step(now_s)
            except Exception:
                log.exception("behavior monitor cycle failed")
