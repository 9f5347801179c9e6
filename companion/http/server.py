"""uvicorn serving the control surface (:func:`companion.http.app.create_app`) in a background thread."""

from __future__ import annotations

import ipaddress
import logging
import threading
import time

import uvicorn

from companion.behaviors.system import ExecutiveLayer
from companion.http.app import create_app
from companion.http.auth import ControlTokens
from companion.mission_service import MissionService
from companion.node import QuadNode
from companion.safety import SafetyMonitor
from companion.team.member import TeamMember
from taskflight_common.tokens import TOKEN_ENV

log = logging.getLogger(__name__)


def is_loopback(host: str) -> bool:
    """True for ``localhost`` and loopback addresses (127.0.0.0/8, ::1)."""
    if host.strip().lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


class ControlServer:
    """uvicorn serving :func:`create_app` on ``host:port`` in a background thread (port 0: any free).

    Without a token (``token``: an operator token, ``tokens``: tokens by role) it serves on a loopback
    host only (ValueError for another: anyone who reaches the port could fly the vehicle) and says at
    start that it is open."""

    def __init__(self, node: QuadNode, port: int = 8765, host: str = "127.0.0.1",
                 token: str | None = None, behaviors: ExecutiveLayer | None = None,
                 missions: MissionService | None = None, team: TeamMember | None = None,
                 tokens: ControlTokens | None = None, safety: SafetyMonitor | None = None) -> None:
        if token is None and tokens is None and not is_loopback(host):
            raise ValueError(f"control surface on {host} without tokens: anyone who reaches the port could "
                             f"fly the vehicle; give --tokens FILE or {TOKEN_ENV}, or serve on 127.0.0.1")
        self.app = create_app(node, token, behaviors, missions, team, tokens, safety=safety)
        config = uvicorn.Config(self.app, host=host, port=port, log_level="warning", lifespan="off",
                                timeout_graceful_shutdown=2)
        self.server = uvicorn.Server(config)
        self._thread = threading.Thread(target=self.server.run, name="control-http", daemon=True)
        self.host = host
        self.port = port
        self.token_required = self.app.state.tokens is not None
        if not self.token_required:
            log.warning("control surface on %s without tokens: open to every local user, each the operator "
                        "(give --tokens FILE or %s to require bearer tokens)", host, TOKEN_ENV)

    def start(self, timeout_s: float = 10.0) -> ControlServer:
        self._thread.start()
        deadline = time.monotonic() + timeout_s
        while not self.server.started:
            if not self._thread.is_alive() or time.monotonic() > deadline:
                raise RuntimeError(f"control server did not start on {self.host}:{self.port}")
            self._thread.join(0.01)
        sock = self.server.servers[0].sockets[0]
        self.port = sock.getsockname()[1]
        tokens = self.app.state.tokens
        log.info("control surface on %s port %d (%s), %s", self.host, self.port, self.url,
                 f"bearer tokens required (roles: {', '.join(tokens.roles())})" if tokens is not None
                 else "no authentication (loopback only)")
        return self

    @property
    def url(self) -> str:
        """Where a client on this machine reaches the surface (loopback for a wildcard host)."""
        host = {"0.0.0.0": "127.0.0.1", "": "127.0.0.1", "::": "::1"}.get(self.host, self.host)
        if ":" in host and not host.startswith("["):
            host = f"[{host}]"
        return f"http://{host}:{self.port}"

    def close(self) -> None:
        self.app.state.closing.set()
        self.server.should_exit = True
        if self._thread.is_alive():
            self._thread.join(timeout=5.0)
