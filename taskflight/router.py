"""``taskflight router [--listen tcp/0.0.0.0:7447]``: a Zenoh router for the fleet bus, until Ctrl-C.

Vehicles and ground services on other subnets or hosts join one team through it with
``--team zenoh:tcp/ROUTER_HOST:7447`` (:mod:`companion.team.zenoh_transport`); on one LAN ``zenoh:`` needs
no router (multicast scouting). The router routes every key of every team (``taskflight/<team>/...``).
"""

from __future__ import annotations

import argparse
import logging
import re
import sys

from taskflight_common.runtime import stop_on_signals

log = logging.getLogger(__name__)

DEFAULT_LISTEN = "tcp/0.0.0.0:7447"
_ENDPOINT = re.compile(r"^(tcp|udp|tls|quic|ws)/[^/,]+:\d+$")


def add_router_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--listen", action="append", default=None, metavar="ENDPOINT",
                        help=f"where the router listens (default {DEFAULT_LISTEN}; repeatable)")


def run_router(args: argparse.Namespace) -> int:
    import zenoh

    from companion.team.zenoh_transport import zenoh_config

    listen = tuple(args.listen or [DEFAULT_LISTEN])
    for e in listen:
        if not _ENDPOINT.match(e):
            print(f"taskflight router: error: --listen {e!r}: expected PROTO/HOST:PORT, e.g. "
                  f"{DEFAULT_LISTEN}",
                  file=sys.stderr)
            return 2
    stop = stop_on_signals()
    try:
        session = zenoh.open(zenoh_config("router", listen=listen))
    except zenoh.ZError as exc:
        print(f"taskflight router: error: cannot listen on {', '.join(listen)}: {exc}", file=sys.stderr)
        return 2
    try:
        print(f"taskflight router: listening on {', '.join(listen)} (zenoh id {session.info.zid()}); members "
              f"join with --team zenoh:{listen[0].replace('0.0.0.0', 'HOST')}", flush=True)
        while not stop.wait(1.0):
            pass
    finally:
        session.close()
    print("taskflight router: stopped", flush=True)
    return 0
