"""The autopilot's geofence polygon through the companion's own link: upload, then enable.

The MAVLink mission protocol with ``mission_type`` MAV_MISSION_TYPE_FENCE
(https://mavlink.io/en/services/mission.html, https://mavlink.io/en/services/geofence.html), as ArduCopter
stores a polygon fence (``AC_PolyFence_loader``): one MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION item per
vertex, each with ``param1`` = the polygon's vertex count, latitude and longitude in ``x``/``y``
(degrees * 1e7, MAV_FRAME_GLOBAL). MISSION_COUNT -> MISSION_REQUEST_INT(i) -> MISSION_ITEM_INT(i) ... ->
MISSION_ACK; an upload that hears nothing of the autopilot in ``timeout_s`` (wall time) is begun again
(``attempts``). The upload replaces the autopilot's whole fence plan (ArduPilot's rule: the plan is
swapped only when complete). Only the autopilot's messages addressed to this companion count (another
ground station's transfers on the same autopilot are not ours), and a MISSION_ACK saying
MAV_MISSION_INVALID_SEQUENCE does not end the upload: it answers an item sent for a request of an
attempt given up (the autopilot keeps asking for the item it needs, as ArduPilot does).

Then, when asked, the fence is enabled as ArduCopter reads it: FENCE_TYPE gets the polygon bit (4) added
to the types it has, and FENCE_ENABLE is set to 1; both with the autopilot's read-back
(:class:`.params.ParamClient`: names and ranges from the autopilot's table; forced past the in-flight
50 % rule, which is for gains: the operator confirmed this fence, and a fleet is often in the air).
Seed 003 Sec. II: the operator's fence, held by every vehicle's autopilot.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as M  # noqa: N812 (as companion.link.mirror)

from mission_specs.param_table import ParamWriteError

from .connection import MavlinkLink
from .params import ParamClient, ParamError

FENCE = M.MAV_MISSION_TYPE_FENCE
VERTEX_INCLUSION = M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
POLYGON_BIT = 4
"""FENCE_TYPE's bit for polygons (ArduPilot's AC_FENCE_TYPE_POLYGON)."""
MAX_VERTICES = 100


class FenceError(RuntimeError):
    """The autopilot refused the fence, or did not answer."""


@dataclass(frozen=True)
class FenceUpload:
    """What the autopilot holds after an upload (the parameters' read-back when enabled)."""

    vertices: int
    enabled: bool
    fence_type: int | None


def check_vertices(points: list[list[float]]) -> list[tuple[float, float]]:
    """[[lat, lon], ...] -> [(lat, lon), ...]; ValueError naming the bad vertex."""
    if not 3 <= len(points) <= MAX_VERTICES:
        raise ValueError(f"points: a polygon of 3 to {MAX_VERTICES} [lat, lon] vertices, got {len(points)}")
    out = []
    for i, p in enumerate(points):
        if len(p) < 2 or not all(isinstance(v, int | float) and math.isfinite(v) for v in p[:2]):
            raise ValueError(f"points[{i}]: [lat, lon] as finite numbers, got {p!r}")
        lat, lon = float(p[0]), float(p[1])
        if not (-90 <= lat <= 90 and -180 <= lon <= 180):
            raise ValueError(f"points[{i}]: latitude within -90..90 and longitude within -180..180")
        out.append((lat, lon))
    return out


class FenceClient:
    """Uploads the polygon fence over ``link`` (thread-safe: one upload at a time; calls block)."""

    def __init__(self, link: MavlinkLink, timeout_s: float = 2.0, attempts: int = 3) -> None:
        self.link = link
        self.timeout_s = timeout_s
        self.attempts = attempts
        self.params = ParamClient(link)
        self._cond = threading.Condition()
        self._serial = threading.Lock()
        self._items: list[tuple[float, float]] | None = None
        self._heard = 0
        """the autopilot's requests and ACKs of this transfer so far (progress, whatever they ask)"""
        self._ack: int | None = None
        link.listeners.append(self._on_message)

    def _on_message(self, msg: Any) -> None:
        t = msg.get_type()
        if t not in ("MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"):
            return
        if getattr(msg, "mission_type", 0) != FENCE or not self.link.addressed_to_us(msg):
            return
        with self._cond:
            items = self._items
            if items is None:
                return
            self._heard += 1
            self._cond.notify_all()
            if t == "MISSION_ACK":
                if int(msg.type) != M.MAV_MISSION_INVALID_SEQUENCE:
                    self._ack = int(msg.type)
                return
            seq = int(msg.seq)
        if 0 <= seq < len(items):  # sent from the receive thread: the autopilot waits for it
            lat, lon = items[seq]
            self.link.send_mission_item_int(seq, M.MAV_FRAME_GLOBAL, VERTEX_INCLUSION,
                                            (float(len(items)), 0.0, 0.0, 0.0), lat, lon, 0.0, FENCE)

    def upload(self, points: list[list[float]], enable: bool = True) -> FenceUpload:
        """Replace the autopilot's fence with the inclusion polygon ``points`` ([[lat, lon], ...]); with
        ``enable`` turn the polygon fence on. ValueError for bad points (nothing sent), FenceError when
        the autopilot refuses or does not answer."""
        vertices = check_vertices(points)
        if self.link.target_system is None:
            raise FenceError("no autopilot heard yet")
        with self._serial:
            self._transfer(vertices)
            if not enable:
                return FenceUpload(len(vertices), False, None)
            try:  # forced: the 50 % rule in flight is for gains; the operator confirmed this fence
                kind = int(self.params.get("FENCE_TYPE").value)
                if not kind & POLYGON_BIT:
                    kind = int(self.params.set("FENCE_TYPE", float(kind | POLYGON_BIT), force=True).value)
                on = self.params.set("FENCE_ENABLE", 1.0, force=True).value
            except (ParamError, ParamWriteError) as exc:
                raise FenceError(f"the fence was stored but not enabled: {exc}") from None
            return FenceUpload(len(vertices), on >= 1, kind)

    def _transfer(self, vertices: list[tuple[float, float]]) -> None:
        with self._cond:
            self._items, self._heard, self._ack = vertices, 0, None
        try:
            for _ in range(self.attempts):
                self.link.send_mission_count(len(vertices), FENCE)
                while True:  # wait for progress (a request or the ACK); none in timeout_s: start again
                    with self._cond:
                        seen = self._heard

                        def moved(seen: int = seen) -> bool:
                            return self._ack is not None or self._heard > seen

                        got = self._cond.wait_for(moved, timeout=self.timeout_s)
                        ack = self._ack
                    if ack is not None:
                        if ack != M.MAV_MISSION_ACCEPTED:
                            name = M.enums["MAV_MISSION_RESULT"].get(ack)
                            raise FenceError(f"the autopilot refused the fence: "
                                             f"{name.name if name else ack}")
                        return
                    if not got:
                        break
            raise FenceError(f"no answer from the autopilot to the fence upload after {self.attempts} "
                             "attempts")
        finally:
            with self._cond:
                self._items = None


__all__ = ["FenceClient", "FenceError", "FenceUpload", "check_vertices"]
