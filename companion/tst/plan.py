"""What an executor needs of a delegated node, in the local frame (seed 000 Sec. III-A, Fig. 3).

Delegation (:mod:`companion.tst.delegation`) checks a tree against a platform, fixes its free
parameters and expands it; for every node it leaves a :class:`NodePlan`: the numbers the platform's
executors fly (metres from home; m/s; s), so that no executor converts geopoints or resolves
qualitative values itself.

Points are (north, east, altitude above home), not the NED of :mod:`taskflight_common.geo` that the
geodesy uses (:func:`companion.tst.params.geopoint_to_ned`): they are what the behaviors are asked for
(seed 001's ``GO_TO_POINT coordinate: (north, east, altitude)``), and the flight log, the mission report
and ``GET /mission`` show them under the names ``position_neu`` / ``waypoints_neu``. The conversion
happens once, in :func:`companion.tst.params.plan_point`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

Vec3 = tuple[float, float, float]


@dataclass
class NodePlan:
    node_id: str
    task: str
    speed_m_s: float | None = None
    altitude_m: float | None = None
    position_neu: Vec3 | None = None  # fly-to / land / hover target
    waypoints_neu: list[Vec3] = field(default_factory=list)  # scan-ground, in flight order
    straight_line: bool = True
    duration_s: float | None = None  # wait / hover
    expected_s: float | None = None  # the estimated time to run (for the endurance)
    length_m: float | None = None
    area_ne: list[tuple[float, float]] = field(default_factory=list)  # scan-ground area
    extra: dict[str, Any] = field(default_factory=dict)  # data_uuid, repeat, loiter_mode, scan specs...

    def to_dict(self) -> dict[str, Any]:
        """JSON form (tuples as lists, unset fields left out)."""
        out: dict[str, Any] = {}
        for key, value in self.__dict__.items():
            if value is None or (isinstance(value, list | dict) and not value):
                continue
            out[key] = _jsonable(value)
        return out


def _jsonable(value: Any) -> Any:
    if isinstance(value, tuple | list):
        return [_jsonable(v) for v in value]
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, float):
        return round(value, 6)
    return value
