"""The one place the MAVLink endpoint's protocol pieces are built and handed to each other.

:class:`~.endpoint.MavlinkEndpoint` is the core (links, framing, signing, dispatch) and imports no piece.
Every piece installs its handlers on the core when built; what a piece needs of another (the stream
scheduler to add telemetry builders to, the command dispatcher to add MAV_CMDs to) it is given here:

* :func:`link_protocol`: what any MAVLink vehicle speaks (message streams and their requests, MAV_CMD
  dispatch, parameters, SETUP_SIGNING);
* :func:`vehicle_link`: that plus the vehicle's telemetry, commands, GUIDED targets, pilot input,
  missions and failsafe status, with the endpoint's two scheduler functions registered on the
  vehicle (seed 002 Sec. 3.2: ``mavlink.poll`` an event function, ``mavlink.telemetry`` in the
  telemetry group).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from autopilot_model.modules.flight_modes import FlightModes
from autopilot_model.modules.mission import MissionRunner, MissionStore
from autopilot_model.modules.rc_input import RcInput
from autopilot_model.modules.safety import Safety
from autopilot_model.modules.vehicle_api import VehicleApi

from .commands import CommandDispatcher
from .endpoint import MavlinkEndpoint
from .guided import GuidedTargetsProtocol
from .mission_protocol import MissionProtocol, finite_home
from .params_protocol import ParamsProtocol
from .pilot import PilotLink
from .rangefinder_link import RangeFinderLink
from .signing_setup import SigningSetup
from .status_telemetry import FenceLink, StatusTelemetry
from .stream_requests import StreamRequests
from .streams import StreamScheduler
from .telemetry import VehicleTelemetry
from .vehicle_commands import VehicleCommands


@dataclass
class LinkProtocol:
    """The vehicle-independent pieces of one endpoint."""

    endpoint: MavlinkEndpoint
    streams: StreamScheduler
    commands: CommandDispatcher
    params: ParamsProtocol
    stream_requests: StreamRequests
    signing_setup: SigningSetup


def link_protocol(endpoint: MavlinkEndpoint, armed: Callable[[], bool] = lambda: False) -> LinkProtocol:
    """Streams, MAV_CMD dispatch, parameters and SETUP_SIGNING (refused while ``armed()``) on ``endpoint``."""
    streams = StreamScheduler(endpoint)
    commands = CommandDispatcher(endpoint)
    params = ParamsProtocol(endpoint)
    endpoint.link_opened.append(streams.init_link)
    endpoint.periodic += [streams.update, params.update]
    return LinkProtocol(endpoint, streams, commands, params, StreamRequests(endpoint, streams, commands),
                        SigningSetup(endpoint, armed))


@dataclass
class VehicleLink:
    """Every piece of a vehicle's endpoint (what ``taskflight autopilot`` serves)."""

    protocol: LinkProtocol
    telemetry: VehicleTelemetry
    vehicle_commands: VehicleCommands
    guided: GuidedTargetsProtocol
    pilot: PilotLink
    missions: MissionProtocol
    status: StatusTelemetry
    fence: FenceLink
    rangefinder: RangeFinderLink | None = None

    @property
    def endpoint(self) -> MavlinkEndpoint:
        return self.protocol.endpoint

    @property
    def streams(self) -> StreamScheduler:
        return self.protocol.streams


def vehicle_link(endpoint: MavlinkEndpoint, vehicle: VehicleApi, modes: FlightModes, rc: RcInput,
                 store: MissionStore, runner: MissionRunner, safety: Safety) -> VehicleLink:
    """Build every piece of ``vehicle``'s endpoint and register the endpoint's scheduler functions
    (``mavlink.poll``, ``mavlink.telemetry``, ``mission.periodic``) on the vehicle."""
    proto = link_protocol(endpoint, armed=lambda: vehicle.nav.armed)
    streams, commands = proto.streams, proto.commands
    telemetry = VehicleTelemetry(endpoint, streams, modes)
    vehicle_commands = VehicleCommands(endpoint, streams, commands, modes)
    guided = GuidedTargetsProtocol(endpoint, streams, modes)
    pilot = PilotLink(endpoint, streams, rc)
    missions = MissionProtocol(endpoint, store, now=vehicle.clock.now, home=lambda: finite_home(vehicle.home),
                               commands=commands, streams=streams)
    missions.status = runner
    fence = safety.fence
    fence_link = FenceLink(endpoint, streams, commands, fence)
    safety.on_fence_breach = fence_link.send_now
    status = StatusTelemetry(endpoint, streams, vehicle)
    telemetry.capabilities |= (mavlink2.MAV_PROTOCOL_CAPABILITY_MISSION_INT
                               | mavlink2.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE
                               | mavlink2.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY)
    telemetry.critical = lambda: bool(
        safety.gcs_failsafe or safety.battery_level or safety.fence_breached
        or safety.ekf_failsafe or rc.failsafe)
    telemetry.fence_state = lambda: (bool(fence.present()),
                                     fence.enabled and vehicle.params.get("FENCE_ACTION") != 0,
                                     bool(fence.breached))
    sensor = getattr(vehicle, "rangefinder", None)  # a kinematic test vehicle has none
    ranges = RangeFinderLink(endpoint, streams, sensor, vehicle.clock) if sensor is not None else None
    link = VehicleLink(proto, telemetry, vehicle_commands, guided, pilot, missions, status, fence_link,
                       ranges)
    vehicle.register("mavlink.poll", endpoint.poll)
    vehicle.register("mavlink.telemetry", endpoint.telemetry)
    vehicle.register("mission.periodic", missions.periodic)
    return link
