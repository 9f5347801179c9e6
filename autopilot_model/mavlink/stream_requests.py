"""How clients ask for telemetry: the messages and commands that drive :mod:`.streams`.

* REQUEST_DATA_STREAM (legacy; MAVProxy): a rate for an ArduCopter stream group on the requesting link.
* MAV_CMD_SET_MESSAGE_INTERVAL (MAVSDK, QGC): one message's interval on the requesting link.
* MAV_CMD_GET_MESSAGE_INTERVAL: answered with MESSAGE_INTERVAL.
* MAV_CMD_REQUEST_MESSAGE: one message now (after the ACK, as ArduPilot does);
  MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES is the older way to ask for AUTOPILOT_VERSION.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from .commands import ACCEPTED, DENIED, UNSUPPORTED, Command, CommandResult

if TYPE_CHECKING:
    from .commands import CommandDispatcher
    from .endpoint import MavlinkEndpoint
    from .streams import StreamScheduler
    from .transport import Peer


def message_name(msg_id: float) -> str | None:
    """Name of a message id given as a command parameter (a float), or None."""
    if not math.isfinite(msg_id) or msg_id < 0 or msg_id != int(msg_id):
        return None
    cls = mavlink2.mavlink_map.get(int(msg_id))
    return cls.msgname if cls is not None else None


class StreamRequests:
    """Installs the stream-request handlers on an endpoint."""

    def __init__(self, endpoint: MavlinkEndpoint, streams: StreamScheduler,
                 commands: CommandDispatcher) -> None:
        self.endpoint = endpoint
        self.streams = streams
        self.commands = commands
        endpoint.add_handler("REQUEST_DATA_STREAM", self._on_request_data_stream)
        cmds = commands
        cmds.add(mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL, self._set_interval, dedup=False)
        cmds.add(mavlink2.MAV_CMD_GET_MESSAGE_INTERVAL, self._get_interval, dedup=False)
        cmds.add(mavlink2.MAV_CMD_REQUEST_MESSAGE, self._request_message, dedup=False)
        cmds.add(mavlink2.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, self._request_capabilities, dedup=False)

    def _on_request_data_stream(self, msg: Any, peer: Peer) -> None:
        self.streams.request_data_stream(peer, msg.req_stream_id, msg.req_message_rate,
                                                  bool(msg.start_stop) and msg.req_message_rate > 0)

    def _set_interval(self, cmd: Command, peer: Peer) -> CommandResult:
        name = message_name(cmd.p(1))
        interval = cmd.p(2)
        if name is None or (not self.streams.supports(name) and name != "HEARTBEAT"):
            return UNSUPPORTED, None
        if not math.isfinite(interval) or interval < -1:
            return DENIED, "SET_MESSAGE_INTERVAL: bad interval"
        self.streams.set_interval(peer, name, int(interval))
        return ACCEPTED, None

    def _get_interval(self, cmd: Command, peer: Peer) -> CommandResult:
        name = message_name(cmd.p(1))
        if name is None:
            return UNSUPPORTED, None
        interval = self.streams.get_interval(peer, name)
        ep = self.endpoint
        reply = ep.mav.message_interval_encode(int(cmd.p(1)), interval)
        self.commands.after_ack(lambda: ep.send(reply, peer))
        return ACCEPTED, None

    def _request_message(self, cmd: Command, peer: Peer) -> CommandResult:
        name = message_name(cmd.p(1))
        streams = self.streams
        if name is None or not streams.supports(name):
            return UNSUPPORTED, None
        streams_fn = streams.send_now
        self.commands.after_ack(lambda: streams_fn(name, peer))
        return ACCEPTED, None

    def _request_capabilities(self, cmd: Command, peer: Peer) -> CommandResult:
        if not self.streams.supports("AUTOPILOT_VERSION"):
            return UNSUPPORTED, None
        if cmd.p(1) == 1:
            streams = self.streams
            self.commands.after_ack(lambda: streams.send_now("AUTOPILOT_VERSION", peer))
        return ACCEPTED, None
