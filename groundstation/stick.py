"""The operator's stick on the ground service: who holds it, when a sample was made, and forwarding only
the newest one (seed 000 Sec. VII, the operator's break-in; Sec. IV-C, a stream's validity).

* :class:`StickLeases`: one operator holds a vehicle's stick at a time. A lease is taken explicitly
  (``POST /api/vehicles/{vid}/stick/lease``), renewed by the holder's samples or a keepalive (the same
  POST with the lease id), released (``DELETE``) or expired :data:`LEASE_TTL_S` after the last renewal.
  Every page sees it in the snapshot (``stick_lease: {holder, expires_in}``); only the holder's samples
  are forwarded.
* :class:`ClockSync`: the page stamps each sample with its own clock (``performance.now()``, ms); the
  service estimates the page's offset from ``clock`` exchanges on the WebSocket (the service sends its
  time, the page echoes it with its own: offset = sent + rtt / 2 - page time, from the exchange with the
  shortest round trip), or, until one has come back, from the smallest lag seen (receive - stamp). A
  sample's age is then measured from the operator's hand, not from its arrival.
* :class:`StickForwarder`: per vehicle a latest-sample slot and a sender task. A new sample replaces the
  one waiting; the sender forwards the newest without awaiting the previous forward (up to
  :data:`MAX_IN_FLIGHT` at once; sequence numbers let the companion drop one overtaken on the way), with
  ``age_ms`` = how old it is when forwarded; a sample already past its validity is not forwarded. A slow
  companion therefore never makes samples queue: the vehicle flies the newest stick or, past its validity,
  zero velocity. The transport is one function (:data:`Transport`; HTTP today).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import secrets
import threading
import time
from collections import deque
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import Any

import httpx

from groundstation.companions import ApiError, CompanionClient

log = logging.getLogger(__name__)

#: a lease lapses this long after its last sample or keepalive (s)
LEASE_TTL_S = 3.0
#: forwards of one vehicle's samples in flight at once
MAX_IN_FLIGHT = 8
#: a vehicle's sender task ends after this long without samples (s); the next sample starts another
SENDER_IDLE_S = 10.0
#: clock exchanges kept (the shortest round trip of these gives the offset)
SYNC_WINDOW = 8


@dataclass
class Lease:
    """One operator's hold on one vehicle's stick."""

    vehicle: int
    lease_id: str
    holder: str
    expires_at: float  # time.monotonic()

    def view(self, now: float) -> dict[str, Any]:
        """What every page sees (the lease id is the holder's alone)."""
        return {"holder": self.holder, "expires_in": round(max(0.0, self.expires_at - now), 2)}


class LeaseError(ApiError):
    """The stick is not yours (409, naming the holder) or the lease is gone."""


class StickLeases:
    """The vehicles' stick leases (thread-safe: REST routes run in worker threads, samples in the loop)."""

    def __init__(self, ttl_s: float = LEASE_TTL_S, clock: Callable[[], float] = time.monotonic) -> None:
        self.ttl_s, self._clock = ttl_s, clock
        self._lock = threading.Lock()
        self._by_vehicle: dict[int, Lease] = {}

    def _live(self, vid: int, now: float) -> Lease | None:
        lease = self._by_vehicle.get(vid)
        if lease is not None and lease.expires_at <= now:
            del self._by_vehicle[vid]
            log.info("vehicle %d: the stick lease of %s expired", vid, lease.holder)
            return None
        return lease

    def take(self, vid: int, holder: str) -> Lease:
        """A new lease for ``holder``; LeaseError (409) while another lease on ``vid`` is live."""
        with self._lock:
            now = self._clock()
            lease = self._live(vid, now)
            if lease is not None:
                raise LeaseError(409, f"vehicle {vid}: the stick is held by {lease.holder} (its lease lapses "
                                      f"{lease.expires_at - now:.1f} s after its last sample)",
                                 stick_lease=lease.view(now))
            lease = Lease(vid, "lease-" + secrets.token_hex(8), holder, now + self.ttl_s)
            self._by_vehicle[vid] = lease
            return lease

    def renew(self, vid: int, lease_id: str, holder: str) -> Lease:
        """Extend the holder's lease (a sample or a keepalive); LeaseError when it is not the live one."""
        with self._lock:
            now = self._clock()
            lease = self._live(vid, now)
            if lease is None:
                raise LeaseError(409, f"vehicle {vid}: no stick lease {lease_id} (released or expired): take "
                                      f"it again with POST /api/vehicles/{vid}/stick/lease")
            if lease.lease_id != lease_id or lease.holder != holder:
                raise LeaseError(409, f"vehicle {vid}: the stick is held by {lease.holder}",
                                 stick_lease=lease.view(now))
            lease.expires_at = now + self.ttl_s
            return lease

    def release(self, vid: int, lease_id: str, holder: str) -> bool:
        """End the lease; False when it had already lapsed; LeaseError when it is someone else's."""
        with self._lock:
            now = self._clock()
            lease = self._live(vid, now)
            if lease is None:
                return False
            if lease.lease_id != lease_id or lease.holder != holder:
                raise LeaseError(409, f"vehicle {vid}: the stick is held by {lease.holder}, not this lease",
                                 stick_lease=lease.view(now))
            del self._by_vehicle[vid]
            return True

    def view(self, vid: int) -> dict[str, Any] | None:
        with self._lock:
            now = self._clock()
            lease = self._live(vid, now)
            return None if lease is None else lease.view(now)

    def views(self) -> dict[int, dict[str, Any]]:
        """Every live lease's view by vehicle."""
        with self._lock:
            now = self._clock()
            return {vid: lease.view(now) for vid in list(self._by_vehicle)
                    if (lease := self._live(vid, now)) is not None}


class ClockSync:
    """One page's clock (ms, ``performance.now()``) in the service's ``time.monotonic()`` (module doc)."""

    def __init__(self) -> None:
        self._exchanges: deque[tuple[float, float]] = deque(maxlen=SYNC_WINDOW)  # (rtt, offset)
        self._min_lag: float | None = None

    def echo(self, sent: float, page_ms: float, now: float) -> None:
        """The page answered a ``clock`` message sent at ``sent`` (service time) with its time ``page_ms``."""
        rtt = now - sent
        if 0.0 <= rtt < 5.0:
            self._exchanges.append((rtt, sent + rtt / 2.0 - page_ms / 1000.0))

    @property
    def synced(self) -> bool:
        return bool(self._exchanges)

    def to_service(self, page_ms: float, now: float) -> float:
        """When a sample stamped ``page_ms`` was made, in service time (never after ``now``)."""
        page_s = page_ms / 1000.0
        if self._exchanges:
            offset = min(self._exchanges)[1]
        else:  # no exchange yet: the smallest lag seen is the transit time (ages are then lower bounds)
            lag = now - page_s
            self._min_lag = lag if self._min_lag is None else min(self._min_lag, lag)
            offset = self._min_lag
        return min(now, page_s + offset)


@dataclass
class StickSample:
    """One stick sample on its way: ``made`` in service time (``time.monotonic()``)."""

    vehicle: int
    url: str
    values: list[float]
    validity_s: float
    made: float
    seq: int
    source: str  #: the sender: the lease id (the companion counts sequence numbers per sender)
    #: told the forward's outcome: (HTTP status or 0, why it was not taken or None)
    reply: Callable[[int, str | None], None] | None = None

    def body(self, age_s: float) -> dict[str, Any]:
        return {"values": self.values, "validity_s": self.validity_s, "age_ms": round(age_s * 1000.0, 1),
                "seq": self.seq, "sender": self.source}


#: sends one sample, ``age_s`` old, to its vehicle -> (status, reason it was dropped or None)
Transport = Callable[[StickSample, float], Awaitable[tuple[int, str | None]]]


def http_transport(headers: dict[str, str]) -> tuple[Transport, Callable[[], Awaitable[None]]]:
    """Samples as ``POST /external/ext_vel`` to the vehicle's companion (the joystick break-in flies it),
    with the service's companion ``headers``; returns (send, close)."""
    client = httpx.AsyncClient(headers=headers, limits=httpx.Limits(max_connections=None,
                                                                     max_keepalive_connections=64))

    async def send(sample: StickSample, age_s: float) -> tuple[int, str | None]:
        try:
            r = await client.post(sample.url.rstrip("/") + "/external/ext_vel", json=sample.body(age_s),
                                  timeout=max(0.25, sample.validity_s))
        except httpx.HTTPError as exc:
            return 0, f"the companion at {sample.url} did not take it: {type(exc).__name__}"
        try:
            answer = r.json()
        except ValueError:
            answer = None
        if r.status_code == 200 and isinstance(answer, dict) and answer.get("accepted") is False:
            return r.status_code, str(answer.get("reason") or "dropped")
        if r.status_code != 200:
            err = answer.get("error") if isinstance(answer, dict) else None
            return r.status_code, str(err or r.text[:200])
        return r.status_code, None

    return send, client.aclose


@dataclass
class _Lane:
    """One vehicle's slot and sender."""

    wake: asyncio.Event = field(default_factory=asyncio.Event)
    slot: StickSample | None = None
    task: asyncio.Task[None] | None = None
    in_flight: set[asyncio.Task[None]] = field(default_factory=set)


class StickForwarder:
    """Newest-sample-only forwarding (module doc); lives in the service's event loop."""

    def __init__(self, transport: Transport, max_in_flight: int = MAX_IN_FLIGHT,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.transport, self.max_in_flight, self._clock = transport, max_in_flight, clock
        self._lanes: dict[int, _Lane] = {}
        self.forwarded = self.replaced = self.expired = 0

    def submit(self, sample: StickSample) -> None:
        """Put ``sample`` in its vehicle's slot (replacing one not yet forwarded); never waits."""
        lane = self._lanes.get(sample.vehicle)
        if lane is None:
            lane = self._lanes[sample.vehicle] = _Lane()
        if lane.slot is not None:
            self.replaced += 1
        lane.slot = sample
        lane.wake.set()
        if lane.task is None or lane.task.done():
            lane.task = asyncio.create_task(self._send_loop(sample.vehicle, lane))

    async def _send_loop(self, vid: int, lane: _Lane) -> None:
        while True:
            try:
                await asyncio.wait_for(lane.wake.wait(), SENDER_IDLE_S)
            except TimeoutError:
                if lane.slot is None and not lane.in_flight:
                    return
                continue
            lane.wake.clear()
            while len(lane.in_flight) >= self.max_in_flight:
                await asyncio.wait(lane.in_flight, return_when=asyncio.FIRST_COMPLETED)
            sample, lane.slot = lane.slot, None  # the newest, taken only when it can go at once
            if sample is None:
                continue
            age = self._clock() - sample.made
            if age >= sample.validity_s:
                self.expired += 1
                continue
            task = asyncio.create_task(self._forward(sample, age))
            lane.in_flight.add(task)
            task.add_done_callback(lane.in_flight.discard)

    async def _forward(self, sample: StickSample, age_s: float) -> None:
        try:
            status, reason = await self.transport(sample, age_s)
        except Exception as exc:  # a transport's failure is the sample's, never the loop's
            log.debug("vehicle %d: stick sample not forwarded: %s", sample.vehicle, exc)
            status, reason = 0, str(exc)
        self.forwarded += 1
        if sample.reply is not None:
            sample.reply(status, reason)

    async def close(self) -> None:
        for lane in self._lanes.values():
            for t in [lane.task, *lane.in_flight]:
                if t is not None:
                    t.cancel()
                    with contextlib.suppress(asyncio.CancelledError, Exception):
                        await t
        self._lanes.clear()


class StickDesk:
    """The service's stick: leases (any thread) and, once the event loop asks, the forwarder."""

    def __init__(self, client: CompanionClient) -> None:
        self.leases = StickLeases()
        self.client = client
        self._forwarder: StickForwarder | None = None
        self._close: Callable[[], Awaitable[None]] | None = None

    @property
    def forwarder(self) -> StickForwarder:
        """Made in the event loop on first use."""
        if self._forwarder is None:
            send, self._close = http_transport(self.client.headers())
            self._forwarder = StickForwarder(send)
        return self._forwarder

    async def aclose(self) -> None:
        if self._forwarder is not None:
            await self._forwarder.close()
        if self._close is not None:
            await self._close()


_desk_lock = threading.Lock()


def desk_of(state: Any, client: CompanionClient) -> StickDesk:
    """The app's :class:`StickDesk` (``app.state.stick``), made on first use."""
    with _desk_lock:
        desk = getattr(state, "stick", None)
        if desk is None:
            desk = StickDesk(client)
            state.stick = desk
        return desk
