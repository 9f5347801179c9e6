"""The ground service's view of each vehicle over the Zenoh fleet bus (instead of HTTP polling).

Seed 003 Fig. 1: the Process Monitor tier reads each vehicle's state. On a Zenoh team each companion
publishes it (:mod:`companion.team.presence`): ``taskflight/<team>/vehicle/<id>/status`` a few times a
second (its ``GET /status`` and ``GET /mission`` answers, its name and its control URL) and
``.../events`` (detections). :class:`FleetBus` subscribes to both on the station's own Zenoh session and
feeds the :class:`~groundstation.fleet.Fleet`: a vehicle on another host appears with nothing but the
team URL in common, and its control URL, found on the bus, is where the operator's commands go (HTTP). A
control URL on loopback published from another host (another loopback id,
:func:`~companion.team.presence.loopback_id`: a host of the same name or another network namespace too)
is not taken (it would reach this host's own loopback). A vehicle silent on the bus for
:data:`~groundstation.fleet.LOST_S` is unreachable (a ``link_lost`` event), and ``link_restored`` when
heard again.
"""

from __future__ import annotations

import ipaddress
import json
import logging
import socket
import threading
import time
from typing import Any
from urllib.parse import urlsplit

from companion.team.presence import loopback_id
from companion.team.zenoh_transport import ZenohBus, zenoh_bus_of

from .fleet import KEEP, LOST_S, Fleet

log = logging.getLogger(__name__)


def _is_loopback_url(url: str) -> bool:
    host = urlsplit(url).hostname or ""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class FleetBus:
    """See module docstring. Counters: ``status_messages``, ``event_messages``, ``bad_messages``."""

    def __init__(self, fleet: Fleet, bus: ZenohBus) -> None:
        self.fleet, self.bus = fleet, bus
        self.status_messages = self.event_messages = self.bad_messages = 0
        self._heard: dict[int, float] = {}  # vehicle -> monotonic time of its last status
        self._elsewhere: set[int] = set()    # vehicles whose control URL is another host's loopback
        self.hostname = socket.gethostname()
        self.loopback = loopback_id()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._subs = [bus.subscribe(bus.key("vehicle", "*", "status"), self._on_status),
                      bus.subscribe(bus.key("vehicle", "*", "events"), self._on_event)]
        log.info("ground: vehicles' status from the fleet bus %s (no HTTP polling)", bus.key("vehicle", "*"))

    @classmethod
    def for_station(cls, fleet: Fleet) -> FleetBus | None:
        """The subscription on the station's Zenoh session; None for a team on another transport."""
        bus = zenoh_bus_of(fleet.station.link.transport)
        return cls(fleet, bus) if bus is not None else None

    @staticmethod
    def _vehicle_of(key: str) -> int | None:
        parts = key.split("/")
        try:
            vid = int(parts[-2])
        except (IndexError, ValueError):
            return None
        return vid if vid > 0 else None

    def _decode(self, key: str, payload: bytes) -> tuple[int, dict[str, Any]] | None:
        vid = self._vehicle_of(key)
        try:
            msg = json.loads(payload)
        except (ValueError, UnicodeDecodeError):
            msg = None
        if vid is None or not isinstance(msg, dict):
            self.bad_messages += 1
            log.debug("fleet bus: malformed message on %s dropped", key)
            return None
        return vid, msg

    def _on_status(self, key: str, payload: bytes) -> None:
        got = self._decode(key, payload)
        if got is None:
            return
        vid, msg = got
        url = msg.get("control_url")
        if url is not None and not (isinstance(url, str) and url.startswith(("http://", "https://"))):
            url = None
        theirs = msg.get("loopback")  # a companion of before the loopback id: its host name alone
        ours = theirs == self.loopback if isinstance(theirs, str) else msg.get("host") == self.hostname
        if url is not None and _is_loopback_url(url) and not ours:
            if vid not in self._elsewhere:  # another host's loopback would be ours: never called
                self._elsewhere.add(vid)
                log.warning("fleet bus: vehicle %d serves its control surface on %s of host %s only "
                            "(not this host's loopback): commands to it are refused (serve it with "
                            "--control-host 0.0.0.0 and a token)",
                            vid, url, msg.get("host"))
            url = None
        with self._lock:
            self._heard[vid] = time.monotonic()
        self.status_messages += 1
        self.fleet.heard_on_bus(vid, str(msg.get("name") or ""), url, msg.get("status"),
                                msg.get("mission", KEEP))

    def _on_event(self, key: str, payload: bytes) -> None:
        got = self._decode(key, payload)
        if got is None:
            return
        vid, msg = got
        self.event_messages += 1
        if msg.get("kind") == "detection":
            self.fleet.detected(vid, self.fleet.polled(vid), msg.get("object"), msg.get("object_kind"),
                                msg.get("ned"))

    def watch_loop(self) -> None:
        """Until closed: a vehicle silent on the bus for LOST_S becomes unreachable."""
        while not self._stop.wait(0.5):
            now = time.monotonic()
            with self._lock:
                silent = [(v, now - t) for v, t in self._heard.items() if now - t > LOST_S]
            for vid, age in silent:
                self.fleet.silent_on_bus(vid, age)

    def close(self) -> None:
        self._stop.set()
        for s in self._subs:
            try:
                s.undeclare()
            except Exception as exc:  # the session is already closed
                log.debug("fleet bus: undeclare: %s", exc)
        self._subs = []
