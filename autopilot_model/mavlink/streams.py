"""Telemetry streams: which message goes to which link how often (simulated time).

Rates are per link, as ArduPilot keeps them per serial port, and can be set three ways:

* ``MAV_CMD_SET_MESSAGE_INTERVAL`` (param1 message id, param2 interval in us; -1 off, 0 default),
* the legacy ``REQUEST_DATA_STREAM`` with ArduCopter's stream groups (MAVProxy uses it),
* ``MAV_CMD_REQUEST_MESSAGE`` for one message now.

A stream is a message name plus a *builder*, a function returning the message (or None when it does
not apply right now, e.g. no active position target). The builders for the vehicle's state are in
:mod:`.telemetry`; other pieces add theirs with :meth:`StreamScheduler.add_builder`.

The scheduler runs in the telemetry task group (seed 002); per call it only compares the current
time with the earliest due time of each link unless something is due, so the idle cost is tiny. A stream
goes out at once when its rate is set, then on the multiples of its interval in simulated time, so streams
of commensurate rates leave together.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

if TYPE_CHECKING:
    from .endpoint import MavlinkEndpoint
    from .transport import Peer

log = logging.getLogger(__name__)

Builder = Callable[[], Any]

#: ArduCopter's REQUEST_DATA_STREAM groups, restricted to the messages this model produces.
STREAM_GROUPS: dict[int, tuple[str, ...]] = {
    mavlink2.MAV_DATA_STREAM_RAW_SENSORS: (),
    mavlink2.MAV_DATA_STREAM_EXTENDED_STATUS: ("SYS_STATUS", "MISSION_CURRENT", "GPS_RAW_INT",
                                               "NAV_CONTROLLER_OUTPUT", "FENCE_STATUS",
                                               "POSITION_TARGET_LOCAL_NED"),
    mavlink2.MAV_DATA_STREAM_RC_CHANNELS: ("RC_CHANNELS", "SERVO_OUTPUT_RAW"),
    mavlink2.MAV_DATA_STREAM_POSITION: ("GLOBAL_POSITION_INT", "LOCAL_POSITION_NED"),
    mavlink2.MAV_DATA_STREAM_EXTRA1: ("ATTITUDE",),
    mavlink2.MAV_DATA_STREAM_EXTRA2: ("VFR_HUD",),
    mavlink2.MAV_DATA_STREAM_EXTRA3: ("SYSTEM_TIME", "BATTERY_STATUS", "EKF_STATUS_REPORT",
                                      "EXTENDED_SYS_STATE", "HOME_POSITION", "RANGEFINDER",
                                      "DISTANCE_SENSOR"),
}

#: What a new link gets before it asks for anything (param TELEM_DEFAULTS=1), in Hz.
DEFAULT_RATES_HZ: dict[str, float] = {
    "SYS_STATUS": 1.0,
    "EXTENDED_SYS_STATE": 1.0,
    "GPS_RAW_INT": 1.0,
    "GLOBAL_POSITION_INT": 4.0,
    "LOCAL_POSITION_NED": 4.0,
    "ATTITUDE": 4.0,
    "VFR_HUD": 2.0,
    "BATTERY_STATUS": 1.0,
    "SYSTEM_TIME": 1.0,
    "HOME_POSITION": 0.5,
    "MISSION_CURRENT": 1.0,
    "POSITION_TARGET_LOCAL_NED": 2.0,
}

#: The rate "0 = default" of SET_MESSAGE_INTERVAL refers to, for messages without a default above.
FALLBACK_DEFAULT_HZ = 1.0
HEARTBEAT_INTERVAL_US = 1_000_000
MAX_RATE_HZ = 50.0


def interval_us_for(hz: float) -> int:
    """Interval in microseconds for a rate in Hz, capped at :data:`MAX_RATE_HZ`; 0 Hz = off (-1)."""
    if not hz > 0:
        return -1
    return round(1e6 / min(hz, MAX_RATE_HZ))


class StreamScheduler:
    """Per-link message intervals and the periodic sending of due messages."""

    def __init__(self, endpoint: MavlinkEndpoint) -> None:
        self.endpoint = endpoint
        self.builders: dict[str, Builder] = {}
        self.on_heartbeat: list[Callable[[], None]] = []

    # --- configuration -------------------------------------------------------------------------
    def add_builder(self, name: str, fn: Builder) -> None:
        """Make message ``name`` available for streaming and REQUEST_MESSAGE."""
        self.builders[name] = fn

    def supports(self, name: str) -> bool:
        return name in self.builders

    def init_link(self, peer: Peer) -> None:
        st = peer.state
        now = self.endpoint.clock.now_us
        st.intervals_us["HEARTBEAT"] = HEARTBEAT_INTERVAL_US
        st.next_due_us["HEARTBEAT"] = now
        if self.endpoint.params.get("TELEM_DEFAULTS") >= 1:
            for name, hz in DEFAULT_RATES_HZ.items():
                self._set(peer, name, interval_us_for(hz))
        st.next_any_us = now

    def _set(self, peer: Peer, name: str, interval_us: int) -> None:
        st = peer.state
        if interval_us < 0:
            st.intervals_us.pop(name, None)
            st.next_due_us.pop(name, None)
            return
        st.intervals_us[name] = interval_us
        now = self.endpoint.clock.now_us
        st.next_due_us[name] = now
        st.next_any_us = now

    def set_interval(self, peer: Peer, name: str, interval_us: int) -> bool:
        """SET_MESSAGE_INTERVAL semantics: -1 off, 0 default rate, >0 microseconds. False if unknown."""
        if name == "HEARTBEAT":
            return interval_us != -1  # the heartbeat always goes out at 1 Hz
        if name not in self.builders:
            return False
        self.endpoint.link_state(peer)
        if interval_us == 0:
            interval_us = interval_us_for(DEFAULT_RATES_HZ.get(name, FALLBACK_DEFAULT_HZ))
        elif interval_us > 0:
            interval_us = max(interval_us, int(1e6 / MAX_RATE_HZ))
        self._set(peer, name, interval_us)
        return True

    def get_interval(self, peer: Peer, name: str) -> int:
        st = self.endpoint.link_state(peer)
        if name not in self.builders and name != "HEARTBEAT":
            return 0
        return st.intervals_us.get(name, -1)

    def request_data_stream(self, peer: Peer, stream_id: int, rate_hz: int, start: bool) -> None:
        """Legacy REQUEST_DATA_STREAM: one rate for a whole ArduCopter stream group (0 = all)."""
        self.endpoint.link_state(peer)
        groups = list(STREAM_GROUPS) if stream_id == mavlink2.MAV_DATA_STREAM_ALL else [stream_id]
        interval = interval_us_for(rate_hz) if start else -1
        for g in groups:
            for name in STREAM_GROUPS.get(g, ()):
                if name in self.builders:
                    self._set(peer, name, interval)

    def send_now(self, name: str, peer: Peer | None) -> bool:
        """REQUEST_MESSAGE: build and send ``name`` once; False if it is unknown or not available."""
        fn = self.builders.get(name)
        if fn is None:
            return False
        msg = fn()
        if msg is None:
            return False
        self.endpoint.send(msg, peer)
        return True

    # --- periodic ------------------------------------------------------------------------------
    def update(self) -> None:
        ep = self.endpoint
        now = ep.clock.now_us
        built: dict[str, Any] = {}
        for peer in ep.peers():
            st = peer.state if peer.state is not None else ep.link_state(peer)
            if now < st.next_any_us:
                continue
            next_any = now + HEARTBEAT_INTERVAL_US
            for name, due in list(st.next_due_us.items()):
                if now >= due:
                    interval = st.intervals_us[name]
                    # the next multiple of the interval in simulated time (never a burst after a slow call):
                    # streams of commensurate rates (20, 10, 5, 2, 1 Hz) fall due in the same telemetry call
                    # and leave in one datagram (the endpoint gathers a call's packets per link)
                    due = now - now % interval + interval
                    st.next_due_us[name] = due
                    msg = built.get(name)
                    if msg is None:
                        msg = self._build(name)
                        built[name] = msg
                    if msg is not None:
                        ep.send(msg, peer)
                if due < next_any:
                    next_any = due
            st.next_any_us = next_any

    def _build(self, name: str) -> Any:
        fn = self.builders.get(name)
        if fn is None:
            return None
        try:
            return fn()
        except Exception:
            self.endpoint.stats["builder_error"] += 1
            log.exception("building %s failed", name)
            return None
