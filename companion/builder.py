"""The companion's composition root: one configuration, one builder, for every user of a companion.

``taskflight companion`` (:mod:`companion.main`), the demos, ``fig16``, the benches and the tests all build
a vehicle's companion here: :class:`CompanionConfig` says what it is made of (the autopilot link, the
flight envelope and limits, the pause routines, the executive layer and its behavior catalog, the mission
layer's platform, the team, the control surface and its token), :func:`build_companion` makes the parts,
and :class:`Companion` starts and closes them in their one order:

* start: the QuadNode (seed 000 Fig. 10: the queue's tick thread and the link), the executive layer
  (seed 001), the mission given at start (seed 000 Sec. III; delegated once the vehicle's home is known),
  the team member (seed 003; once the autopilot is heard), the commands to queue and ``run`` (with the
  executive layer on: the operator's FLY_COMMANDS behavior, the coordinator being the queue's one writer),
  the control surface (:mod:`companion.http`);
* close: the control surface, the team member, the mission layer, the executive layer, the node, the
  flight log.

Between :func:`build_companion` and :meth:`Companion.start` a caller may attach listeners to the node
(``node.setpoint_listeners``, ``node.link.listeners``): the node is made but not started.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass, field
from pathlib import Path

from companion.behaviors.catalog import BehaviorCatalog
from companion.behaviors.system import ExecutiveLayer
from companion.flight import Envelope, FlightCommand, Limits, PauseRoutineCatalog
from companion.flight.external import DEFAULT_MAX_VALIDITY_S
from companion.flight.limits import FlightConfig, narrow
from companion.flightlog import FlightRecorder
from companion.http import ControlServer
from companion.http.auth import ControlTokens
from companion.http.server import is_loopback
from companion.mission_service import MissionService
from companion.node import QuadNode
from companion.safety import SafetyConfig, SafetyDecision, SafetyMonitor
from companion.sensing.scenario import Scenario
from companion.team.join import join_team
from companion.team.member import TeamMember
from companion.team.transport import open_transport
from companion.tst.platform import Platform, bundled_platform
from companion.tst.spec import Mission

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class CompanionConfig:
    """What one vehicle's companion is made of (``taskflight companion``'s options, loaded)."""

    #: the autopilot link: ``udpout:HOST:PORT``, ``udpin:...``, ``tcp:...``, ``serial:DEVICE[:BAUD]``
    autopilot: str
    #: setpoint stream rate (Hz of autopilot time, 1..50)
    rate_hz: float = 20.0
    baud: int = 57600
    #: our MAVLink system id (None: the autopilot's own)
    source_system: int | None = None
    #: longest validity an external-data sample may claim (s)
    max_validity_s: float = DEFAULT_MAX_VALIDITY_S
    #: the queue's limits and operational envelope (None: the defaults). With the mission layer served they
    #: and ``flight_config`` only *narrow* the platform's (:func:`queue_envelope`)
    limits: Limits | None = None
    envelope: Envelope | None = None
    #: ``--flight-config``: the limits and envelope parts a file names
    flight_config: FlightConfig | None = None
    #: the queue's pause routines (None: the bundled ones; seed 000 Sec. V)
    pause_routines: PauseRoutineCatalog | None = None
    #: serve the executive layer (seed 001); False: the queue is driven through the QAPI only
    behaviors: bool = True
    #: its behavior catalog (None: the bundled one)
    behavior_catalog: BehaviorCatalog | None = None
    #: behavior and process events as JSON lines
    behavior_log: str | Path | None = None
    #: objects for the simulated downward camera
    scenario: Scenario | None = None
    #: serve the mission layer (Task Specification Trees, seed 000) on top of the executive layer
    missions: bool = True
    #: the platform for delegation (None: the bundled indoor platform)
    platform: Platform | None = None
    #: the flight log (JSON lines: setpoints, positions, commands, mission events)
    flight_log: str | Path | None = None
    #: a mission to delegate once the vehicle's home is known; ``start_mission``: start it once accepted
    mission: Mission | None = None
    start_mission: bool = False
    #: flight commands queued at start; ``run``: run the queue at start
    commands: tuple[FlightCommand, ...] = field(default=())
    run: bool = False
    #: the team link to join (seed 003), the allocation policy, the vehicle's name in the team
    team: str | None = None
    team_policy: str = "greedy"
    name: str = ""
    #: the control surface: port (0 any free; None off), host, bearer token (None: no authentication)
    control_port: int | None = 8765
    control_host: str = "127.0.0.1"
    control_token: str | None = None
    #: the safety monitor's thresholds (``enabled=False``: off, said at start); it needs the executive layer
    safety: SafetyConfig = field(default_factory=SafetyConfig)
    #: the control surface's tokens by role ``{operator: [..], mission: [..], observer: [..]}``
    #: (``--tokens FILE``; ``control_token`` is one more operator token)
    control_tokens: dict[str, list[str]] | None = None

    def __post_init__(self) -> None:
        if self.mission is not None and not self.behaviors:
            raise ValueError("--mission needs the executive layer (drop --no-behaviors)")
        if self.team and not self.behaviors:
            raise ValueError("--team needs the executive layer (drop --no-behaviors)")
        if (self.control_port is not None and not self.control_token and not self.control_tokens
                and not is_loopback(self.control_host)):
            raise ValueError(f"--control-host {self.control_host} without tokens: anyone who reaches the "
                             "port could fly the vehicle; give --tokens FILE or TASKFLIGHT_CONTROL_TOKEN, or "
                             "serve on 127.0.0.1")


class MissionRejectedError(RuntimeError):
    """The mission given at start was rejected by delegation (the reasons are logged)."""


class Companion:
    """One vehicle's companion, made by :func:`build_companion` (see module docstring)."""

    def __init__(self, config: CompanionConfig, node: QuadNode, recorder: FlightRecorder | None,
                 layer: ExecutiveLayer | None, missions: MissionService | None) -> None:
        self.config = config
        self.node = node
        self.recorder = recorder
        self.layer = layer
        self.missions = missions
        self.member: TeamMember | None = None
        self.server: ControlServer | None = None
        #: the safety monitor (the emergency requester), with the executive layer
        self.safety: SafetyMonitor | None = None
        if layer is not None:
            self.safety = SafetyMonitor(node, layer, config.safety)
            self.safety.listeners.append(self._on_safety)

    def _on_safety(self, decision: SafetyDecision) -> None:
        """The safety monitor takes the vehicle: the team member gives its task back, the mission is
        aborted with the reason (before the emergency behavior is asked for). A report (the autopilot's own
        failsafe took the vehicle, the link is lost) takes nothing: the mission's events record it (its
        behavior ends on its own if the vehicle was taken), and the team member's own tiers give the task
        back while the vehicle is overridden. A link that looks lost because this process was starved for
        a few seconds must not end a mission the autopilot is still flying."""
        reason = f"{decision.check}: {decision.reason}"
        if decision.action == "report":
            if self.missions is not None:
                self.missions.safety_report(reason)
            return
        if self.member is not None:
            self.member.safety_stop(reason)
        if self.missions is not None:
            self.missions.safety_stop(reason)

    def control_server(self, port: int | None = None, host: str | None = None,
                       token: str | None = None) -> ControlServer:
        """A control surface over this companion's parts (not started); the config's port, host and token
        unless given."""
        c = self.config
        return ControlServer(self.node, port if port is not None else (c.control_port or 0),
                             host=host if host is not None else c.control_host,
                             token=token if token is not None else c.control_token,
                             behaviors=self.layer, missions=self.missions, team=self.member,
                             safety=self.safety,
                             tokens=ControlTokens(c.control_tokens) if c.control_tokens else None)

    def start(self, stop: threading.Event | None = None) -> Companion:
        """Start the parts in order (module docstring). ``stop`` ends the waits for the vehicle (the
        mission's and the team's); :class:`MissionRejectedError` if the mission given at start is rejected."""
        c = self.config
        stop = stop or threading.Event()
        self.node.start()
        if self.layer is not None:
            self.layer.start()
        if self.safety is not None:
            self.safety.attach()
        elif c.safety.enabled:
            log.warning("safety monitor off: it needs the executive layer (--no-behaviors)")
        if self.missions is not None:
            if c.mission is not None:
                self._fly_mission(self.missions, c.mission, stop)
            if c.team:
                self.member = self._join(self.missions, c.team, stop)
        if c.commands and self.layer is not None:  # one writer of the queue: the coordinator
            result = self.layer.coordinator.fly_commands(c.commands, "operator", hold=not c.run)
            if not result.accepted:
                raise RuntimeError(f"--commands refused: {result.reason}")
            log.info("commands: %d flight commands, %s (%s)", len(c.commands),
                     "running" if c.run else "held until POST /run", result.activation_id)
        else:
            self.node.add_commands(c.commands)
            if c.run:
                self.node.run()
        if c.control_port is not None and c.control_port >= 0:
            self.server = self.control_server().start()
            log.info("companion: autopilot %s, %g Hz, control %s", c.autopilot, c.rate_hz, self.server.url)
        return self

    def close(self) -> None:
        """Close what was made, in the reverse order of the start (a part never started closes too)."""
        if self.server is not None:
            self.server.close()
        if self.member is not None:
            self.member.close()
        if self.missions is not None:
            self.missions.close()
        if self.safety is not None:
            self.safety.detach()
        if self.layer is not None:
            self.layer.close()
        self.node.close()
        if self.recorder is not None:
            self.recorder.close()

    def __enter__(self) -> Companion:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- the waits for the vehicle -------------------------------------------------------------------------
    def _fly_mission(self, missions: MissionService, mission: Mission, stop: threading.Event) -> None:
        """Delegate ``mission`` once the vehicle's home is known; start it if asked."""
        assert self.layer is not None
        while missions.node.link.mirror.snapshot().home is None or not self.layer.coordinator.is_active(
                "SELF_LOCALIZE"):
            if stop.wait(0.2):
                return
        result = missions.submit(mission)
        if not result.accepted:
            for reason in result.reasons:
                log.error("mission rejected: %s", reason)
            raise MissionRejectedError(f"mission {mission.name} rejected")
        log.info("mission %s accepted: %d nodes, %d waypoints", mission.name, len(result.plans),
                 result.waypoints)
        if self.config.start_mission:
            missions.start()

    def _join(self, missions: MissionService, url: str, stop: threading.Event) -> TeamMember | None:
        """Join the team once the autopilot is heard (the member id is its system id)."""
        link = missions.node.link
        while link.target_system is None:
            if stop.wait(0.2):
                return None
        c = self.config
        member = join_team(missions, url, link.target_system, policy=c.team_policy, name=c.name)
        log.info("team %s: member %d (%s), policy %s", url, member.id, member.name, c.team_policy)
        return member


