"""The fleet bus on Zenoh: seed 003's group state (Sec. III-A) carried by a real middleware.

Seed 003 broadcasts the group state on a lossy radio and relays it by controlled flooding so that members
out of one another's range still hear each other. On an IP network a middleware does the routing: Zenoh
peers discover each other by multicast scouting on a LAN and a Zenoh router (``taskflight router``) joins
vehicles on other subnets. So over Zenoh **no controlled flooding is needed**: every member's packets reach
every other member through the peers and routers; the team link still relays what it knows (the
application protocol is unchanged), which only adds redundancy.

The payloads are the very packets of :mod:`companion.team.wire` that the UDP transport carries, so whatever
the codec adds (epochs, signatures) applies to both transports. Key expressions:

* ``taskflight/<team>/group/<member>``: a member's group-state packets (:class:`ZenohTransport`);
* ``taskflight/<team>/vehicle/<id>/status``: a companion's status, mission and control URL as JSON, a few
  times a second (:mod:`companion.team.presence`); ``.../events``: its events (detections).

URLs (:func:`parse_zenoh_url`): ``zenoh:`` (peer mode, multicast scouting: a LAN with no configuration),
``zenoh:tcp/HOST:PORT`` (a client of the router at HOST:PORT, for vehicles on other subnets; several
endpoints separated by commas), with options ``team=NAME`` (the key-expression prefix, default
``default``: two teams on one network keep apart by name) and ``mode=peer|client``.
"""

from __future__ import annotations

import collections
import json
import logging
import re
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any
from urllib.parse import parse_qsl, urlsplit

from companion.team.transport import Transport

log = logging.getLogger(__name__)

DEFAULT_TEAM = "default"
DEFAULT_ROUTER_PORT = 7447
#: options of a ``zenoh:`` URL (``loss``, ``seed``, ``range`` are :func:`open_transport`'s)
ZENOH_OPTIONS = frozenset({"team", "mode"})
_NAME = re.compile(r"^[A-Za-z0-9_.\-]+$")
_ENDPOINT = re.compile(r"^(tcp|udp|tls|quic|ws)/[^/,]+:\d+$")
#: received packets kept at most before the oldest are dropped (a member that does not read)
MAX_QUEUE = 10000


def is_zenoh_url(url: str | None) -> bool:
    return bool(url) and url.strip().lower().startswith("zenoh:")  # type: ignore[union-attr]


@dataclass(frozen=True)
class ZenohSpec:
    """What a ``zenoh:`` URL names: the mode, the endpoints to connect to, the team's name."""

    mode: str
    connect: tuple[str, ...]
    team: str

    @property
    def url(self) -> str:
        ends = ",".join(self.connect)
        default_mode = "client" if self.connect else "peer"
        opts = [f"team={self.team}"] if self.team != DEFAULT_TEAM else []
        if self.mode != default_mode:
            opts.append(f"mode={self.mode}")
        return f"zenoh:{ends}" + ("?" + "&".join(opts) if opts else "")


def parse_zenoh_url(url: str, extra_options: frozenset[str] = frozenset()) -> ZenohSpec:
    """The :class:`ZenohSpec` of ``url`` (module doc); ValueError naming the bad part."""
    u = urlsplit(url.strip())
    if u.scheme.lower() != "zenoh":
        raise ValueError(f"team URL {url!r}: not a zenoh: URL")
    opts: dict[str, str] = {}
    for k, v in parse_qsl(u.query, keep_blank_values=True):
        if k not in ZENOH_OPTIONS | extra_options:
            raise ValueError(f"team URL {url!r}: unknown option {k!r} "
                             f"(known: {', '.join(sorted(ZENOH_OPTIONS | extra_options))})")
        opts[k] = v
    where = (u.netloc + u.path).strip("/")
    connect = tuple(e.strip() for e in where.split(",") if e.strip()) if where else ()
    for e in connect:
        if not _ENDPOINT.match(e):
            raise ValueError(f"team URL {url!r}: endpoint {e!r} is not PROTO/HOST:PORT "
                             f"(e.g. zenoh:tcp/192.168.1.10:{DEFAULT_ROUTER_PORT})")
    team = opts.get("team", DEFAULT_TEAM)
    if not _NAME.match(team):
        raise ValueError(f"team URL {url!r}: option team={team!r}: letters, digits, '_', '-', '.' only")
    mode = opts.get("mode", "client" if connect else "peer")
    if mode not in ("peer", "client"):
        raise ValueError(f"team URL {url!r}: option mode={mode!r}: peer or client")
    if mode == "client" and not connect:
        raise ValueError(f"team URL {url!r}: mode=client needs a router (zenoh:tcp/HOST:PORT)")
    return ZenohSpec(mode, connect, team)


