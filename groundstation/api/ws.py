"""``/api/ws``: the live stream and the operator's stick.

The server sends ``{"type": "hello", "role"}``, then fleet snapshots ``{"type": "snapshot", "seq", "t",
"vehicles": [...], "tasks": [...], "stale_s", "lost_s"}`` every ``snapshot_period_s`` (default 0.1 s:
10 Hz), events ``{"type": "event", ...}`` as they happen and ``{"type": "ack", "id", "acked_by",
"acked_at"}`` when an operator acknowledges an alert. Events are queued per client; snapshots are not:
a client slower than the stream is sent the newest snapshot when it is ready for one, never a backlog
(:class:`~groundstation.service.Outbox`).
Each vehicle of a snapshot carries ``stick_lease``: null, or ``{"holder", "expires_in"}`` while an
operator holds its stick (:mod:`groundstation.stick`).

The client authenticates with ``?token=`` or a first message ``{"type": "auth", "token": "..."}``, then
may send ``{"type": "ping"}`` (answered ``pong``) and, as an operator holding the vehicle's stick lease
(``POST /api/vehicles/{vid}/stick/lease``), stick samples ``{"type": "joystick", "vehicle": 1, "lease":
"lease-...", "values": [v_north, v_east, v_down, yaw_rate], "validity_s": 0.3, "seq": 12, "t": 8123.4}``
at 10-20 Hz (seed 000 Sec. VII: the operator's break-in). ``t`` is the page's clock when the sample was
made (ms, ``performance.now()``); the service sends ``{"type": "clock", "t"}`` now and then and the page
answers ``{"type": "clock", "t": <the same>, "page_t": <its clock>}``, from which the service knows the
page's clock (:class:`groundstation.stick.ClockSync`). ``seq`` increases per page.

Each sample renews the lease and goes to the vehicle's ExtVel stream (``/external/ext_vel``, which the
joystick break-in flies on all channels) with a short validity (at most :data:`MAX_VALIDITY_S`) counted
from when it was made: only the newest sample per vehicle is forwarded, without awaiting the previous
forward (:class:`groundstation.stick.StickForwarder`), so a slow companion never makes samples queue and
a lost browser stops the vehicle instead of running it away. A malformed message, or a sample without
the vehicle's lease, is answered ``{"type": "error", "error"}`` and changes nothing.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
import socket
import time
from dataclasses import dataclass
from typing import Any

from fastapi import APIRouter, FastAPI, WebSocket, WebSocketDisconnect

from groundstation.auth import Principal
from groundstation.companions import ApiError
from groundstation.fleet import LOST_S, STALE_S
from groundstation.service import GroundService, Outbox
from groundstation.stick import ClockSync, LeaseError, StickDesk, StickSample, desk_of

log = logging.getLogger(__name__)
router = APIRouter(tags=["live"])

#: the longest validity a stick sample may ask for (s); the default
MAX_VALIDITY_S, DEFAULT_VALIDITY_S = 0.5, 0.3
#: the largest velocity (m/s) and yaw rate (deg/s) a sample may carry
MAX_SPEED, MAX_YAW_RATE = 20.0, 180.0
AUTH_TIMEOUT_S = 10.0
#: a companion refusing every sample tells the page once per this period (s), not 15 times a second
ERROR_EVERY_S = 1.0
_BACKGROUND: set[asyncio.Task[Any]] = set()
#: how often the service asks a page for its clock (s)
CLOCK_PERIOD_S = 5.0


class Client:
    """One connected socket: an outbox (events queued, the newest snapshot in one slot) drained by one
    writer task: a slow client is sent the newest snapshot, and never blocks the others."""

    def __init__(self, sock: WebSocket, who: Principal, outbox: Outbox) -> None:
        self.sock, self.who, self.out = sock, who, outbox
        self.joysticked: set[int] = set()
        self.clock = ClockSync()
        #: when this page was last told a sample was refused, per vehicle (at most every ERROR_EVERY_S)
        self.refused_at: dict[int, float] = {}
        self.seq = 0
        #: (vehicle, lease id) this socket's samples used: released when it closes
        self.leases: set[tuple[int, str]] = set()

    def put(self, item: Any) -> None:
        """A message in order (errors, pongs: queued like events)."""
        self.out.put_event(item)

    def put_snapshot(self, text: str) -> None:
        """A snapshot: replaces one not sent yet."""
        self.out.put_snapshot(text)

    async def writer(self) -> None:
        while True:
            item = await self.out.get()
            if isinstance(item, str):
                await self.sock.send_text(item)
            else:
                await self.sock.send_json(item)


def desk(app: FastAPI, svc: GroundService) -> StickDesk:
    return desk_of(app.state, svc.client)


#: the kernel's send buffer of a live-stream socket (bytes; Linux doubles it): small, so that a client slower
#: than the stream holds back the writer (and its snapshot slot is replaced) instead of megabytes of old
#: snapshots queueing in an autotuned buffer; 128 kB a 50 ms round trip still carries 2.5 MB/s (a 100-vehicle
#: snapshot at 10 Hz is 0.65 MB/s)
SEND_BUFFER = 64 * 1024


def limit_send_buffer(sock: WebSocket, size: int = SEND_BUFFER) -> bool:
    """Cap the connection's kernel send buffer (best effort: False when the server does not expose its
    transport; the outbox still replaces snapshots, only later)."""
    protocol = getattr(getattr(sock, "_receive", None), "__self__", None)
    transport = getattr(protocol, "transport", None)
    raw = transport.get_extra_info("socket") if transport is not None else None
    if raw is None:
        return False
    try:
        raw.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, size)
    except OSError:
        return False
    return True


def snapshot_message(svc: GroundService, seq: int, stick: StickDesk | None = None) -> str:
    leases = stick.leases.views() if stick is not None else {}
    vehicles = [{**v, "stick_lease": leases.get(v["id"])} for v in svc.fleet.snapshot()]
    return json.dumps({"type": "snapshot", "seq": seq, "t": time.time(), "vehicles": vehicles,
                       "tasks": svc.tasks(), "stale_s": STALE_S, "lost_s": LOST_S})


async def broadcast(app: FastAPI, svc: GroundService, period_s: float) -> None:
    """Send every client a fleet snapshot each period (built once, in a worker thread)."""
    try:
        await _broadcast(app, svc, period_s)
    finally:
        await desk(app, svc).aclose()


async def _broadcast(app: FastAPI, svc: GroundService, period_s: float) -> None:
    seq = 0
    next_t = time.monotonic()
    stick = desk(app, svc)
    while True:
        next_t += period_s
        clients: set[Client] = app.state.sockets
        if clients:
            seq += 1
            try:
                text = await asyncio.to_thread(snapshot_message, svc, seq, stick)
            except Exception:
                log.exception("snapshot failed")
            else:
                for c in list(clients):
                    c.put_snapshot(text)
        delay = next_t - time.monotonic()
        if delay < -period_s:  # fell behind (a loaded machine): do not burst
            next_t = time.monotonic()
        await asyncio.sleep(max(0.0, delay))


def _error(message: str) -> dict[str, Any]:
    return {"type": "error", "error": message}


def _parse(text: str) -> dict[str, Any]:
    try:
        msg = json.loads(text)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"malformed JSON: {exc}") from None
    if not isinstance(msg, dict) or not isinstance(msg.get("type"), str):
        raise ValueError("expected an object with a 'type' (auth, ping, joystick, clock)")
    return msg


def _number(v: Any, where: str, limit: float) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) or abs(v) > limit:
        raise ValueError(f"{where}: expected a finite number within +-{limit:g}, got {v!r}")
    return float(v)


@dataclass(frozen=True)
class JoystickMessage:
    """A parsed stick sample (module doc)."""

    vehicle: int
    values: list[float]
    validity_s: float
    lease: str | None
    seq: int | None
    t_ms: float | None


def parse_joystick(msg: dict[str, Any]) -> JoystickMessage:
    """The stick sample of ``msg``; ValueError naming the field."""
    extra = set(msg) - {"type", "vehicle", "values", "validity_s", "lease", "seq", "t"}
    if extra:
        raise ValueError(f"joystick: unknown fields {sorted(extra)}")
    vid = msg.get("vehicle")
    if isinstance(vid, bool) or not isinstance(vid, int) or not 1 <= vid <= 255:
        raise ValueError(f"vehicle: expected a vehicle id 1..255, got {vid!r}")
    values = msg.get("values")
    if not isinstance(values, list) or len(values) != 4:
        raise ValueError("values: expected [v_north, v_east, v_down, yaw_rate]")
    vals = [_number(v, f"values[{i}]", MAX_YAW_RATE if i == 3 else MAX_SPEED) for i, v in enumerate(values)]
    validity = msg.get("validity_s", DEFAULT_VALIDITY_S)
    if (isinstance(validity, bool) or not isinstance(validity, int | float)
            or not 0 < validity <= MAX_VALIDITY_S):
        raise ValueError(f"validity_s: expected 0 < validity_s <= {MAX_VALIDITY_S}, got {validity!r}")
    lease = msg.get("lease")
    if lease is not None and (not isinstance(lease, str) or not 0 < len(lease) <= 64):
        raise ValueError(f"lease: expected the lease id of POST /api/vehicles/{vid}/stick/lease, "
                         f"got {lease!r}")
    seq = msg.get("seq")
    if seq is not None and (isinstance(seq, bool) or not isinstance(seq, int) or seq < 0):
        raise ValueError(f"seq: expected an integer >= 0, got {seq!r}")
    t_ms = msg.get("t")
    if t_ms is not None:
        t_ms = _number(t_ms, "t", 1e13)
    return JoystickMessage(vid, vals, float(validity), lease, seq, t_ms)


async def _authenticate(sock: WebSocket, svc: GroundService) -> Principal | None:
    token = sock.query_params.get("token")
    if token is None:
        try:
            text = await asyncio.wait_for(sock.receive_text(), AUTH_TIMEOUT_S)
            msg = _parse(text)
        except (TimeoutError, ValueError) as exc:
            await sock.send_json(_error(f"authentication required: {exc or 'no auth message'}"))
            return None
        if msg["type"] != "auth" or not isinstance(msg.get("token"), str):
            await sock.send_json(_error("authentication required: send {\"type\": \"auth\", \"token\": ...} "
                                        "first, or connect with ?token="))
            return None
        token = msg["token"]
    who = svc.tokens.check(token)
    if who is None:
        await sock.send_json(_error("invalid token"))
    return who


async def _joystick(client: Client, stick: StickDesk, svc: GroundService, msg: dict[str, Any]) -> None:
    if not client.who.may_command:
        client.put(_error(f"forbidden: the {client.who.role} role may not send joystick samples"))
        return
    now = time.monotonic()
    j = parse_joystick(msg)
    vid = j.vehicle
    if j.lease is None:
        holder = stick.leases.view(vid)
        client.put(_error(f"vehicle {vid}: take the stick first (POST /api/vehicles/{vid}/stick/lease)"
                          + (f"; it is held by {holder['holder']}" if holder else "")) | {"vehicle": vid})
        return
    try:
        stick.leases.renew(vid, j.lease, client.who.name)
        url = svc.fleet.url_of(vid)
    except ApiError as exc:
        client.put(_error(exc.message) | {"vehicle": vid})
        return
    if not url:
        client.put(_error(f"vehicle {vid} has no control URL") | {"vehicle": vid})
        return
    client.leases.add((vid, j.lease))
    client.seq = j.seq if j.seq is not None else client.seq + 1
    made = client.clock.to_service(j.t_ms, now) if j.t_ms is not None else now

    def reply(status: int, reason: str | None) -> None:
        t = time.monotonic()
        if status != 200 and t - client.refused_at.get(vid, -math.inf) >= ERROR_EVERY_S:
            client.refused_at[vid] = t
            client.put(_error(f"vehicle {vid}: joystick sample not taken (companion answered "
                              f"{status or 'nothing'}: {reason}; is the vehicle paused with the joystick "
                              "break-in?)") | {"vehicle": vid})
        if vid not in client.joysticked:  # the first sample per vehicle is audited with its outcome
            client.joysticked.add(vid)
            task = asyncio.get_running_loop().create_task(asyncio.to_thread(
                svc.audit, client.who, "joystick", f"vehicle {vid}", {"values": j.values, "validity_s":
                                                                      j.validity_s, "lease": j.lease},
                status or 502, {"status": status, "reason": reason}))
            _BACKGROUND.add(task)  # held until done (the loop holds tasks only weakly)
            task.add_done_callback(_BACKGROUND.discard)

    stick.forwarder.submit(StickSample(vid, url, j.values, j.validity_s, made, client.seq, j.lease, reply))


def _clock_echo(client: Client, msg: dict[str, Any]) -> None:
    sent, page_t = msg.get("t"), msg.get("page_t")
    if isinstance(sent, bool) or isinstance(page_t, bool) or not isinstance(sent, int | float) \
            or not isinstance(page_t, int | float) or not math.isfinite(sent) or not math.isfinite(page_t):
        raise ValueError("clock: expected {\"type\": \"clock\", \"t\": <the service's t>, \"page_t\": ms}")
    client.clock.echo(float(sent), float(page_t), time.monotonic())


async def _ask_clock(client: Client) -> None:
    """Ask the page for its clock now and every :data:`CLOCK_PERIOD_S` (module doc)."""
    while True:
        client.put({"type": "clock", "t": time.monotonic()})
        await asyncio.sleep(CLOCK_PERIOD_S if client.clock.synced else 0.5)


@router.websocket("/ws")
async def websocket(sock: WebSocket) -> None:
    """The live stream (module docstring)."""
    svc: GroundService = sock.app.state.service
    await sock.accept()
    who = await _authenticate(sock, svc)
    if who is None:
        await sock.close(code=1008)
        return
    limit_send_buffer(sock)
    client = Client(sock, who, svc.hub.subscribe())
    await sock.send_json({"type": "hello", "role": who.role, "name": who.name})
    writer = asyncio.create_task(client.writer())
    clocker = asyncio.create_task(_ask_clock(client)) if who.may_command else None
    stick = desk(sock.app, svc)
    sock.app.state.sockets.add(client)
    try:
        while True:
            raw = await sock.receive()
            if raw["type"] == "websocket.disconnect":
                break
            text = raw.get("text")
            if text is None:
                text = (raw.get("bytes") or b"").decode("utf-8", errors="replace")
            try:
                msg = _parse(text)
                if msg["type"] == "ping":
                    client.put({"type": "pong", "t": time.time()})
                elif msg["type"] == "joystick":
                    await _joystick(client, stick, svc, msg)
                elif msg["type"] == "clock":
                    _clock_echo(client, msg)
                elif msg["type"] == "auth":
                    client.put(_error("already authenticated"))
                else:
                    raise ValueError(f"type: unknown message type {msg['type']!r} "
                                     "(auth, ping, joystick, clock)")
            except ValueError as exc:
                client.put(_error(str(exc)))
    except (WebSocketDisconnect, RuntimeError):
        pass
    finally:
        sock.app.state.sockets.discard(client)
        svc.hub.unsubscribe(client.out)
        for vid, lease_id in client.leases:  # a closed page lets go of the sticks it flew
            with contextlib.suppress(LeaseError):
                if stick.leases.release(vid, lease_id, who.name):
                    log.info("vehicle %d: stick lease %s released (its page closed)", vid, lease_id)
        for task in (writer, clocker):
            if task is not None:
                task.cancel()
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await task
