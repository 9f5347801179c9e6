"""The operator's stick through the ground service (seed 000 Sec. VII, the break-in; Sec. IV-C, a
stream's validity).

* the forwarder keeps only the newest sample per vehicle and never waits for a slow companion: with a
  transport answering in 600 ms, samples made at 20 Hz are forwarded while young (a waiting one replaced
  by a newer), none past its validity, the last one always; once the samples stop, at most the ones in
  flight and the one waiting still go;
* the stick lease over REST and the WebSocket, on a real companion's HTTP surface (a companion never
  started: its queue takes the samples): one operator takes it; a second operator's take is refused
  naming the holder, its samples (without the lease or with the other's) are refused and reach nothing;
  the second operator's snapshot shows who holds the stick; the holder's samples reach the companion with
  their sequence number, lease and age; released (or the holder's page closed), the stick is free.
"""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import Iterator
from typing import Any

import pytest

from companion.builder import CompanionConfig, build_companion
from companion.node import QuadNode
from groundstation.stick import MAX_IN_FLIGHT, StickForwarder, StickSample
from harness.fake_autopilot import unanswered_url
from harness.ground import OPERATOR, OPERATOR2, InProcessGround
from harness.timing import wait_for


def test_a_slow_companion_never_makes_samples_queue() -> None:
    sent: list[tuple[int, float, float]] = []  # (seq, age when forwarded, when it arrived)

    async def slow(sample: StickSample, age_s: float) -> tuple[int, str | None]:
        await asyncio.sleep(0.6)  # answers slower than MAX_IN_FLIGHT forwards at the stick's rate
        sent.append((sample.seq, age_s, time.monotonic()))
        return 200, None

    async def run() -> tuple[float, StickForwarder]:
        fwd = StickForwarder(slow)
        for seq in range(60):  # 3 s of stick at 20 Hz
            fwd.submit(StickSample(1, "http://x", [1.0, 0, 0, 0], 0.3, time.monotonic(), seq, "lease-t"))
            await asyncio.sleep(0.05)
        last = time.monotonic()
        await asyncio.sleep(2.0)
        await fwd.close()
        return last, fwd

    last, fwd = asyncio.run(run())
    seqs = [s for s, _, _ in sent]
    assert len(sent) >= 20, f"only {len(sent)} of 60 forwarded: the forwards waited for each other"
    assert max(age for _, age, _ in sent) < 0.3, "a sample forwarded past its validity"
    # after the last sample, only what was in flight or waiting: never a backlog
    assert sum(1 for *_, t in sent if t > last) <= MAX_IN_FLIGHT + 1
    assert fwd.replaced > 0, "no sample was ever replaced by a newer one: the companion was not slow"
    assert seqs == sorted(seqs) and seqs[-1] == 59, "the newest sample (the operator's last) not forwarded"


@pytest.fixture(scope="module")
def companion() -> Iterator[tuple[QuadNode, str]]:
    c = build_companion(CompanionConfig(unanswered_url(), behaviors=False, control_port=0))
    server = c.control_server(host="127.0.0.1", token=None).start()
    try:
        yield c.node, server.url
    finally:
        server.close()
        c.node.close()


@pytest.fixture(scope="module")
def ground(companion: tuple[QuadNode, str],
           tmp_path_factory: pytest.TempPathFactory) -> Iterator[InProcessGround]:
    g = InProcessGround(tmp_path_factory.mktemp("stick"), companions={1: companion[1]})
    yield g
    g.close()


def messages(ws: Any, until: Any, timeout: float = 10.0) -> dict[str, Any]:
    """The first message for which ``until`` is true (others skipped)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        m = json.loads(ws.recv(timeout=max(0.01, deadline - time.monotonic())))
        if until(m):
            return m
    raise AssertionError("no such message")


def lease_of(m: dict[str, Any], vid: int = 1) -> Any:
    return next(v for v in m["vehicles"] if v["id"] == vid).get("stick_lease", "missing")


def test_one_operator_holds_the_stick_and_the_other_sees_it(companion: tuple[QuadNode, str],
                                                            ground: InProcessGround) -> None:
    node = companion[0]
    with ground.http(OPERATOR) as one, ground.http(OPERATOR2) as two:
        assert one.get("/api/vehicles/1/stick/lease").json() == {"vehicle": 1, "stick_lease": None,
                                                                 "released": None}
        assert one.post("/api/vehicles/9/stick/lease").status_code == 404
        r = one.post("/api/vehicles/1/stick/lease")
        assert r.status_code == 200, r.text
        lease = r.json()
        holder = lease["holder"]
        assert holder.startswith("operator:") and lease["lease_id"].startswith("lease-")
        r = two.post("/api/vehicles/1/stick/lease")
        assert r.status_code == 409 and holder in r.json()["error"], r.text
        r = two.delete("/api/vehicles/1/stick/lease", params={"lease_id": lease["lease_id"]})
        assert r.status_code == 409, r.text

        with ground.ws(OPERATOR2) as ws2, ground.ws(OPERATOR) as ws1:
            # the other operator's page: the lease shown in its snapshot, its samples refused
            m = messages(ws2, lambda m: m["type"] == "snapshot" and lease_of(m) not in (None, "missing"))
            assert lease_of(m)["holder"] == holder and 0 < lease_of(m)["expires_in"] <= lease["ttl_s"]
            before = node.queue.external_sample("ext_vel")
            for extra in ({}, {"lease": lease["lease_id"]}, {"lease": "lease-guessed"}):
                ws2.send(json.dumps({"type": "joystick", "vehicle": 1, "values": [2, 0, 0, 0], "seq": 1,
                                     **extra}))
                err = messages(ws2, lambda m: m["type"] == "error")
                assert holder in err["error"] or "lease" in err["error"], err
            # the holder's samples reach the companion: newest, with seq, lease and age
            for seq in range(1, 11):
                ws1.send(json.dumps({"type": "joystick", "vehicle": 1, "lease": lease["lease_id"],
                                     "values": [1.0, 0, 0, 0], "validity_s": 0.5, "seq": seq}))
                time.sleep(0.02)

            def took() -> bool:
                s = node.queue.external_sample("ext_vel")
                return s is not None and s != before and s.sender == lease["lease_id"]
            wait_for(took, 10, "the holder's samples at the companion")
            s = node.queue.external_sample("ext_vel")
            assert s is not None and s.values == (1.0, 0.0, 0.0, 0.0) and s.validity_s == 0.5
            # the holder's page closes: the lease goes with it
        wait_for(lambda: one.get("/api/vehicles/1/stick/lease").json()["stick_lease"] is None, 10,
                 "the lease released when its page closed")
        # now the second operator may take it, and release it
        r = two.post("/api/vehicles/1/stick/lease")
        assert r.status_code == 200, r.text
        again = two.post("/api/vehicles/1/stick/lease", json={"lease_id": r.json()["lease_id"]})
        assert again.status_code == 200 and again.json()["lease_id"] == r.json()["lease_id"]
        gone = two.delete("/api/vehicles/1/stick/lease", params={"lease_id": r.json()["lease_id"]})
        assert gone.status_code == 200 and gone.json()["released"] is True
        assert two.get("/api/vehicles/1/stick/lease").json()["stick_lease"] is None
        actions = [e["action"] for e in one.get("/api/audit").json()["entries"]]
        assert {"stick_lease", "stick_release"} <= set(actions)