def zenoh_config(mode: str, connect: tuple[str, ...] = (), listen: tuple[str, ...] | None = None) -> Any:
    """A ``zenoh.Config`` in ``mode`` (peer, client or router) connecting to / listening on endpoints."""
    import zenoh

    cfg = zenoh.Config()
    cfg.insert_json5("mode", json.dumps(mode))
    if connect:
        cfg.insert_json5("connect/endpoints", json.dumps(list(connect)))
    if listen is not None:
        cfg.insert_json5("listen/endpoints", json.dumps(list(listen)))
    return cfg


class ZenohBus:
    """One Zenoh session on a team's key space (``taskflight/<team>/...``): what the group transport, the
    companion's presence publisher and the ground service's subscription share."""

    def __init__(self, spec: ZenohSpec) -> None:
        import zenoh

        self.spec = spec
        self.prefix = f"taskflight/{spec.team}"
        try:
            self.session = zenoh.open(zenoh_config(spec.mode, spec.connect))
        except zenoh.ZError as exc:
            raise OSError(f"zenoh {spec.url}: cannot open a session: {exc}") from exc
        self._closed = False
        self._lock = threading.Lock()
        where = ", ".join(spec.connect) if spec.connect else "multicast scouting on the LAN"
        log.info("fleet bus %s: %s mode, %s, keys %s/...", spec.url, spec.mode, where, self.prefix)

    @classmethod
    def open(cls, url: str) -> ZenohBus:
        return cls(parse_zenoh_url(url))

    def key(self, *parts: object) -> str:
        return "/".join([self.prefix, *map(str, parts)])

    def subscribe(self, key: str, fn: Callable[[str, bytes], None]) -> Any:
        """Call ``fn(key, payload)`` for every sample on ``key`` (a key expression; exceptions logged)."""
        def on_sample(sample: Any) -> None:
            try:
                fn(str(sample.key_expr), sample.payload.to_bytes())
            except Exception:
                log.exception("fleet bus: handler of %s failed", key)
        return self.session.declare_subscriber(key, on_sample)

    def publisher(self, key: str) -> Any:
        return self.session.declare_publisher(key)

    @property
    def closed(self) -> bool:
        return self._closed

    def close(self) -> None:
        with self._lock:
            if self._closed:
                return
            self._closed = True
        try:
            self.session.close()
        except Exception as exc:  # closing twice or during interpreter shutdown
            log.debug("fleet bus close: %s", exc)


class ZenohTransport(Transport):
    """Seed 003's team-link packets as Zenoh publications on ``taskflight/<team>/group/<member>``; every
    member subscribes to ``taskflight/<team>/group/*`` (its own packets come back too: the link drops them
    by sender id, as with UDP multicast). No controlled flooding is needed: Zenoh routes (module doc)."""

    def __init__(self, bus: ZenohBus, member: int | None = None) -> None:
        self.bus = bus
        self.member = member
        self._queue: collections.deque[bytes] = collections.deque(maxlen=MAX_QUEUE)
        self._cond = threading.Condition()
        self._closed = False
        self._pubs: dict[str, Any] = {}
        self._sub = bus.subscribe(bus.key("group", "*"), self._put)

    @property
    def url(self) -> str:
        return self.bus.spec.url

    def _put(self, _key: str, data: bytes) -> None:
        with self._cond:
            self._queue.append(data)
            self._cond.notify()

    def _key_for(self, data: bytes) -> str:
        from companion.team.transport import _sender_of

        who = self.member if self.member is not None else _sender_of(data)
        return self.bus.key("group", who if who is not None else "unknown")

    def send(self, data: bytes) -> None:
        if self._closed:
            raise OSError("ZenohTransport closed")
        key = self._key_for(data)
        pub = self._pubs.get(key)
        if pub is None:
            pub = self._pubs[key] = self.bus.publisher(key)
        try:
            pub.put(bytes(data))
        except Exception as exc:  # zenoh.ZError: the session is gone
            raise OSError(f"zenoh put on {key}: {exc}") from exc

    def recv(self, timeout_s: float) -> bytes | None:
        with self._cond:
            if not self._queue and timeout_s > 0 and not self._closed:
                self._cond.wait(timeout_s)
            return self._queue.popleft() if self._queue else None

    def close(self) -> None:
        with self._cond:
            if self._closed:
                return
            self._closed = True
            self._queue.clear()
            self._cond.notify_all()
        self.bus.close()


def zenoh_bus_of(transport: Transport) -> ZenohBus | None:
    """The Zenoh bus under ``transport`` (through wrappers such as the lossy one), None if not on Zenoh."""
    t: Any = transport
    for _ in range(5):
        if isinstance(t, ZenohTransport):
            return t.bus
        t = getattr(t, "inner", None)
        if t is None:
            return None
    return None
