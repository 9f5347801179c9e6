"""The MAVLink mission protocol, vehicle side (https://mavlink.io/en/services/mission.html).

Upload: MISSION_COUNT -> MISSION_REQUEST_INT(0) -> MISSION_ITEM_INT(0) -> ... -> MISSION_ACK. Items
arrive into a staging list; the stored plan is replaced only when the whole upload succeeded, so a
bad item or an abandoned upload leaves the stored plan unchanged. A request that gets no answer is
repeated after :data:`ITEM_TIMEOUT_S`; after :data:`MAX_RETRIES` repeats the upload is given up with
MISSION_ACK(MAV_MISSION_OPERATION_CANCELLED) (ArduPilot repeats every second too, and gives up 8 s after
the last item it received, where the model gives up after about 6 s). A legacy MISSION_ITEM
is accepted and converted.

Download: MISSION_REQUEST_LIST -> MISSION_COUNT; then each MISSION_REQUEST_INT (or legacy
MISSION_REQUEST) is answered with MISSION_ITEM_INT. Download is driven by the ground station (which
owns its timeouts), so the vehicle side keeps no state for it. As in ArduPilot, item 0 of the flight
plan is reported as the current home position.

Partial upload (MISSION_WRITE_PARTIAL_LIST start..end, as ArduPilot's
``MissionItemProtocol::handle_mission_write_partial_list``): items start..end are requested in turn and
replace the stored ones (end = the count appends one); the other items stay. Refused with
MAV_MISSION_DENIED while an upload of that type is in progress, MAV_MISSION_ERROR for a bad range
(start or end past the count, end before start). The plan is swapped in when the last item arrived.

Also: MISSION_CLEAR_ALL, MISSION_SET_CURRENT (answered with MISSION_CURRENT), MISSION_CURRENT sent
on every change and streamed by the endpoint's telemetry (its builder is registered here). Mission
types MISSION, FENCE and RALLY are kept separately.

Time base: every timeout here is simulated time (the vehicle clock), as in
ArduCopter SITL, where ``MissionItemProtocol::update`` measures the request timeout with
``AP_HAL::millis()`` and SITL's ``millis()`` is the simulation's stopped clock. So the protocol keeps
the same rule as the GCS failsafe and every other vehicle timer: a model sped up N times repeats an
unanswered request after ``ITEM_TIMEOUT_S / N`` wall seconds, as ArduCopter at ``--speedup N`` does,
and a paused or slowed model never gives up on a ground station that is merely slower than the wall.
The model's rule for each purpose is listed in ``docs/conformance.md`` ("Time bases").
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Protocol

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from autopilot_model.modules.mission import (
    ACCEPTED,
    FRAME_GLOBAL,
    MAX_ITEMS,
    MISSION,
    MISSION_TYPES,
    NAV_WAYPOINT,
    MissionItem,
    MissionStore,
    validate_item,
    validate_plan,
)

if TYPE_CHECKING:
    from .commands import CommandDispatcher
    from .streams import StreamScheduler

log = logging.getLogger(__name__)

ITEM_TIMEOUT_S = 1.0
"""Simulated time without the requested item after which the request is repeated (ArduPilot: 1 s)."""
MAX_RETRIES = 5
"""Repeated requests before an upload is given up."""
ACK_REPEAT_WINDOW_S = 5.0
"""Simulated time after an upload during which the final item, if sent again (our ACK was lost), is
acknowledged again."""
MISSION_TYPE_ALL = mavlink.MAV_MISSION_TYPE_ALL

# MISSION_STATE values for MISSION_CURRENT
STATE_NO_MISSION = 1
STATE_NOT_STARTED = 2
STATE_ACTIVE = 3
STATE_PAUSED = 4
STATE_COMPLETE = 5


class Endpoint(Protocol):
    """What the protocol needs of :class:`autopilot_model.mavlink.endpoint.MavlinkEndpoint`."""

    mav: Any

    def add_handler(self, msg_type: str, fn: Callable[[Any, Any], None]) -> None: ...
    def send(self, msg: Any, link: Any = None) -> None: ...
    def statustext(self, severity: int, text: str) -> None: ...


class MissionStatus(Protocol):
    """What MISSION_CURRENT reports of the mission's execution (the runner provides it)."""

    @property
    def mission_state(self) -> int: ...
    @property
    def mission_mode(self) -> int: ...


@dataclass
class _Upload:
    """One upload in progress (one per mission type)."""

    mission_type: int
    count: int
    link: Any
    peer: tuple[int, int]
    items: list[MissionItem] = field(default_factory=list)
    t_request: float = 0.0
    """Simulated time of the last MISSION_REQUEST_INT sent."""
    retries: int = 0
    tail: list[MissionItem] = field(default_factory=list)
    """Partial upload: the stored items after the range, kept."""

    @property
    def expected(self) -> int:
        return len(self.items)


