"""What an executor needs of a delegated node, in the local frame (seed 000 Sec. III-A, Fig. 3).

Delegation (:mod:`companion.tst.delegation`) checks a tree against a platform, fixes its free
parameters and expands it; for every node it leaves a :class:`NodePlan`: the numbers the platform's
executors fly (metres north, east, up from home; m/s; s), so that no executor converts geopoints or
resolves qualitative values itself.
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
