"""A simulated downward camera that turns the scenario's objects into beliefs (seed 000 Sec. VI-E, VII).

In seed 000's scan-and-search mission "the operator monitors the live video from the platform" and
the scan's data "should be labeled with [the data_uuid] unique identifier" (Sec. VI-E, Fig. 14a). In
simulation, :class:`DownwardCamera` is that sensor: an execution process (seed 001 Sec. 6.2.3,
:class:`~companion.behaviors.processes.ExecutionProcess`) named ``camera`` whose ``tick`` computes the
camera's footprint from the vehicle's state and reports every scenario object inside it as beliefs
(seed 001 Sec. 5.2.2), so IF / WHILE conditions such as ``visible(?x), object(?x, person)`` see real
detections:

* an object entering the view adds ``object(7, person)``, ``position(7, (n, e, d))`` and ``visible(7)``
  and is recorded as a :class:`Detection` (time, object, position, the vehicle's position, and the
  running scan's node id and ``data_uuid`` if one is set, :meth:`DownwardCamera.label`:
  :meth:`DownwardCamera.results`, :meth:`DownwardCamera.detections_of`);
* an object leaving the view removes ``visible(7)``; ``object`` and ``position`` stay (the robot
  remembers what it has seen);
* nothing is seen while the process is stopped (stopping removes the ``visible`` beliefs), without a
  vehicle state, below ``min_altitude_m`` or beyond ``max_range_m`` (slant range).

The camera looks straight down (a nadir gimbal levels it: roll and pitch are ignored); its footprint
is a rectangle centred below the vehicle, ``2 h tan(h_fov / 2)`` across the heading and
``2 h tan(v_fov / 2)`` along it, ``h`` the height above the object (``VehicleState.p`` is NED, so the
vehicle's altitude is ``-p[2]``).
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from companion.behaviors.belief_syntax import Belief
from companion.behaviors.beliefs import BeliefMemory
from companion.behaviors.processes import ExecutionProcess, ProcessError
from companion.flight.setpoint import VehicleState
from companion.sensing.footprint import Fov, fov_pair
from companion.sensing.scenario import ObjectId, Scenario

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Detection:
    """One object entering the camera's view: when, what, where, from where, for which scan."""

    t_s: float
    object_id: ObjectId
    cls: str
    position: tuple[float, float, float]
    vehicle: tuple[float, float, float]  # north, east, altitude (m)
    data_uuid: str | None = None
    node_id: str | None = None  # the TST node (a scan) that was running

    def to_dict(self) -> dict[str, Any]:
        return {"t": round(self.t_s, 4), "id": self.object_id, "class": self.cls,
                "position": list(self.position), "vehicle": [round(v, 3) for v in self.vehicle],
                "data_uuid": self.data_uuid, "node": self.node_id}


