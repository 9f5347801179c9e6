"""MAVLink parameter protocol over the model's :class:`~autopilot_model.params.ParamStore`.

* PARAM_REQUEST_LIST: every parameter as PARAM_VALUE, *paced* (a few per telemetry call and at most
  :data:`WALL_RATE_PER_LINK` per wall second, so a sped-up simulation does not overrun the receiver's
  socket buffer), per link, restartable.
* PARAM_REQUEST_READ: by name (``param_index == -1``) or by index; unknown ones get no answer, as
  in ArduPilot (counted in ``stats["param_unknown"]``).
* PARAM_SET: type and range checked by the store. Accepted: the new value is broadcast as PARAM_VALUE
  on every link (and persisted by the store when a file is attached). Rejected (unknown, out of
  range, not an integer, not finite): the value is left as it was, a STATUSTEXT says why, and the
  current value is sent back to the requester so its cache stays right.

Values are sent as C-cast floats (MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST, ArduPilot's encoding);
integer parameters are typed MAV_PARAM_TYPE_INT32, the rest MAV_PARAM_TYPE_REAL32.
"""

from __future__ import annotations

import logging
import math
import time
from typing import TYPE_CHECKING, Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from autopilot_model.params import PARAM_INT, ParamError

from .endpoint import InvalidFieldError

if TYPE_CHECKING:
    from .endpoint import MavlinkEndpoint
    from .transport import Peer

log = logging.getLogger(__name__)

PER_CALL = 8
WALL_RATE_PER_LINK = 4000.0


def _name_of(raw: Any) -> str:
    if isinstance(raw, bytes | bytearray):
        raw = raw.split(b"\x00", 1)[0].decode("ascii", "replace")
    return str(raw).split("\x00", 1)[0].strip()


class ParamsProtocol:
    """Handlers for PARAM_REQUEST_LIST / PARAM_REQUEST_READ / PARAM_SET and the paced list sender."""

    def __init__(self, endpoint: MavlinkEndpoint) -> None:
        self.endpoint = endpoint
        self.store = endpoint.params
        endpoint.add_handler("PARAM_REQUEST_LIST", self._on_request_list)
        endpoint.add_handler("PARAM_REQUEST_READ", self._on_request_read)
        endpoint.add_handler("PARAM_SET", self._on_set)
        self._active: list[Peer] = []
        self._tokens: dict[int, tuple[float, float]] = {}

    # --- encoding ------------------------------------------------------------------------------
    def value_message(self, index: int) -> Any:
        d = self.store.by_index(index)
        ptype = mavlink2.MAV_PARAM_TYPE_INT32 if d.kind == PARAM_INT else mavlink2.MAV_PARAM_TYPE_REAL32
        return self.endpoint.mav.param_value_encode(d.name.encode("ascii"), float(d.value), ptype,
                                                    len(self.store), index)

    # --- handlers ------------------------------------------------------------------------------
    def _on_request_list(self, msg: Any, peer: Peer) -> None:
        st = self.endpoint.link_state(peer)
        st.param_queue = list(range(len(self.store)))
        if peer not in self._active:
            self._active.append(peer)

    def _on_request_read(self, msg: Any, peer: Peer) -> None:
        if msg.param_index >= 0:
            if msg.param_index >= len(self.store):
                self.endpoint.stats["param_unknown"] += 1
                return
            index = msg.param_index
        else:
            name = _name_of(msg.param_id)
            if name not in self.store:
                self.endpoint.stats["param_unknown"] += 1
                return
            index = self.store.index_of(name)
        self.endpoint.send(self.value_message(index), peer)

    def _on_set(self, msg: Any, peer: Peer) -> None:
        ep = self.endpoint
        name = _name_of(msg.param_id)
        if name not in self.store:
            ep.stats["param_unknown"] += 1
            ep.statustext(mavlink2.MAV_SEVERITY_WARNING, f"unknown parameter {name}", peer)
            return
        value = msg.param_value
        try:
            self.store.set(name, value)
        except ParamError as exc:
            ep.stats["param_rejected"] += 1
            ep.statustext(mavlink2.MAV_SEVERITY_WARNING, str(exc), peer)
            ep.send(self.value_message(self.store.index_of(name)), peer)
            if not math.isfinite(value):
                raise InvalidFieldError(f"{name}: value not finite") from None
            return
        log.info("parameter %s set to %g", name, self.store.get(name))
        ep.send(self.value_message(self.store.index_of(name)), None)

    # --- periodic ------------------------------------------------------------------------------
    def update(self) -> None:
        """Send the next few parameters of every list in progress (telemetry group)."""
        if not self._active:
            return
        now = time.perf_counter()
        for peer in list(self._active):
            st = peer.state
            if peer.closed or st is None or not st.param_queue:
                self._active.remove(peer)
                continue
            tokens, last = self._tokens.get(id(peer), (float(PER_CALL), now))
            tokens = min(float(PER_CALL), tokens + (now - last) * WALL_RATE_PER_LINK)
            n = min(int(tokens), PER_CALL, len(st.param_queue))
            for _ in range(n):
                index = st.param_queue.pop(0)
                if index < len(self.store):
                    self.endpoint.send(self.value_message(index), peer)
            self._tokens[id(peer)] = (tokens - n, now)
