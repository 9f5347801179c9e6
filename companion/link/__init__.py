"""The companion's MAVLink link to the autopilot (seed 000 Fig. 10: the QuadNode-firmware connection).

* :mod:`.clock` -- :class:`AutopilotClock`, the autopilot's time estimated between telemetry samples;
* :mod:`.mirror` -- :class:`VehicleMirror`, the vehicle's state (one writer: the receive thread);
* :mod:`.commands` -- COMMAND_LONG with ACK tracking and retries;
* :mod:`.setpoints` -- SET_POSITION_TARGET_LOCAL_NED encoding (type masks as ArduCopter reads them)
  and the is_synced check on the POSITION_TARGET_LOCAL_NED echo;
* :mod:`.connection` -- :class:`MavlinkLink`: pymavlink over UDP, TCP or serial, heartbeat, streams;
* :mod:`.guided` -- :class:`GuidedSupervisor`: GUIDED, arming, take-off, LAND, override detection.

Only this package speaks MAVLink to the autopilot (ARCHITECTURE).
"""

from .clock import AutopilotClock
from .commands import CommandRequest, CommandState, CommandTracker
from .connection import MavlinkLink, parse_url
from .guided import GuidedSupervisor, Phase
from .mirror import MirrorState, VehicleMirror
from .setpoints import MASK_POSITION, MASK_VELOCITY, SyncTracker, target_fields

__all__ = ["MASK_POSITION", "MASK_VELOCITY", "AutopilotClock", "CommandRequest", "CommandState",
           "CommandTracker", "GuidedSupervisor", "MavlinkLink", "MirrorState", "Phase", "SyncTracker",
           "VehicleMirror", "parse_url", "target_fields"]
