"""``taskflight ground``: the ground service.

``taskflight ground [--team URL] [--db FILE] [--host H --port P] [--tokens FILE] [--companion ID=URL ...]
[--companion-token T] [--tiles FILE.mbtiles|URL]``. Without ``--tokens`` an operator and an observer
token are generated and printed. The companion token (``--companion-token`` or
``$TASKFLIGHT_CONTROL_TOKEN``) is the bearer token the service sends to the companions' control surfaces.
``--tiles``: the map's raster tiles (:mod:`groundstation.tiles`). Imports its layers only when run (the
parser is light).
"""

from __future__ import annotations

import argparse
import logging
import os
import sys

from taskflight_common.runtime import freeze_startup_heap
from taskflight_common.tokens import TOKEN_ENV

log = logging.getLogger(__name__)

DEFAULT_TEAM = "udp://239.255.70.1:14600"


def add_ground_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--team", default=DEFAULT_TEAM, metavar="URL",
                        help=f"the team link (default {DEFAULT_TEAM}; ?loss=F drops that fraction)")
    parser.add_argument("--db", default="taskflight-ground.db", metavar="FILE",
                        help="the SQLite database (created if absent; restarted on it, nothing is lost)")
    parser.add_argument("--host", default="127.0.0.1", help="bind address (default 127.0.0.1)")
    parser.add_argument("--port", type=int, default=8600, help="HTTP port (default 8600)")
    parser.add_argument("--tokens", default=None, metavar="FILE",
                        help="YAML {operator: [tokens], observer: [tokens]} (default: generated, printed)")
    parser.add_argument("--companion", action="append", default=[], metavar="ID=URL",
                        help="a vehicle's companion control URL, e.g. 1=http://127.0.0.1:8765 (repeatable)")
    parser.add_argument("--companion-token", default=None, metavar="TOKEN",
                        help=f"bearer token toward the companions (default ${TOKEN_ENV})")
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


def run_ground(args: argparse.Namespace) -> int:
    import uvicorn

    from .app import create_app
    from .auth import Tokens
    from .service import GroundService, load_fence
    from .tiles import TileSource

    try:
        companions = parse_companions(args.companion)
        tokens = Tokens.load(args.tokens) if args.tokens else Tokens.generate()
        if not 0.02 <= args.snapshot_period <= 1.0:
            raise ValueError("--snapshot-period: between 0.02 and 1 s")
        fence = load_fence(args.fence) if args.fence else None
        tiles = TileSource(args.tiles) if getattr(args, "tiles", None) else None
        service = GroundService(args.db, tokens, team_url=args.team, companions=companions,
                                companion_token=args.companion_token or os.environ.get(TOKEN_ENV),
                                fence=fence)
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
