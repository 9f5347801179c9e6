"""A companion's presence on the fleet bus: what the ground service needs of each vehicle, published.

Seed 003 Fig. 1's Process Monitor tier reads each vehicle's state. Over HTTP the ground service polls every
companion in turn; on the Zenoh bus (:mod:`companion.team.zenoh_transport`) each companion publishes it
instead, so a vehicle on another host appears in the ground service with nothing but the team URL in common:

* ``taskflight/<team>/vehicle/<id>/status``, every ``period_s`` (0.5 s: 2 Hz): JSON ``{"id", "name", "t",
  "host", "loopback", "control_url", "status", "mission"}``: ``status`` is what ``GET /status`` answers,
  ``mission`` what ``GET /mission`` answers (sent when it changed and every :data:`MISSION_EVERY`-th
  message, left out otherwise: the receiver keeps the last one), ``control_url`` the companion's control
  surface (None when it serves none; commands go there over HTTP; a loopback URL is of use only where
  ``loopback``, :func:`loopback_id`, is the receiver's own: two hosts of one name, or two network
  namespaces, differ).
  A message with the mission measured 2.2 kB (two idle vehicles of ``taskflight up``);
* ``taskflight/<team>/vehicle/<id>/events``: JSON ``{"kind": "detection", "object", "object_kind", "ned",
  "t"}`` for each object its camera sees for the first time (the camera's beliefs, seed 000 Sec. VII).

The parts are given as callables by the composition root (:mod:`companion.builder`), so this module needs
neither the HTTP surface nor the executive layer.
"""

from __future__ import annotations

import json
import logging
import os
import socket
import threading
import time
from collections.abc import Callable
from typing import Any

from .zenoh_transport import ZenohBus

log = logging.getLogger(__name__)

DEFAULT_PERIOD_S = 0.5
#: the mission's status is sent at least every this many messages (and whenever it changed)
MISSION_EVERY = 10
#: the camera's beliefs are looked at every this many status messages
DETECTION_EVERY = 4
#: each detection is published this many times (every DETECTION_EVERY messages): a publication is not
#: acknowledged, and one made before a subscriber is matched is lost (the ground keeps the first it hears)
DETECTION_REPEATS = 5
#: object kinds that are the vehicle's own beliefs about itself, not detections
OWN_KINDS = frozenset({"aerial_robot"})


def loopback_id() -> str:
    """Who shares this process's loopback: the machine's boot id and the inode of its network namespace
    (two hosts of one name, e.g. every Raspberry Pi's ``raspberrypi``, or two namespaces of one machine,
    differ); the host name where ``/proc`` does not say."""
    try:
        boot = open("/proc/sys/kernel/random/boot_id", encoding="ascii").read().strip()  # noqa: SIM115
        return f"{boot}/{os.stat('/proc/self/ns/net').st_ino}"
    except OSError:
        return socket.gethostname()


class Presence:
    """Publishes one vehicle's status and events on ``bus`` (module doc) from a daemon thread."""

    def __init__(self, bus: ZenohBus, vehicle: int, *, name: str = "",
                 status: Callable[[], dict[str, Any]],
                 mission: Callable[[], dict[str, Any] | None] | None = None,
                 control_url: Callable[[], str | None] | None = None,
                 detections: Callable[[], list[dict[str, Any]]] | None = None,
                 period_s: float = DEFAULT_PERIOD_S, owns_bus: bool = True) -> None:
        if not period_s > 0:
            raise ValueError(f"Presence: period_s {period_s!r} must be positive")
        self.bus, self.vehicle, self.name, self.period_s = bus, vehicle, name, period_s
        self._status, self._mission, self._url, self._detections = status, mission, control_url, detections
        self._owns_bus = owns_bus
        self._loopback = loopback_id()
        self._status_pub = bus.publisher(bus.key("vehicle", vehicle, "status"))
        self._events_pub = bus.publisher(bus.key("vehicle", vehicle, "events"))
        self._seen: dict[str, tuple[int, list[Any], float]] = {}  #: object -> (times published, first p, t)
        self._last_mission: str | None = None
        self.published = 0
        self.errors = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def message(self) -> dict[str, Any]:
        msg = {"id": self.vehicle, "name": self.name, "t": time.time(), "host": socket.gethostname(),
               "loopback": self._loopback,
               "control_url": self._url() if self._url is not None else None, "status": self._status()}
        mission = self._mission() if self._mission is not None else None
        text = json.dumps(mission, default=str, sort_keys=True)
        if text != self._last_mission or self.published % MISSION_EVERY == 0:
            msg["mission"] = mission
            self._last_mission = text
        return msg

    def publish_once(self) -> None:
        self._status_pub.put(json.dumps(self.message(), default=str).encode())
        self.published += 1
        if self._detections is not None and self.published % DETECTION_EVERY == 1:
            for ev in self.due_detections():
                self._events_pub.put(json.dumps(ev, default=str).encode())

    def due_detections(self) -> list[dict[str, Any]]:
        """The objects seen (bindings ``{"x", "kind", "p"}``) not yet published :data:`DETECTION_REPEATS`
        times, as detection events (the first sighting's position and time)."""
        assert self._detections is not None
        out = []
        for b in self._detections():
            key, pos = str(b.get("x")), b.get("p")
            if b.get("kind") in OWN_KINDS or not isinstance(pos, list | tuple) or len(pos) != 3:
                continue
            first = self._seen.setdefault(key, (0, list(pos), time.time()))
            if first[0] >= DETECTION_REPEATS:
                continue
            self._seen[key] = (first[0] + 1, first[1], first[2])
            pos, t = first[1], first[2]
            out.append({"kind": "detection", "object": b.get("x"), "object_kind": b.get("kind"),
                        "ned": list(pos), "t": t})
        return out

    def start(self) -> Presence:
        self._thread = threading.Thread(target=self._run, name=f"presence-{self.vehicle}", daemon=True)
        self._thread.start()
        log.info("fleet bus: vehicle %d publishes its status on %s every %g s", self.vehicle,
                 self.bus.key("vehicle", self.vehicle, "status"), self.period_s)
        return self

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                self.publish_once()
            except Exception:  # one bad status must not end the vehicle's presence
                self.errors += 1
                log.exception("fleet bus: vehicle %d status not published", self.vehicle)
            self._stop.wait(self.period_s)

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        if self._owns_bus:
            self.bus.close()
