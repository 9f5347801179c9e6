"""``taskflight ground``: the ground service.

``taskflight ground [--team URL] [--db FILE] [--host H --port P] [--tokens FILE] [--companion ID=URL ...]
[--companion-token-file FILE] [--resume-tasks] [--events-keep-days D] [--telemetry-keep S]
[--tiles FILE.mbtiles|URL]``. Without
``--tokens`` an operator and an observer token are generated and printed. The companion token (the
bearer token the service sends to the companions' control surfaces) comes from
``$TASKFLIGHT_CONTROL_TOKEN`` or ``--companion-token-file`` (its first line): never from the command line,
which every user of the machine reads in ``ps`` (``--companion-token`` is still taken, with a warning).
Restarted on a database an earlier run left, the open tasks come back held (not given to the team)
until the operator releases them, except those live vehicles are found flying; ``--resume-tasks``
releases them at start. ``--tiles FILE.mbtiles|URL``: the map's raster tiles (:mod:`groundstation.tiles`).
Imports its layers only when run (the parser is light).
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
from pathlib import Path

from taskflight_common.runtime import freeze_startup_heap
from taskflight_common.tokens import TOKEN_ENV

log = logging.getLogger(__name__)

DEFAULT_TEAM = "udp://239.255.70.1:14600"


def add_ground_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--team", default=DEFAULT_TEAM, metavar="URL",
                        help=f"the team link (default {DEFAULT_TEAM}; zenoh: on a LAN, zenoh:tcp/ROUTER:7447 "
                             "through taskflight router: the vehicles' status then comes over the bus, no "
                             "--companion needed; ?loss=F drops that fraction)")
    parser.add_argument("--team-key", default=None, metavar="FILE",
                        help="sign and check the team link with this key file (default $TASKFLIGHT_TEAM_KEY; "
                             "without one the team-control station is unauthenticated)")
    parser.add_argument("--db", default="taskflight-ground.db", metavar="FILE",
                        help="the SQLite database (created if absent; restarted on it, nothing is lost)")
    parser.add_argument("--host", default="127.0.0.1", help="bind address (default 127.0.0.1)")
    parser.add_argument("--port", type=int, default=8600, help="HTTP port (default 8600)")
    parser.add_argument("--tokens", default=None, metavar="FILE",
                        help="YAML {operator: [tokens], observer: [tokens]} (default: generated, printed)")
    parser.add_argument("--companion", action="append", default=[], metavar="ID=URL",
                        help="a vehicle's companion control URL, e.g. 1=http://127.0.0.1:8765 (repeatable)")
    parser.add_argument("--companion-token-file", default=None, metavar="FILE",
                        help=f"a file whose first line is the bearer token toward the companions (default "
                             f"${TOKEN_ENV})")
    parser.add_argument("--companion-token", default=None, metavar="TOKEN",
                        help=f"deprecated: the token is visible in ps; use ${TOKEN_ENV} or "
                             "--companion-token-file")
    parser.add_argument("--resume-tasks", action="store_true",
                        help="give the open tasks of the database's earlier run to the team at start "
                             "(default: held until the operator releases them, except those live "
                             "vehicles fly)")
    parser.add_argument("--events-keep-days", type=float, default=30.0, metavar="D",
                        help="events (alerts, history) older than D days are pruned (default 30)")
    parser.add_argument("--telemetry-keep", type=float, default=3600.0, metavar="S",
                        help="vehicle telemetry (the replay) older than S seconds is pruned (default 3600)")
    parser.add_argument("--fence", default=None, metavar="YAML",
                        help="the operational fence, 'fence: [[lat, lon], ...]': tasks outside it are "
                             "refused and the map draws it")
    parser.add_argument("--tiles", default=None, metavar="FILE|URL",
                        help="the map's raster tiles: an MBTiles file served at /tiles/{z}/{x}/{y}.png "
                             "(offline), or a tile URL template such as "
                             "https://tile.example/{z}/{x}/{y}.png; "
                             "without it the map draws a scale grid")
    parser.add_argument("--snapshot-period", type=float, default=0.1, metavar="S",
                        help="WebSocket fleet snapshot period (default 0.1 s)")


def parse_companions(items: list[str]) -> dict[int, str]:
    """``["1=http://h:p", ...]`` -> {1: "http://h:p"}; ValueError naming the bad item."""
    out: dict[int, str] = {}
    for item in items:
        vid, sep, url = item.partition("=")
        if not sep or not vid.strip().isdigit() or not 1 <= int(vid) <= 255:
            raise ValueError(f"--companion {item!r}: expected ID=URL with ID in 1..255")
        if not url.startswith(("http://", "https://")):
            raise ValueError(f"--companion {item!r}: the URL must start with http:// or https://")
        out[int(vid)] = url.rstrip("/")
    return out


def companion_token(args: argparse.Namespace) -> str | None:
    """The token toward the companions: ``--companion-token-file``, ``$TASKFLIGHT_CONTROL_TOKEN``, or the
    deprecated ``--companion-token`` (a warning). ValueError for an empty or unreadable file."""
    if args.companion_token_file:
        lines = Path(args.companion_token_file).read_text().splitlines()
        if not lines or not lines[0].strip():
            raise ValueError(f"--companion-token-file {args.companion_token_file}: empty")
        return lines[0].strip()
    if args.companion_token:
        log.warning("--companion-token puts the token on the command line (ps shows it): use $%s or "
                    "--companion-token-file", TOKEN_ENV)
        return str(args.companion_token)
    return os.environ.get(TOKEN_ENV) or None


def run_ground(args: argparse.Namespace) -> int:
    import uvicorn

    from .app import create_app
    from .auth import Tokens
    from .service import GroundService, Retention, load_fence
    from .tiles import TileSource

    try:
        companions = parse_companions(args.companion)
        tokens = Tokens.load(args.tokens) if args.tokens else Tokens.generate()
        if not 0.02 <= args.snapshot_period <= 1.0:
            raise ValueError("--snapshot-period: between 0.02 and 1 s")
        fence = load_fence(args.fence) if args.fence else None
        from companion.team.auth import team_key

        retention = Retention(events_keep_s=args.events_keep_days * 86400.0,
                              telemetry_keep_s=args.telemetry_keep)
        tiles = TileSource(args.tiles) if getattr(args, "tiles", None) else None
        service = GroundService(args.db, tokens, team_url=args.team, companions=companions,
                                companion_token=companion_token(args), fence=fence,
                                resume_tasks=args.resume_tasks, retention=retention,
                                team_key=team_key(args.team_key))
    except (ValueError, OSError) as exc:
        print(f"taskflight ground: error: {exc}", file=sys.stderr)
        return 2
    if not args.tokens:
        print("taskflight ground: generated tokens (give them with --tokens FILE next time):")
        print(tokens.to_yaml(), end="", flush=True)
    print(f"taskflight ground: http://{args.host}:{args.port}/api (OpenAPI: /docs), team {args.team}, "
          f"database {args.db}", flush=True)
    service.start()
    try:
        app = create_app(service, args.snapshot_period, tiles)
        freeze_startup_heap("ground")
        uvicorn.run(app, host=args.host, port=args.port,
                    log_level="warning", ws="websockets-sansio")
    finally:
        service.close()
    return 0