def queue_envelope(config: CompanionConfig) -> tuple[Limits | None, Envelope | None]:
    """The limits and operational envelope the queue flies (seed 000 Sec. IV-D's P_env).

    With the mission layer served, the platform (``config.platform``, else the bundled indoor one) is their
    one source, the same envelope and limits delegation checks (:meth:`Platform.flight_envelope`,
    :meth:`Platform.flight_limits`): ``limits`` / ``envelope`` / ``flight_config`` may narrow them, and
    one that would widen them is a ``ValueError`` naming the field. Without it the queue flies ``limits``
    / ``envelope`` / ``flight_config`` as given (None: the defaults).
    """
    if not (config.behaviors and config.missions):
        if config.flight_config is not None:
            return config.flight_config.standalone()
        return config.limits, config.envelope
    platform = config.platform or bundled_platform("indoor")
    limits, envelope = platform.flight_limits(), platform.flight_envelope()
    if config.limits is not None:
        defaults = Limits()  # a field left at its default was not given
        given = {f: getattr(config.limits, f) for f in config.limits.__dataclass_fields__
                 if getattr(config.limits, f) != getattr(defaults, f)}
        limits, envelope = narrow(limits, envelope, given, source="limits")
    if config.envelope is not None:
        e = config.envelope
        limits, envelope = narrow(limits, envelope, None, e, e.altitude_floor, e.altitude_ceiling,
                                  source="envelope")
    if config.flight_config is not None:
        limits, envelope = config.flight_config.narrow(limits, envelope)
    log.info("queue envelope from platform %s: %s; %g m/s, %g m/s up/down", platform.name,
             envelope.describe(), limits.horizontal_speed, limits.vertical_speed)
    return limits, envelope


def build_companion(config: CompanionConfig) -> Companion:
    """The companion ``config`` describes, made and not started (ValueError or OSError if it cannot be).

    A team URL is opened and closed once here, so that a bad one fails before anything flies.
    """
    if config.team:
        open_transport(config.team, member=0, position_of=lambda m: None).close()
    limits, envelope = queue_envelope(config)
    node = QuadNode(config.autopilot, rate_hz=config.rate_hz, limits=limits, envelope=envelope,
                    catalog=config.pause_routines, baud=config.baud, source_system=config.source_system,
                    max_validity_s=config.max_validity_s)
    recorder = FlightRecorder(node, config.flight_log) if config.flight_log else None
    layer = missions = None
    if config.behaviors:
        layer = ExecutiveLayer.for_node(node, catalog=config.behavior_catalog, log_path=config.behavior_log,
                                        scenario=config.scenario)
        if config.missions:
            missions = MissionService(node, layer, config.platform, recorder=recorder)
    return Companion(config, node, recorder, layer, missions)
