"""The ``taskflight`` command line: one entry point, one sub-command per job.

Each sub-command imports its layer only when used, so ``taskflight --help`` is instant.
"""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Callable, Sequence

from taskflight_common.cliargs import join_signed_values
from taskflight_common.runtime import die_with_parent, setup_logging


def _cmd_autopilot(args: argparse.Namespace) -> int:
    from autopilot_model.sitl import run_autopilot

    return run_autopilot(args)


def _cmd_fleet(args: argparse.Namespace) -> int:
    from autopilot_model.fleet import run_fleet

    return run_fleet(args)


def _cmd_demo(args: argparse.Namespace) -> int:
    from taskflight.demo import run_demo

    return run_demo(args)


def _cmd_up(args: argparse.Namespace) -> int:
    from taskflight.up import run_up

    return run_up(args)


def _cmd_demo_team(args: argparse.Namespace) -> int:
    from taskflight.demo_team import run_demo_team

    return run_demo_team(args)


def _cmd_companion(args: argparse.Namespace) -> int:
    from companion.main import run_companion

    return run_companion(args)


def _cmd_companion_host(args: argparse.Namespace) -> int:
    from companion.host import run_host

    return run_host(args)


def _cmd_behaviors(args: argparse.Namespace) -> int:
    return args.behaviors_handler(args)


def _cmd_behaviors_timeline(args: argparse.Namespace) -> int:
    from companion.behaviors.timeline import TimelineError, run_timeline

    try:
        print(run_timeline(args.log, args.out, args.title))
    except (OSError, TimelineError) as exc:
        print(f"taskflight behaviors timeline: error: {exc}", file=sys.stderr)
        return 2
    return 0


def add_behaviors_arguments(parser: argparse.ArgumentParser) -> None:
    """``taskflight behaviors SUBCOMMAND``: each sub-command sets ``behaviors_handler``."""
    bsub = parser.add_subparsers(dest="behaviors_command", required=True, metavar="SUBCOMMAND")
    tp = bsub.add_parser("timeline", help="draw a flight log's behavior activations and processes (PNG)")
    tp.add_argument("log", metavar="LOG", help="the flight's JSON-lines log (coordinator, process manager)")
    tp.add_argument("--out", required=True, metavar="FILE.png", help="the PNG to write")
    tp.add_argument("--title", default=None, help="the figure's title")
    tp.set_defaults(behaviors_handler=_cmd_behaviors_timeline)


def _cmd_mission(args: argparse.Namespace) -> int:
    return args.mission_handler(args)


def _cmd_mission_check(args: argparse.Namespace) -> int:
    from taskflight.mission_check import run_mission_check

    return run_mission_check(args)


def _cmd_mission_list(args: argparse.Namespace) -> int:
    from taskflight.mission_check import bundled_missions

    print("\n".join(bundled_missions()))
    return 0


def add_mission_arguments(parser: argparse.ArgumentParser) -> None:
    """``taskflight mission SUBCOMMAND``: each sub-command sets ``mission_handler``."""
    msub = parser.add_subparsers(dest="mission_command", required=True, metavar="SUBCOMMAND")
    cp = msub.add_parser("check", help="delegate a mission file to a platform offline (exit 0 accepted, "
                                       "1 rejected, 2 bad file)")
    from taskflight.mission_check import add_check_arguments

    add_check_arguments(cp)
    cp.set_defaults(mission_handler=_cmd_mission_check)
    lp = msub.add_parser("list", help="the bundled missions (mission check takes them by name)")
    lp.set_defaults(mission_handler=_cmd_mission_list)
    from companion.mission_report.cli import add_mission_plot_arguments
    from taskflight.fig16 import add_fig16_arguments

    add_mission_plot_arguments(msub)
    add_fig16_arguments(msub)


def _cmd_team(args: argparse.Namespace) -> int:
    return args.team_handler(args)


def _cmd_team_sim(args: argparse.Namespace) -> int:
    from companion.team.sim_cli import run_sim

    return run_sim(args)


def _cmd_team_control(args: argparse.Namespace) -> int:
    from companion.team.control_cli import run_control

    return run_control(args)


