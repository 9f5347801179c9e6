"""The autopilot's FENCE plan read back by a pymavlink ground station (the tests' independent observer):
MISSION_REQUEST_LIST with ``mission_type`` MAV_MISSION_TYPE_FENCE, then MISSION_REQUEST_INT per item
(https://mavlink.io/en/services/mission.html#download_mission)."""

from __future__ import annotations

from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

FENCE = mavlink.MAV_MISSION_TYPE_FENCE
VERTEX_INCLUSION = mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION


def read_fence(g: Any, target: int = 1, timeout_s: float = 30.0) -> list[tuple[int, float, float, float]]:
    """``g``'s (a :class:`harness.observer.Gcs`) download of the vehicle's fence plan: (command, param1,
    lat, lon) per item."""
    with g._lock:
        g.mission.clear()
    g.conn.mav.mission_request_list_send(target, 1, FENCE)
    count = g.next_mission(("MISSION_COUNT",), timeout_s).count
    items = []
    for i in range(count):
        g.conn.mav.mission_request_int_send(target, 1, i, FENCE)
        it = g.next_mission(("MISSION_ITEM_INT",), timeout_s)
        assert it.seq == i and it.mission_type == FENCE, f"asked for fence item {i}, got {it}"
        items.append((int(it.command), float(it.param1), it.x * 1e-7, it.y * 1e-7))
    g.conn.mav.mission_ack_send(target, 1, mavlink.MAV_MISSION_ACCEPTED, FENCE)
    return items


def param(g: Any, name: str, target: int = 1, timeout_s: float = 30.0) -> float:
    """The autopilot's value of ``name``, asked now."""
    with g._lock:
        g.params.pop(name, None)
    g.conn.mav.param_request_read_send(target, 1, name.encode("ascii"), -1)
    return float(g.wait(lambda: g.params.get(name), timeout_s, f"PARAM_VALUE {name}")[0])