class DownwardCamera(ExecutionProcess):
    """The simulated nadir camera process (see the module docstring). Thread-safe."""

    name = "camera"

    def __init__(self, scenario: Scenario, fov_deg: Fov, beliefs: BeliefMemory,
                 vehicle: Callable[[], VehicleState | None], data_uuid: str | None = None,
                 max_range_m: float = 60.0, min_altitude_m: float = 0.5) -> None:
        super().__init__()
        h_fov, v_fov = fov_pair(fov_deg)
        if not (math.isfinite(max_range_m) and max_range_m > 0.0):
            raise ValueError(f"max_range_m: must be > 0, got {max_range_m!r}")
        if not (math.isfinite(min_altitude_m) and min_altitude_m >= 0.0):
            raise ValueError(f"min_altitude_m: must be >= 0, got {min_altitude_m!r}")
        self.scenario = scenario
        self.fov_deg = (h_fov, v_fov)
        self._tan_half = (math.tan(math.radians(h_fov) / 2.0), math.tan(math.radians(v_fov) / 2.0))
        self.beliefs = beliefs
        self._vehicle = vehicle
        self.max_range_m = float(max_range_m)
        self.min_altitude_m = float(min_altitude_m)
        self._objects = list(scenario)
        self._pos = np.asarray([o.position for o in self._objects], dtype=float).reshape(-1, 3)
        self._lock = threading.Lock()
        self._data_uuid = data_uuid
        self._node_id: str | None = None
        self._visible: set[ObjectId] = set()
        self.detections: list[Detection] = []

    # --- the scan's label -----------------------------------------------------------------------------
    @property
    def data_uuid(self) -> str | None:
        """The label put on detections (the running scan-ground task's ``data_uuid``), or None."""
        with self._lock:
            return self._data_uuid

    @data_uuid.setter
    def data_uuid(self, value: str | None) -> None:
        if value is not None and not isinstance(value, str):
            raise ValueError(f"data_uuid: expected a string or None, got {type(value).__name__}")
        with self._lock:
            self._data_uuid = value

    def label(self, node_id: str | None, data_uuid: str | None) -> int:
        """Label what is seen from now on with the running scan's node id and ``data_uuid`` (None, None:
        no scan); returns how many detections were recorded before (see :meth:`detections_of`)."""
        if data_uuid is not None and not isinstance(data_uuid, str):
            raise ValueError(f"data_uuid: expected a string or None, got {type(data_uuid).__name__}")
        with self._lock:
            self._node_id, self._data_uuid = node_id, data_uuid
            return len(self.detections)

    def detections_of(self, node_id: str, since: int = 0) -> list[Detection]:
        """The detections made while node ``node_id`` ran, from the ``since``-th on, in time order."""
        with self._lock:
            return [d for d in self.detections[since:] if d.node_id == node_id]

    def results(self, data_uuid: str) -> list[Detection]:
        """The detections labelled ``data_uuid`` (the result of that scan), in time order."""
        with self._lock:
            return [d for d in self.detections if d.data_uuid == data_uuid]

    @property
    def visible(self) -> frozenset[ObjectId]:
        """The ids of the objects in view at the last tick."""
        with self._lock:
            return frozenset(self._visible)

    # --- geometry ------------------------------------------------------------------------------------
    def in_view(self, state: VehicleState | None) -> set[ObjectId]:
        """The ids of the scenario objects inside the footprint for this vehicle state."""
        if state is None or not len(self._objects):
            return set()
        pn, pe, pd = (float(c) for c in state.p)
        if not all(math.isfinite(c) for c in (pn, pe, pd, state.yaw)):
            return set()
        height = self._pos[:, 2] - pd  # height of the camera above each object
        dn, de = self._pos[:, 0] - pn, self._pos[:, 1] - pe
        c, s = math.cos(state.yaw), math.sin(state.yaw)
        along, across = dn * c + de * s, -dn * s + de * c
        ok = ((height >= self.min_altitude_m)
              & (np.sqrt(dn * dn + de * de + height * height) <= self.max_range_m)
              & (np.abs(across) <= height * self._tan_half[0] + 1e-9)
              & (np.abs(along) <= height * self._tan_half[1] + 1e-9))
        return {self._objects[i].id for i in np.flatnonzero(ok)}

    def view_polygon(self, state: VehicleState) -> list[tuple[float, float]]:
        """The footprint's corners on the ground (d = 0) as (north, east), for display."""
        pn, pe, pd = (float(c) for c in state.p)
        h = max(0.0, -pd)
        half_w, half_l = h * self._tan_half[0], h * self._tan_half[1]
        c, s = math.cos(state.yaw), math.sin(state.yaw)
        return [(pn + a * c - b * s, pe + a * s + b * c)
                for a, b in ((half_l, half_w), (half_l, -half_w), (-half_l, -half_w), (-half_l, half_w))]

    # --- the process ---------------------------------------------------------------------------------
    def on_start(self) -> None:
        if self.beliefs is None:
            raise ProcessError("camera: no belief memory")

    def on_stop(self) -> None:
        with self._lock:
            gone, self._visible = self._visible, set()
        for obj_id in gone:
            self.beliefs.remove(Belief("visible", (obj_id,)))

    def tick(self, now_s: float) -> None:
        """Look once: add the beliefs of objects entering the view, retract ``visible`` of those leaving."""
        if not self.running:
            return
        state = self._vehicle()
        seen = self.in_view(state)
        with self._lock:
            entered = [o for o in self._objects if o.id in seen and o.id not in self._visible]
            left = [i for i in self._visible if i not in seen]
            self._visible = seen
            uuid, node_id = self._data_uuid, self._node_id
            vehicle = (0.0, 0.0, 0.0) if state is None else (state.p[0], state.p[1], -state.p[2])
            for o in entered:
                self.detections.append(Detection(now_s, o.id, o.cls, o.position, vehicle, uuid, node_id))
        for o in entered:
            self.beliefs.add_all([Belief("object", (o.id, o.cls)), Belief("position", (o.id, o.position)),
                                  Belief("visible", (o.id,))])
            log.info("camera: %s %s in view at (%.1f, %.1f)%s", o.cls, o.id, o.n, o.e,
                     f" [{uuid}]" if uuid else "")
        for obj_id in left:
            self.beliefs.remove(Belief("visible", (obj_id,)))

    def status(self) -> dict[str, Any]:
        with self._lock:
            return {**super().status(), "visible": sorted(map(str, self._visible)),
                    "detections": len(self.detections), "data_uuid": self._data_uuid}