def add_team_arguments(parser: argparse.ArgumentParser) -> None:
    """``taskflight team SUBCOMMAND`` (seed 003): each sub-command sets ``team_handler``."""
    tsub = parser.add_subparsers(dest="team_command", required=True, metavar="SUBCOMMAND")
    sp = tsub.add_parser("sim", help="allocation alone: kinematic vehicles and a station in one process, "
                                     "simulated time, a lossy in-memory team link")
    from companion.team.sim_cli import add_sim_arguments

    add_sim_arguments(sp)
    sp.set_defaults(team_handler=_cmd_team_sim)
    cp = tsub.add_parser("control", help="a team-control station: give the team the tasks of a file and "
                                         "print the assignment as it changes")
    from companion.team.control_cli import add_control_arguments

    add_control_arguments(cp)
    cp.set_defaults(team_handler=_cmd_team_control)


def _cmd_ground(args: argparse.Namespace) -> int:
    from groundstation.main import run_ground

    return run_ground(args)


def _cmd_router(args: argparse.Namespace) -> int:
    from taskflight.router import run_router

    return run_router(args)


def _cmd_docs(args: argparse.Namespace) -> int:
    from taskflight.apidoc import run_docs

    return run_docs(args)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="taskflight", description=__doc__.splitlines()[0])
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output (-vv: debug)")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    handlers: dict[str, Callable[[argparse.Namespace], int]] = {}

    ap = sub.add_parser("autopilot", help="run one simulated vehicle (the bundled autopilot model)")
    from autopilot_model.sitl import add_autopilot_arguments

    add_autopilot_arguments(ap)
    handlers["autopilot"] = _cmd_autopilot
    fp = sub.add_parser("fleet", help="run N simulated vehicles in one process on one clock "
                                      "(system ids 1..N, ports 5760+10i and 14550+10i)")
    from autopilot_model.fleet import add_fleet_arguments

    add_fleet_arguments(fp)
    handlers["fleet"] = _cmd_fleet

    dp = sub.add_parser("demo", help="a demonstration flight on embedded defaults (model + companion)")
    from taskflight.demo import add_demo_arguments

    add_demo_arguments(dp)
    handlers["demo"] = _cmd_demo

    dtp = sub.add_parser("demo-team", help="the team demo (scripts/demo): 3 vehicles, scan-and-search on "
                                           "vehicle 1, a visit and a patrol for the team, a report")
    from taskflight.demo_team import add_demo_team_arguments

    add_demo_team_arguments(dtp)
    handlers["demo-team"] = _cmd_demo_team

    upp = sub.add_parser("up", help="a whole simulated fleet: N models, N companions on one team link, the "
                                    "ground service (Ctrl-C stops everything)")
    from taskflight.up import add_up_arguments

    add_up_arguments(upp)
    handlers["up"] = _cmd_up

    cp = sub.add_parser("companion", help="run the companion for one vehicle")
    from companion.main import add_companion_arguments

    add_companion_arguments(cp)
    handlers["companion"] = _cmd_companion
    hp = sub.add_parser("companion-host", help="run K vehicles' companions in one process (a simulated "
                                               "fleet's; each the companion 'taskflight companion' runs)")
    from companion.host import add_host_arguments

    add_host_arguments(hp)
    handlers["companion-host"] = _cmd_companion_host

    bp = sub.add_parser("behaviors", help="the executive layer: behaviors, beliefs, processes (seed 001)")
    add_behaviors_arguments(bp)
    handlers["behaviors"] = _cmd_behaviors

    mp = sub.add_parser("mission",
                        help="Task Specification Tree missions: check, list, plot, fig16 (seed 000)")
    add_mission_arguments(mp)
    handlers["mission"] = _cmd_mission

    tp = sub.add_parser("team", help="team control: the team simulator (seed 003)")
    add_team_arguments(tp)
    handlers["team"] = _cmd_team

    gp = sub.add_parser("ground", help="the ground service: team control, process monitor, live stream "
                                       "(REST + WebSocket, SQLite)")
    from groundstation.main import add_ground_arguments

    add_ground_arguments(gp)
    handlers["ground"] = _cmd_ground

    rp = sub.add_parser("router", help="a Zenoh router for the fleet bus (--team zenoh:tcp/HOST:7447 joins "
                                       "it from other subnets or hosts; Ctrl-C stops it)")
    from taskflight.router import add_router_arguments

    add_router_arguments(rp)
    handlers["router"] = _cmd_router

    docp = sub.add_parser("docs", help="generated documentation: docs/http-api.md from the OpenAPI schemas")
    from taskflight.apidoc import add_docs_arguments

    add_docs_arguments(docp)
    handlers["docs"] = _cmd_docs

    parser.set_defaults(_handlers=handlers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(join_signed_values(argv))
    die_with_parent()  # a child of taskflight up stops when it dies
    setup_logging(args.verbose, quiet_level=logging.INFO)
    try:
        return args._handlers[args.command](args)
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
