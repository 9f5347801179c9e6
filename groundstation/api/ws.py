"""``/api/ws``: the live stream and the operator's stick.

The server sends ``{"type": "hello", "role"}``, then fleet snapshots ``{"type": "snapshot", "seq", "t",
"vehicles": [...], "tasks": [...], "stale_s", "lost_s"}`` every ``snapshot_period_s`` (default 0.1 s:
10 Hz), events ``{"type": "event", ...}`` as they happen and ``{"type": "ack", "id", "acked_by",
"acked_at"}`` when an operator acknowledges an alert. Events are queued per client; snapshots are not:
a client slower than the stream is sent the newest snapshot when it is ready for one, never a backlog
(:class:`~groundstation.service.Outbox`).

The client authenticates with ``?token=`` or a first message ``{"type": "auth", "token": "..."}``, then
may send ``{"type": "ping"}`` (answered ``pong``) and, as an operator, stick samples ``{"type":
"joystick", "vehicle": 1, "values": [v_north, v_east, v_down, yaw_rate], "validity_s": 0.3}`` at 10-20 Hz
(seed 000 Sec. VII: the operator's break-in). Each is forwarded to the vehicle's ExtVel stream
(``/external/ext_vel``, which the joystick break-in flies on all channels) with a short validity (at
most :data:`MAX_VALIDITY_S`), so a lost browser stops
the vehicle instead of running it away. A malformed message is answered ``{"type": "error", "error"}``
and changes nothing.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
import socket
import time
from typing import Any

from fastapi import APIRouter, FastAPI, WebSocket, WebSocketDisconnect

from groundstation.auth import Principal
from groundstation.companions import ApiError
from groundstation.fleet import LOST_S, STALE_S
from groundstation.service import GroundService, Outbox

log = logging.getLogger(__name__)
router = APIRouter(tags=["live"])

#: the longest validity a stick sample may ask for (s); the default
MAX_VALIDITY_S, DEFAULT_VALIDITY_S = 0.5, 0.3
#: the largest velocity (m/s) and yaw rate (deg/s) a sample may carry
MAX_SPEED, MAX_YAW_RATE = 20.0, 180.0
AUTH_TIMEOUT_S = 10.0


class Client:
    """One connected socket: an outbox (events queued, the newest snapshot in one slot) drained by one
    writer task: a slow client is sent the newest snapshot, and never blocks the others."""

    def __init__(self, sock: WebSocket, who: Principal, outbox: Outbox) -> None:
        self.sock, self.who, self.out = sock, who, outbox
        self.joysticked: set[int] = set()

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


def snapshot_message(svc: GroundService, seq: int) -> str:
    return json.dumps({"type": "snapshot", "seq": seq, "t": time.time(), "vehicles": svc.fleet.snapshot(),
                       "tasks": svc.tasks(), "stale_s": STALE_S, "lost_s": LOST_S})


async def broadcast(app: FastAPI, svc: GroundService, period_s: float) -> None:
    """Send every client a fleet snapshot each period (built once, in a worker thread)."""
    seq = 0
    next_t = time.monotonic()
    while True:
        next_t += period_s
        clients: set[Client] = app.state.sockets
        if clients:
            seq += 1
            try:
                text = await asyncio.to_thread(snapshot_message, svc, seq)
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
        raise ValueError("expected an object with a 'type' (auth, ping, joystick)")
    return msg


def _number(v: Any, where: str, limit: float) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) or abs(v) > limit:
        raise ValueError(f"{where}: expected a finite number within +-{limit:g}, got {v!r}")
    return float(v)


def parse_joystick(msg: dict[str, Any]) -> tuple[int, list[float], float]:
    """(vehicle, values, validity) of a stick sample; ValueError naming the field."""
    extra = set(msg) - {"type", "vehicle", "values", "validity_s"}
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
    return vid, vals, float(validity)


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


async def _joystick(client: Client, svc: GroundService, msg: dict[str, Any]) -> None:
    if not client.who.may_command:
        client.put(_error(f"forbidden: the {client.who.role} role may not send joystick samples"))
        return
    vid, values, validity = parse_joystick(msg)
    try:
        url = svc.fleet.url_of(vid)
    except ApiError as exc:
        client.put(_error(exc.message))
        return
    if not url:
        client.put(_error(f"vehicle {vid} has no control URL"))
        return
    sample = {"values": values, "validity_s": validity}
    status = await svc.client.post_async(url, "/external/ext_vel", sample, timeout_s=1.0)
    if vid not in client.joysticked:
        client.joysticked.add(vid)
        await asyncio.to_thread(svc.audit, client.who, "joystick", f"vehicle {vid}",
                                {"values": values, "validity_s": validity}, status or 502, {"status": status})
    if status != 200:
        client.put(_error(f"vehicle {vid}: joystick sample not taken (companion answered "
                          f"{status or 'nothing'}; is the vehicle paused with the joystick break-in?)")
                   | {"vehicle": vid})


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
                    await _joystick(client, svc, msg)
                elif msg["type"] == "auth":
                    client.put(_error("already authenticated"))
                else:
                    raise ValueError(f"type: unknown message type {msg['type']!r} (auth, ping, joystick)")
            except ValueError as exc:
                client.put(_error(str(exc)))
    except (WebSocketDisconnect, RuntimeError):
        pass
    finally:
        sock.app.state.sockets.discard(client)
        svc.hub.unsubscribe(client.out)
        writer.cancel()
        with contextlib.suppress(asyncio.CancelledError, Exception):
            await writer
