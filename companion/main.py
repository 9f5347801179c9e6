"""``taskflight companion``: one vehicle's companion (seed 000 Fig. 10, the QuadNode) from the command line.

``taskflight companion --autopilot URL [--rate HZ] [--control-port P]`` connects to the autopilot
(``udpout:127.0.0.1:14550`` for the bundled model or ArduPilot SITL, ``serial:/dev/ttyACM0:921600``
for a flight controller), streams setpoints at ``--rate`` Hz of autopilot time and serves the QAPI
over HTTP on ``--control-host`` (default ``127.0.0.1``) port P (see :mod:`companion.http`).
``--control-token`` (default: the environment variable ``TASKFLIGHT_CONTROL_TOKEN``, which other
users cannot read from the process list) makes every endpoint require ``Authorization: Bearer
<token>`` (the operator's); ``--tokens FILE`` (YAML ``{operator: [..], mission: [..], observer: [..]}``)
gives the tokens by role, each role the requester its holders act as (:mod:`companion.http.auth`).
Without any token the surface is open, says so, and serves on loopback only (another host is refused).
``--max-validity S`` caps the validity of external-data samples. ``--commands FILE`` queues a YAML list
of flight commands at start (with the executive layer on: the operator's FLY_COMMANDS behavior); ``--run``
starts executing them. ``--safety FILE`` sets the safety monitor's thresholds
(:mod:`companion.safety`); ``--no-safety-monitor`` turns it off, and the companion says so at start.
``--team URL`` joins a team (seed 003;
:mod:`companion.team.join`): the vehicle shares its state on the team link and flies the team tasks the
allocation gives it.

The options become a :class:`~companion.builder.CompanionConfig` (:func:`config_from_args`: every file is
read and checked here, a bad one exits with status 2) and :func:`~companion.builder.build_companion` makes
the companion, as for every other user of a companion.
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import os
from typing import TYPE_CHECKING, Any

from taskflight_common.runtime import freeze_startup_heap, stop_on_signals
from taskflight_common.tokens import COMPANION_ROLES, TOKEN_ENV, load_tokens
from taskflight_common.yamlio import ConfigError

if TYPE_CHECKING:
    from companion.builder import CompanionConfig

log = logging.getLogger(__name__)


def add_companion_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``taskflight companion``."""
    parser.add_argument("--autopilot", required=True, metavar="URL",
                        help="udpin:HOST:PORT, udpout:HOST:PORT, tcp:HOST:PORT or serial:DEVICE[:BAUD]")
    parser.add_argument("--rate", type=float, default=20.0, metavar="HZ",
                        help="setpoint stream rate in Hz of autopilot time (1..50, default 20)")
    parser.add_argument("--control-port", type=int, default=8765, metavar="P",
                        help="HTTP control surface on port P (default 8765; 0 any free port, -1 off)")
    parser.add_argument("--control-host", default="127.0.0.1", metavar="HOST",
                        help="address the control surface binds to (default 127.0.0.1; 0.0.0.0 all)")
    parser.add_argument("--control-token", default=None, metavar="TOKEN",
                        help="require 'Authorization: Bearer TOKEN' on the control surface (default: "
                             f"${TOKEN_ENV} if set, else no authentication)")
    parser.add_argument("--tokens", default=None, metavar="FILE",
                        help="control-surface tokens by role, YAML {operator: [..], mission: [..], observer: "
                             "[..]}: each role is the requester its holders act as; observers only read")
    # default None, resolved in config_from_args: building the parser stays free of the companion's imports
    parser.add_argument("--max-validity", type=float, default=None, metavar="S",
                        help="longest validity (s) an external-data sample may claim (default: "
                             "companion.flight.external.DEFAULT_MAX_VALIDITY_S)")
    parser.add_argument("--baud", type=int, default=57600, help="serial baud rate (default 57600)")
    parser.add_argument("--source-system", type=int, default=None,
                        help="our MAVLink system id (default: the autopilot's own)")
    parser.add_argument("--flight-config", default=None, metavar="YAML",
                        help="limits and operational envelope (companion.flight.limits); with the "
                             "mission layer it may only narrow the platform's (a wider field is refused)")
    parser.add_argument("--pause-routines", default=None, metavar="YAML",
                        help="extra pause routines of the queue (seed 000 Sec. V)")
    parser.add_argument("--behavior-catalog", default=None, metavar="YAML",
                        help="the executive layer's behavior catalog (seed 001; default "
                             "mission_specs/behavior_catalog.yaml)")
    parser.add_argument("--no-behaviors", action="store_true",
                        help="no executive layer: the queue is driven through the QAPI only")
    parser.add_argument("--behavior-log", default=None, metavar="FILE",
                        help="append behavior and process events as JSON lines (for 'taskflight behaviors "
                             "timeline')")
    parser.add_argument("--flight-log", default=None, metavar="FILE",
                        help="write the flight log (JSON lines: setpoints, measured positions, commands, "
                             "mission events; for 'taskflight mission plot')")
    parser.add_argument("--platform", default=None, metavar="YAML",
                        help="the platform for delegation (default mission_specs/platform_indoor.yaml)")
    parser.add_argument("--scenario", default=None, metavar="YAML",
                        help="objects for the simulated downward camera (companion.sensing.scenario)")
    parser.add_argument("--mission", default=None, metavar="YAML",
                        help="a Task Specification Tree to delegate once the vehicle is heard (seed 000)")
    parser.add_argument("--start", action="store_true", help="with --mission: start it once accepted")
    parser.add_argument("--team", default=None, metavar="URL",
                        help="join a team on this team link (seed 003): zenoh: (peer mode, a LAN), "
                             "zenoh:tcp/ROUTER:7447 (through taskflight router), udp://239.255.70.1:14650"
                             "[?iface=ADDR] (raw multicast, for a radio), bcast://255.255.255.255:14650; "
                             "options ?loss=F&seed=S&range=M, zenoh: ?team=NAME")
    parser.add_argument("--team-key", default=None, metavar="FILE",
                        help="sign and check every team-link packet with this key file (default "
                             "$TASKFLIGHT_TEAM_KEY; without one the link is unauthenticated)")
    parser.add_argument("--team-id", type=int, default=None, metavar="N",
                        help="the member id in the team, unique in it (1..4294967295; default the "
                             "autopilot's MAVLink system id)")
    parser.add_argument("--team-policy", default="greedy", choices=("greedy", "cbba"),
                        help="task allocation policy (default greedy, seed 003 Sec. III-B)")
    parser.add_argument("--name", default="", help="the vehicle's name in the team (default uav<sysid>)")
    parser.add_argument("--safety", default=None, metavar="YAML",
                        help="the safety monitor's thresholds and actions (companion.safety.config; default: "
                             "its defaults)")
    parser.add_argument("--no-safety-monitor", action="store_true",
                        help="no safety monitor (the emergency requester): only the autopilot's own "
                             "failsafes act on a low battery, a bad estimate, a fence ahead (said at start)")
    parser.add_argument("--commands", default=None, metavar="YAML", help="flight commands to queue at start")
    parser.add_argument("--run", action="store_true", help="run the queue at start")


