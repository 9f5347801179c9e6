"""``taskflight up``'s command-line options (:func:`add_up_arguments`) and the defaults they name; the
fleet itself is :mod:`taskflight.up`."""

from __future__ import annotations

import argparse
import os

from mission_specs import bundled

PLATFORM = bundled("platform_outdoor.yaml")
TEAM_GROUP = "239.255.70.1"
DEFAULT_GROUND_PORT = 8700
AUTOPILOTS = ("model", "arducopter")


def add_up_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``taskflight up``."""
    p.add_argument("--vehicles", "-n", type=int, required=True, help="number of vehicles N")
    p.add_argument("--autopilot", choices=AUTOPILOTS, default="model",
                   help="model (default): the bundled autopilot models, all in one process; arducopter: "
                        "ArduPilot's own copter SITL, one process per vehicle ($TASKFLIGHT_ARDUCOPTER names "
                        "the binary, $TASKFLIGHT_ARDUCOPTER_DEFAULTS the parameter file, default "
                        "../shared/ardupilot/copter.parm); READY once every vehicle's EKF uses GPS (ready "
                        "to arm), ~42 simulated s; a ground station connects to TCP 5760+10(I+i) alike "
                        "(SITL listens on every interface); each SITL starts from copter.parm (-w)")
    p.add_argument("--speedup", type=float, default=1.0,
                   help="simulated seconds per wall second (default 1: real time; 0: as fast as possible)")
    p.add_argument("--base-instance", "-I", type=int, default=0,
                   help="instance of vehicle 0 (default 0): vehicle i serves MAVLink on TCP 5760+10(I+i) "
                        "and UDP 14550+10(I+i); its system id stays K+i (--first-sysid)")
    p.add_argument("--ground-port", type=int, default=DEFAULT_GROUND_PORT,
                   help=f"the ground service's HTTP port (default {DEFAULT_GROUND_PORT})")
    p.add_argument("--host", default="127.0.0.1", help="the ground service's bind address (default loopback)")
    p.add_argument("--mavlink-host", default="127.0.0.1",
                   help="bind address of the models' MAVLink ports (default loopback; 0.0.0.0 for a LAN; "
                        "ArduCopter SITL: always every interface)")
    p.add_argument("--control-host", default="127.0.0.1", metavar="HOST",
                   help="bind address of the companions' control surfaces (default loopback; 0.0.0.0 for a "
                        "ground service on another host: on a zenoh: team it finds them through the bus; "
                        "the control token is $TASKFLIGHT_CONTROL_TOKEN when set, else a new one)")
    p.add_argument("--tokens", default=None, metavar="FILE",
                   help="YAML {operator: [..], observer: [..]} (default: generate one of each, written to "
                        "<state-dir>/tokens.yaml, mode 0600)")
    p.add_argument("--team", default=None, metavar="URL",
                   help=f"the team link (default udp://{TEAM_GROUP}:<a free port>; zenoh: on a LAN, "
                        "zenoh:tcp/ROUTER:7447 through taskflight router)")
    p.add_argument("--team-key", default=None, metavar="FILE",
                   help="sign the team link with this key file (default $TASKFLIGHT_TEAM_KEY, else one "
                        "generated in <state-dir>/team.key, mode 0600)")
    p.add_argument("--first-sysid", type=int, default=1, metavar="K",
                   help="MAVLink system id (and team member id) of vehicle 0 (default 1): vehicles K, K+1, "
                        "...; give each host its own block when several start vehicles for one team")
    p.add_argument("--team-loss", type=float, default=0.0, metavar="F",
                   help="drop this fraction of team-link packets at every member (a test of loss)")
    p.add_argument("--state-dir", default=None, metavar="DIR",
                   help="logs, tokens, model parameters, the ground database (default "
                        "$TASKFLIGHT_STATE/up or ~/.taskflight/up)")
    p.add_argument("--platform", default=str(PLATFORM), metavar="YAML",
                   help="the companions' platform for delegation (default: the outdoor one)")
    p.add_argument("--scenario", default=None, metavar="YAML",
                   help="objects for every vehicle's simulated downward camera (north, east of its own home; "
                        "companion.sensing.scenario): detections reach the ground service as events")
    p.add_argument("--tiles", default=None, metavar="FILE|URL",
                   help="the map's tiles for the ground service (an MBTiles file or a URL template; "
                        "default: an offline tile set of the platform's home area, drawn into "
                        "<state-dir>/tiles.mbtiles)")
    p.add_argument("--no-ground", action="store_true", help="everything but the ground service")
    p.add_argument("--no-persist", action="store_true", help="the models neither load nor save parameters")
    p.add_argument("--companion-nice", type=int, default=0, metavar="K",
                   help="run the companions at niceness K (0..19), so that the models' one process keeps "
                        "its clock when many companions load the machine (default 0)")
    p.add_argument("--companions-per-process", type=int, default=None, metavar="K",
                   help="run K vehicles' companions in one process (taskflight companion-host; 1: one "
                        "'taskflight companion' process each, as on a real vehicle; default: the vehicles "
                        f"spread over as many processes as the machine has cores, {os.cpu_count()} here)")
    p.add_argument("--resume-tasks", action="store_true",
                   help="the open tasks an earlier run left in <state-dir>/ground.db are given to the new "
                        "vehicles at start (default: shown held until the operator releases them)")
    p.add_argument("--ready-timeout", type=float, default=None, metavar="S",
                   help="give up starting after S seconds (default 60 + 3 N)")
