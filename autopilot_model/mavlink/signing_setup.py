"""SETUP_SIGNING: a ground station gives the vehicle its MAVLink 2 signing key (ArduPilot's
``GCS_MAVLINK::handle_setup_signing``, libraries/GCS_MAVLink/GCS_Signing.cpp).

* Refused while armed, with the STATUSTEXT "ERROR: Won't setup signing when armed".
* Otherwise the key takes effect at once on every link: incoming packets must then be signed with it
  (:mod:`.signing`), and everything sent is signed. The signing timestamp moves forward to
  ``initial_timestamp`` if that is later.
* An all-zero key with timestamp 0 turns signing off (ArduPilot's ``load_signing_key``).

ArduPilot keeps the key in its parameter storage across restarts; the model keeps it for the process's
life (a restart starts with ``--signing-key``, or unsigned).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

if TYPE_CHECKING:
    from .endpoint import MavlinkEndpoint
    from .transport import Peer


class SigningSetup:
    """Installs the SETUP_SIGNING handler on an endpoint; ``armed`` tells whether the vehicle is armed."""

    def __init__(self, endpoint: MavlinkEndpoint, armed: Callable[[], bool]) -> None:
        self.ep = endpoint
        self._armed = armed
        endpoint.add_handler("SETUP_SIGNING", self._on_setup_signing)

    def _on_setup_signing(self, msg: Any, peer: Peer) -> None:
        ep = self.ep
        if self._armed():
            ep.statustext(mavlink2.MAV_SEVERITY_WARNING, "ERROR: Won't setup signing when armed")
            return
        key = bytes(msg.secret_key)
        if len(key) != 32:
            ep.stats["setup_signing_bad_key"] += 1
            return
        off = msg.initial_timestamp == 0 and not any(key)
        ep.set_signing_key(None if off else key, int(msg.initial_timestamp))
        ep.stats["setup_signing"] += 1