def control_token(args: argparse.Namespace) -> str | None:
    """``--control-token``, else ``$TASKFLIGHT_CONTROL_TOKEN``; None (no authentication) if neither is set."""
    token = args.control_token if args.control_token is not None else os.environ.get(TOKEN_ENV)
    return token if token and token.strip() else None


def control_tokens(args: argparse.Namespace) -> dict[str, list[str]] | None:
    """``--tokens FILE`` checked (the companion's roles, :data:`~taskflight_common.tokens.COMPANION_ROLES`;
    :class:`ConfigError` naming the file, line and role); None without the option."""
    path = getattr(args, "tokens", None)
    if not path:
        return None
    return load_tokens(path, COMPANION_ROLES, "a companion's control surface", need_operator=False)


def config_from_args(args: argparse.Namespace) -> CompanionConfig:
    """The companion ``taskflight companion``'s options describe, every file read and checked
    (:class:`ConfigError`, ValueError or OSError naming what is wrong)."""
    # imported here, not at the top: every ``taskflight`` command builds this module's parser, and the
    # companion's stack (pymavlink, FastAPI, scipy) takes seconds to import
    from companion.behaviors.catalog import load_catalog as load_behavior_catalog
    from companion.builder import CompanionConfig
    from companion.flight import load_catalog, load_commands
    from companion.flight.external import DEFAULT_MAX_VALIDITY_S
    from companion.flight.limits import load_flight_config_fields
    from companion.safety import SafetyConfig, load_safety_config
    from companion.sensing.scenario import Scenario
    from companion.team.auth import team_key
    from companion.tst.platform import load_platform
    from companion.tst.spec import load_mission

    safety = load_safety_config(args.safety) if args.safety else SafetyConfig()
    if args.no_safety_monitor:
        safety = dataclasses.replace(safety, enabled=False)
    return CompanionConfig(
        autopilot=args.autopilot, rate_hz=args.rate, baud=args.baud, source_system=args.source_system,
        max_validity_s=DEFAULT_MAX_VALIDITY_S if args.max_validity is None else args.max_validity,
        flight_config=load_flight_config_fields(args.flight_config) if args.flight_config else None,
        pause_routines=load_catalog(args.pause_routines) if args.pause_routines else None,
        commands=tuple(load_commands(args.commands)) if args.commands else (),
        behaviors=not args.no_behaviors,
        behavior_catalog=None if args.no_behaviors else load_behavior_catalog(
            *([args.behavior_catalog] if args.behavior_catalog else [])),
        behavior_log=args.behavior_log,
        platform=load_platform(args.platform) if args.platform else None,
        scenario=Scenario.load(args.scenario) if args.scenario else None,
        mission=load_mission(args.mission) if args.mission else None, start_mission=args.start,
        team=args.team, team_policy=args.team_policy, name=args.name,
        team_key=team_key(args.team_key) if args.team else None, team_id=args.team_id,
        flight_log=args.flight_log, run=args.run,
        control_port=args.control_port if args.control_port >= 0 else None,
        control_host=args.control_host, control_token=control_token(args),
        control_tokens=control_tokens(args), safety=safety)


def run_companion(args: argparse.Namespace) -> int:
    """Run until SIGINT/SIGTERM; returns the exit status (2 for bad options or files)."""
    from companion.builder import build_companion  # start-up cost: see config_from_args

    try:
        companion = build_companion(config_from_args(args))
    except (ConfigError, ValueError, OSError) as exc:
        log.error("%s", exc)
        return 2
    return serve(companion, "companion")


def serve(runner: Any, label: str) -> int:
    """Start ``runner`` (a companion, or a host of them), run until SIGINT/SIGTERM, close it; the exit
    status: 0, or 1 when it could not start (a mission rejected at start, a port taken...)."""
    from companion.builder import MissionRejectedError

    stop = stop_on_signals()
    try:
        runner.start(stop)
        freeze_startup_heap(label)
        while not stop.wait(0.5):
            pass
    except MissionRejectedError:
        return 1
    except (OSError, RuntimeError) as exc:
        log.error("%s", exc)
        return 1
    finally:
        runner.close()
    return 0
