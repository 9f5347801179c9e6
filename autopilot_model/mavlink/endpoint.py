"""The autopilot model's MAVLink endpoint: a datalink module of the static scheduler (seed 002).

Seed 002 (Sec. 3.2, Fig. 4) puts the datalink among the *event* functions, polled every main-loop
iteration, and the telemetry in its own task group at the end of the iteration. Accordingly the
endpoint has two functions, which the wiring (:mod:`.wiring`) registers with the vehicle:

* ``mavlink.poll`` (event, every iteration): one ``epoll`` call; when data is waiting, read it, parse
  it (:mod:`.framing`), check signatures (:mod:`.signing`) and target ids, and dispatch each message to
  its handler from :attr:`MavlinkEndpoint.handlers`.
* ``mavlink.telemetry`` (periodic, telemetry group): the functions in :attr:`MavlinkEndpoint.periodic`
  (the streams whose interval has elapsed on each link, the paced parameter list).

This module is the endpoint's core: links, framing, signing, dispatch, sending, the heartbeat and
TIMESYNC. It imports no protocol piece. The pieces (streams, commands, parameters, missions, the
vehicle's telemetry ...) install themselves with :meth:`MavlinkEndpoint.add_handler` (messages),
:attr:`MavlinkEndpoint.link_opened` (per-link set-up) and :attr:`MavlinkEndpoint.periodic` (the
telemetry group); :mod:`.wiring` is the one place that builds them and hands each the others it needs.

Every handler runs inside a guard: whatever a packet contains, the endpoint neither raises nor lets a
half-applied change through; malformed input is counted in :attr:`MavlinkEndpoint.stats`.
All MAVLink time fields are simulated time (the vehicle's clock).
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from .framing import FrameParser
from .signing import Signing
from .transport import Peer, Poller, Transport, open_transport

if TYPE_CHECKING:
    from autopilot_model.params import ParamStore
    from taskflight_common.clock import SimClock

log = logging.getLogger(__name__)

Handler = Callable[[Any, Peer], None]

#: Wall-time budget for reading sockets in one poll (a flood must not stall the 500 Hz loop).
POLL_BUDGET_S = 0.0006
#: The largest datagram (or TCP write) the endpoint gathers packets into: under an Ethernet MTU's UDP
#: payload (1472 bytes), so a gathered datagram is never fragmented.
GATHER_MAX_BYTES = 1400
STATUSTEXT_LEN = 50

MAV_TYPE_GCS = mavlink2.MAV_TYPE_GCS


class LinkState:
    """What the protocol keeps per link: its own encoder (sequence numbers) and stream table."""

    def __init__(self, endpoint: MavlinkEndpoint) -> None:
        self.mav = mavlink2.MAVLink(None, endpoint.sysid, endpoint.compid)
        endpoint.signing.configure_encoder(self.mav)
        self.intervals_us: dict[str, int] = {}
        self.next_due_us: dict[str, int] = {}
        self.next_any_us = 0
        self.param_queue: list[int] = []
        self.param_next_us = 0


def define_endpoint_params(params: ParamStore, instance: int = 0) -> None:
    """Parameters the endpoint itself owns."""
    params.define("MAV_SYSID", instance + 1, 1, 255, "int",
                  "MAVLink system id of this vehicle (SYSID_THISMAV in older ArduPilot)")
    params.define("MAV_GCS_SYSID", 255, 1, 255, "int", "system id of the ground station (SYSID_MYGCS)")
    params.define("TELEM_DEFAULTS", 1, 0, 1, "int",
                  "1: stream a basic telemetry set to every new link before it asks for rates")


class MavlinkEndpoint:
    """MAVLink 2 endpoint of one vehicle (ArduCopter dialect): links, dispatch, stats."""

    def __init__(self, clock: SimClock, params: ParamStore, urls: Iterable[str], sysid: int | None = None,
                 compid: int = 1, signing_key: bytes | None = None, instance: int = 0) -> None:
        self.clock = clock
        self.params = params
        define_endpoint_params(params, instance)
        self.sysid = int(sysid if sysid is not None else params.get("MAV_SYSID"))
        self.compid = compid
        self.stats: Counter[str] = Counter()
        self.signing = Signing(signing_key)
        self.mav = mavlink2.MAVLink(None, self.sysid, self.compid)
        self.handlers: dict[str, Handler] = {}
        self.link_opened: list[Callable[[Peer], None]] = []
        """Called with each new link once its :class:`LinkState` exists (e.g. default stream rates)."""
        self.periodic: list[Callable[[], None]] = []
        """Called, in order, by :meth:`telemetry` (the telemetry task group)."""
        self.last_gcs_heartbeat_s: float | None = None
        self._statustext_id = 0
        self._outbox: dict[Peer, list[bytes]] | None = None  # packets gathered per link (see send)
        self.poller = Poller()
        self._epoll = self.poller.epoll_poll
        self.transports: list[Transport] = []
        for url in urls:
            self.transports.append(open_transport(url, self.stats, self.poller))
        self.add_handler("HEARTBEAT", self._on_heartbeat)
        self.add_handler("TIMESYNC", self._on_timesync)
        log.info("MAVLink endpoint sysid %d on %s", self.sysid,
                 ", ".join(str(t.url) for t in self.transports))

    # --- plumbing ------------------------------------------------------------------------------
    def add_handler(self, msg_type: str, fn: Handler) -> None:
        """Handle every accepted message of ``msg_type`` (e.g. ``"MISSION_COUNT"``) with ``fn(msg, link)``."""
        self.handlers[msg_type] = fn

    def peers(self) -> list[Peer]:
        """Every link we may send to (udpin senders, udpout targets, TCP clients)."""
        out: list[Peer] = []
        for t in self.transports:
            for p in t.peers():
                if p.active and not p.closed:
                    out.append(p)
        return out

    def link_state(self, peer: Peer) -> LinkState:
        if peer.state is None:
            state = peer.state = LinkState(self)
            for fn in self.link_opened:
                fn(peer)
            return state
        state = peer.state
        assert isinstance(state, LinkState)
        return state

    def set_signing_key(self, key: bytes | None, initial_timestamp: int = 0) -> None:
        """Enable (32-byte key) or disable (None) signing, for incoming checks and outgoing packets on
        every link at once; the signing timestamp moves forward to ``initial_timestamp`` if later."""
        self.signing.set_key(key)
        self.signing.raise_timestamp(initial_timestamp)
        self.signing.configure_encoder(self.mav)
        for t in self.transports:
            for p in t.peers():
                if p.state is not None:
                    self.signing.configure_encoder(p.state.mav)

    # --- sending -------------------------------------------------------------------------------
    def send(self, msg: Any, link: Peer | None = None) -> None:
        """Send one message on ``link`` (None: on every link). Encoded with each link's sequence.

        Inside :meth:`poll` and :meth:`telemetry` the packets are gathered per link and written when the
        function ends, several to a datagram (at most :data:`GATHER_MAX_BYTES`), as ArduPilot's serial
        drivers write their buffer: a telemetry tick's streams and a burst of replies cost the link one
        write and the receiver one wake-up, not one per message. Elsewhere a packet goes at once."""
        targets = [link] if link is not None else self.peers()
        out = self._outbox
        for peer in targets:
            if peer is None or peer.closed:
                continue
            st = self.link_state(peer)
            try:
                data = msg.pack(st.mav)
            except Exception as exc:  # a builder produced an out-of-range field
                self.stats["tx_encode_error"] += 1
                log.warning("cannot encode %s: %s", msg.get_type(), exc)
                return
            st.mav.seq = (st.mav.seq + 1) & 0xFF
            if out is not None:
                out.setdefault(peer, []).append(data)
            else:
                self._write(peer, [data])

    def _gather(self) -> bool:
        """Start gathering outgoing packets; False when already gathering (the outer call writes)."""
        if self._outbox is not None:
            return False
        self._outbox = {}
        return True

    def _write_gathered(self) -> None:
        """Write what was gathered: each link's packets in order, joined up to :data:`GATHER_MAX_BYTES`."""
        out, self._outbox = self._outbox, None
        for peer, packets in (out or {}).items():
            chunk: list[bytes] = []
            size = 0
            for data in packets:
                if chunk and size + len(data) > GATHER_MAX_BYTES:
                    self._write(peer, chunk)
                    chunk, size = [], 0
                chunk.append(data)
                size += len(data)
            self._write(peer, chunk)

    def _write(self, peer: Peer, packets: list[bytes]) -> None:
        """One write of ``packets`` on ``peer``; ``tx`` / ``tx_dropped`` count messages, not writes."""
        if peer.send_bytes(packets[0] if len(packets) == 1 else b"".join(packets)):
            self.stats["tx"] += len(packets)
        else:
            self.stats["tx_dropped"] += len(packets)

    def statustext(self, severity: int, text: str, link: Peer | None = None) -> None:
        """Send a STATUSTEXT (long texts are split in 50-character chunks sharing one id)."""
        log.info("STATUSTEXT[%d] %s", severity, text)
        raw = text.encode("utf-8", "replace")
        if len(raw) <= STATUSTEXT_LEN:
            self.send(self.mav.statustext_encode(severity, raw, 0, 0), link)
            return
        self._statustext_id = self._statustext_id % 65535 + 1
        chunks = [raw[i:i + STATUSTEXT_LEN] for i in range(0, len(raw), STATUSTEXT_LEN)]
        for seq, chunk in enumerate(chunks):
            self.send(self.mav.statustext_encode(severity, chunk, self._statustext_id, seq), link)

    # --- receiving -----------------------------------------------------------------------------
    def poll(self) -> None:
        """Event function: read and handle whatever arrived. One ``epoll`` call when nothing did."""
        events = self._epoll(0)
        if events:
            outer = self._gather()
            try:
                self.poller.dispatch(events, self._on_data, POLL_BUDGET_S)
            finally:
                if outer:
                    self._write_gathered()

    def _on_data(self, peer: Peer, data: bytes) -> None:
        parser = peer.parser
        if parser is None:
            parser = peer.parser = FrameParser(self.stats, self.signing, stream=peer.name.startswith("tcp"))
        for msg in parser.feed(data):
            self.handle_message(msg, peer)

    def handle_message(self, msg: Any, peer: Peer) -> None:
        """Check and dispatch one decoded message (also the entry point for in-process tests)."""
        self.stats["rx"] += 1
        if not peer.active:
            peer.active = True
            self.link_state(peer)
        tsys = getattr(msg, "target_system", None)
        if tsys is not None and tsys != 0 and tsys != self.sysid:
            self.stats["wrong_target"] += 1
            return
        tcomp = getattr(msg, "target_component", None)
        if tcomp is not None and tcomp != 0 and tcomp != self.compid and msg.get_type() != "SET_MODE":
            self.stats["wrong_target"] += 1
            return
        fn = self.handlers.get(msg.get_type())
        if fn is None:
            self.stats["unhandled"] += 1
            return
        try:
            fn(msg, peer)
        except InvalidFieldError as exc:
            self.stats["invalid_field"] += 1
            log.debug("%s from %s rejected: %s", msg.get_type(), peer.name, exc)
        except Exception:
            self.stats["handler_error"] += 1
            log.exception("handler for %s failed", msg.get_type())

    def _on_heartbeat(self, msg: Any, peer: Peer) -> None:
        """Like ArduCopter (GCS_MAVLINK::handle_heartbeat), only heartbeats from the system id
        MAV_GCS_SYSID (SYSID_MYGCS) count as the ground station's: a companion's heartbeat (another
        component of the vehicle's own system) never keeps the GCS failsafe quiet."""
        if msg.get_srcSystem() == int(self.params.get("MAV_GCS_SYSID")):
            self.last_gcs_heartbeat_s = self.clock.now()
            self.stats["gcs_heartbeats"] += 1

    def _on_timesync(self, msg: Any, peer: Peer) -> None:
        if msg.tc1 == 0:  # a request: answer with our (simulated) time in ns
            reply = self.mav.timesync_encode(self.clock.now_us * 1000, msg.ts1)
            self.send(reply, peer)

    # --- telemetry (periodic) ------------------------------------------------------------------
    def telemetry(self) -> None:
        """Periodic function (telemetry group): every function of :attr:`periodic`, in order; what they
        send is written at the end, gathered per link (see :meth:`send`)."""
        outer = self._gather()
        try:
            for fn in self.periodic:
                fn()
        finally:
            if outer:
                self._write_gathered()

    def close(self) -> None:
        for t in self.transports:
            t.close()
        self.poller.close()


class InvalidFieldError(ValueError):
    """A received message carries a field value that cannot be acted on (NaN, out of range ...)."""


def require_finite(*values: float, what: str = "field") -> None:
    """Raise :class:`InvalidFieldError` unless every value is a finite number."""
    for v in values:
        if not math.isfinite(v):
            raise InvalidFieldError(f"{what} is not finite")