class MissionProtocol:
    """Upload/download/clear/set-current handlers on an endpoint, plus :meth:`periodic` for timeouts.

    ``now`` gives simulated seconds; ``home`` gives the home position (lat deg, lon deg, alt m AMSL) or
    None. With ``commands``, MAV_CMD_DO_SET_MISSION_CURRENT is handled; with ``streams``, MISSION_CURRENT
    is streamed at the rates the links ask for (default 1 Hz).
    """

    def __init__(self, endpoint: Endpoint, store: MissionStore, *, now: Callable[[], float],
                 home: Callable[[], tuple[float, float, float] | None],
                 commands: CommandDispatcher | None = None, streams: StreamScheduler | None = None) -> None:
        self.endpoint = endpoint
        self.store = store
        self.status: MissionStatus | None = None
        """Set by the wiring to the :class:`MissionRunner` so MISSION_CURRENT carries the state."""
        self._now = now
        self._home = home
        self._uploads: dict[int, _Upload] = {}
        self._finished: dict[int, tuple[tuple[int, int], int, float]] = {}
        self.stats = {"uploads": 0, "upload_errors": 0, "retries": 0, "downloads": 0}
        for name, fn in (("MISSION_COUNT", self._on_count), ("MISSION_ITEM_INT", self._on_item),
                         ("MISSION_ITEM", self._on_item), ("MISSION_REQUEST_LIST", self._on_request_list),
                         ("MISSION_REQUEST_INT", self._on_request), ("MISSION_REQUEST", self._on_request),
                         ("MISSION_CLEAR_ALL", self._on_clear), ("MISSION_SET_CURRENT", self._on_set_current),
                         ("MISSION_ACK", self._on_ack),
                         ("MISSION_WRITE_PARTIAL_LIST", self._on_write_partial)):
            endpoint.add_handler(name, fn)
        store.on_current(lambda _seq: self.send_current())
        if commands is not None:
            commands.add(mavlink.MAV_CMD_DO_SET_MISSION_CURRENT, self._cmd_set_current)
        if streams is not None:
            streams.add_builder("MISSION_CURRENT", self.mission_current_msg)

    # --- helpers --------------------------------------------------------------------------------
    def _send(self, link: Any, name: str, *args: Any) -> None:
        self.endpoint.send(getattr(self.endpoint.mav, name + "_encode")(*args), link)

    def _ack(self, msg: Any, link: Any, result: int, mission_type: int) -> None:
        if result != ACCEPTED:
            log.info("mission %s from %d/%d: MISSION_ACK %s", msg.get_type(), msg.get_srcSystem(),
                     msg.get_srcComponent(), _result_name(result))
        self._send(link, "mission_ack", msg.get_srcSystem(), msg.get_srcComponent(), result, mission_type)

    def _request(self, up: _Upload) -> None:
        up.t_request = self._now()
        self._send(up.link, "mission_request_int", up.peer[0], up.peer[1], up.expected, up.mission_type)

    # --- upload ---------------------------------------------------------------------------------
    def _on_count(self, msg: Any, link: Any) -> None:
        mtype = _mission_type(msg)
        peer = (msg.get_srcSystem(), msg.get_srcComponent())
        if mtype not in MISSION_TYPES:
            self._ack(msg, link, mavlink.MAV_MISSION_UNSUPPORTED, mtype)
            return
        busy = self._uploads.get(mtype)
        if busy is not None and busy.peer != peer:
            self._ack(msg, link, mavlink.MAV_MISSION_DENIED, mtype)  # someone else is uploading
            return
        if msg.count > MAX_ITEMS:
            self._uploads.pop(mtype, None)
            self._ack(msg, link, mavlink.MAV_MISSION_NO_SPACE, mtype)
            return
        if msg.count == 0:
            self._uploads.pop(mtype, None)
            result = self._swap(mtype, [])
            self._ack(msg, link, result, mtype)
            return
        up = _Upload(mtype, int(msg.count), link, peer)
        self._uploads[mtype] = up  # a repeated MISSION_COUNT from the same peer restarts the upload
        log.info("mission upload of %d item(s), type %d, from %d/%d", up.count, mtype, *peer)
        self._request(up)

    def _on_write_partial(self, msg: Any, link: Any) -> None:
        mtype = _mission_type(msg)
        peer = (msg.get_srcSystem(), msg.get_srcComponent())
        if mtype not in MISSION_TYPES:
            self._ack(msg, link, mavlink.MAV_MISSION_UNSUPPORTED, mtype)
            return
        if mtype in self._uploads:
            self._ack(msg, link, mavlink.MAV_MISSION_DENIED, mtype)
            return
        stored = self.store.get(mtype)
        start, end = int(msg.start_index), int(msg.end_index)
        if start < 0 or end < 0 or start > len(stored) or end > len(stored) or end < start:
            self._ack(msg, link, mavlink.MAV_MISSION_ERROR, mtype)
            return
        up = _Upload(mtype, end + 1, link, peer, items=list(stored[:start]), tail=list(stored[end + 1:]))
        self._uploads[mtype] = up
        log.info("partial mission upload of items %d..%d, type %d, from %d/%d", start, end, mtype, *peer)
        self._request(up)

    def _on_item(self, msg: Any, link: Any) -> None:
        mtype = _mission_type(msg)
        peer = (msg.get_srcSystem(), msg.get_srcComponent())
        if mtype not in MISSION_TYPES:
            self._ack(msg, link, mavlink.MAV_MISSION_UNSUPPORTED, mtype)
            return
        up = self._uploads.get(mtype)
        if up is None:
            done = self._finished.get(mtype)
            if done is not None and done[0] == peer and done[1] == msg.seq and \
                    self._now() - done[2] < ACK_REPEAT_WINDOW_S:
                self._ack(msg, link, ACCEPTED, mtype)  # our final ACK was lost: say it again
            else:
                self._ack(msg, link, mavlink.MAV_MISSION_ERROR, mtype)  # no upload in progress
            return
        if up.peer != peer:
            self._ack(msg, link, mavlink.MAV_MISSION_DENIED, mtype)
            return
        if msg.seq < up.expected:  # a repeat of an item we have: ask again for the one we need
            self._request(up)
            return
        if msg.seq != up.expected:
            self._ack(msg, link, mavlink.MAV_MISSION_INVALID_SEQUENCE, mtype)
            return
        try:
            item = MissionItem.from_msg(msg)
        except ValueError as exc:
            self._fail(up, msg, link, int(exc.args[1]))
            return
        item = replace(item, mission_type=mtype)
        result = validate_item(item)
        if result != ACCEPTED:
            self._fail(up, msg, link, result)
            return
        up.items.append(item)
        up.retries = 0
        if up.expected < up.count:
            self._request(up)
            return
        del self._uploads[mtype]
        result = self._swap(mtype, up.items + up.tail)
        if result == ACCEPTED:
            self.stats["uploads"] += 1
            self._finished[mtype] = (peer, up.count - 1, self._now())
        else:
            self.stats["upload_errors"] += 1
        self._ack(msg, link, result, mtype)

    def _fail(self, up: _Upload, msg: Any, link: Any, result: int) -> None:
        self._uploads.pop(up.mission_type, None)
        self.stats["upload_errors"] += 1
        self._ack(msg, link, result, up.mission_type)

    def _swap(self, mtype: int, items: list[MissionItem]) -> int:
        result = validate_plan(mtype, items)
        if result != ACCEPTED:
            return result
        self.store.replace(mtype, items)
        if mtype == MISSION:
            self.send_current()
        return ACCEPTED

    # --- download -------------------------------------------------------------------------------
    def _on_request_list(self, msg: Any, link: Any) -> None:
        mtype = _mission_type(msg)
        if mtype not in MISSION_TYPES:
            self._ack(msg, link, mavlink.MAV_MISSION_UNSUPPORTED, mtype)
            return
        self.stats["downloads"] += 1
        self._send(link, "mission_count", msg.get_srcSystem(), msg.get_srcComponent(),
                   self.store.count(mtype), mtype)

    def _on_request(self, msg: Any, link: Any) -> None:
        mtype = _mission_type(msg)
        if mtype not in MISSION_TYPES:
            self._ack(msg, link, mavlink.MAV_MISSION_UNSUPPORTED, mtype)
            return
        if not 0 <= msg.seq < self.store.count(mtype):
            self._ack(msg, link, mavlink.MAV_MISSION_INVALID_SEQUENCE, mtype)
            return
        it = self.store.item(msg.seq, mtype)
        if mtype == MISSION and it.seq == 0:
            it = self._home_item(it)
        current = 1 if (mtype == MISSION and it.seq == self.store.current) else 0
        self._send(link, "mission_item_int", msg.get_srcSystem(), msg.get_srcComponent(), it.seq,
                   it.frame, it.command, current, it.autocontinue, it.param1, it.param2, it.param3,
                   it.param4, it.x, it.y, it.z, mtype)

    def _home_item(self, stored: MissionItem) -> MissionItem:
        home = self._home()
        if home is None:
            return stored
        lat, lon, alt = home
        return MissionItem(seq=0, frame=FRAME_GLOBAL, command=NAV_WAYPOINT, autocontinue=1,
                           x=round(lat * 1e7), y=round(lon * 1e7), z=float(alt))

    def _on_ack(self, msg: Any, link: Any) -> None:
        """The ground station's ACK ending a download (or cancelling one): nothing to undo."""
        log.debug("MISSION_ACK %s from %d/%d", _result_name(msg.type), msg.get_srcSystem(),
                  msg.get_srcComponent())

    # --- clear / current ------------------------------------------------------------------------
    def _on_clear(self, msg: Any, link: Any) -> None:
        mtype = _mission_type(msg)
        types = MISSION_TYPES if mtype == MISSION_TYPE_ALL else (mtype,)
        if mtype != MISSION_TYPE_ALL and mtype not in MISSION_TYPES:
            self._ack(msg, link, mavlink.MAV_MISSION_UNSUPPORTED, mtype)
            return
        if MISSION in types and self.store.running:
            self._ack(msg, link, mavlink.MAV_MISSION_DENIED, mtype)  # ArduPilot: not while flying it
            return
        for t in types:
            self._uploads.pop(t, None)
            self.store.clear(t)
        self.send_current()
        self._ack(msg, link, ACCEPTED, mtype)

    def _on_set_current(self, msg: Any, link: Any) -> None:
        if not self.set_current(int(msg.seq)):
            self.send_current(link)

    def _cmd_set_current(self, cmd: Any, link: Any) -> tuple[int, str | None]:
        """MAV_CMD_DO_SET_MISSION_CURRENT (param1: the item)."""
        seq = cmd.p(1)
        if not math.isfinite(seq) or seq < 0 or seq != int(seq):
            return mavlink.MAV_RESULT_DENIED, "Mission: invalid item"
        if not self.set_current(int(seq)):
            return mavlink.MAV_RESULT_DENIED, None  # set_current has said why
        return mavlink.MAV_RESULT_ACCEPTED, None

    def set_current(self, seq: int) -> bool:
        """Make ``seq`` the current item (also for MAV_CMD_DO_SET_MISSION_CURRENT); False if invalid.

        On success MISSION_CURRENT is sent (the answer the protocol defines); the runner, if flying the
        plan, jumps to the item.
        """
        if not self.store.set_current(seq):
            self.endpoint.statustext(mavlink.MAV_SEVERITY_WARNING, f"Mission: invalid item {seq}")
            return False
        self.send_current()
        return True

    def mission_current_msg(self) -> Any:
        """A MISSION_CURRENT message for the present state (also usable by the telemetry streams)."""
        n = self.store.count(MISSION)
        total = n - 1 if n > 0 else 65535  # home (item 0) excluded, UINT16_MAX: no mission
        if self.status is not None:
            state, mode = self.status.mission_state, self.status.mission_mode
        else:
            state, mode = (STATE_NO_MISSION if n <= 1 else STATE_NOT_STARTED), 0
        return self.endpoint.mav.mission_current_encode(self.store.current, total, state, mode)

    def send_current(self, link: Any = None) -> None:
        """Send MISSION_CURRENT now (on every change; the telemetry streams repeat it)."""
        self.endpoint.send(self.mission_current_msg(), link)

    # --- periodic -------------------------------------------------------------------------------
    def periodic(self) -> None:
        """Repeat unanswered requests and give up exhausted uploads (call at 10 Hz or faster)."""
        for up in list(self._uploads.values()):
            if self._now() - up.t_request < ITEM_TIMEOUT_S:
                continue
            if up.retries >= MAX_RETRIES:
                del self._uploads[up.mission_type]
                self.stats["upload_errors"] += 1
                log.warning("mission upload (type %d) abandoned at item %d/%d", up.mission_type,
                            up.expected, up.count)
                self._send(up.link, "mission_ack", up.peer[0], up.peer[1],
                           mavlink.MAV_MISSION_OPERATION_CANCELLED, up.mission_type)
                continue
            up.retries += 1
            self.stats["retries"] += 1
            self._request(up)

    @property
    def uploading(self) -> bool:
        return bool(self._uploads)


def _mission_type(msg: Any) -> int:
    """The message's mission_type (a MAVLink 2 extension: absent or 0 from MAVLink 1 senders)."""
    return int(getattr(msg, "mission_type", MISSION) or 0)


def _result_name(result: int) -> str:
    entry = mavlink.enums["MAV_MISSION_RESULT"].get(result)
    return entry.name if entry is not None else str(result)


def finite_home(home: Sequence[float]) -> tuple[float, float, float] | None:
    """Home (lat, lon, alt AMSL) as MISSION item 0 carries it; None unless all three are finite."""
    lat, lon, alt = float(home[0]), float(home[1]), float(home[2])
    return (lat, lon, alt) if all(map(math.isfinite, (lat, lon, alt))) else None
