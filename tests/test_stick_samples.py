"""Stick samples on the companion (seed 000 Sec. IV-C, a stream's validity; Sec. VII, the operator's
break-in): a sample stamped where it was made counts its validity from there, so one that arrives already
past it is dropped; a sample whose sequence number is not above its sender's last is dropped whatever its
stamp says; a new sender (a new stick lease) starts its own count. Over real HTTP on loopback
(``POST /external/ext_vel`` with ``age_ms``, ``seq``, ``sender``), on a companion never started (its queue
answers on its own).
"""

from __future__ import annotations

from collections.abc import Iterator

import httpx
import pytest

from companion.builder import CompanionConfig, build_companion
from companion.flight.external import ExternalData, ExternalDataError
from companion.node import QuadNode
from harness.fake_autopilot import unanswered_url


@pytest.fixture
def served() -> Iterator[tuple[QuadNode, httpx.Client]]:
    companion = build_companion(CompanionConfig(unanswered_url(), behaviors=False, control_port=0))
    server = companion.control_server(host="127.0.0.1", token=None).start()
    try:
        with httpx.Client(base_url=server.url, timeout=10.0) as http:
            yield companion.node, http
    finally:
        server.close()
        companion.node.close()


def post(http: httpx.Client, **body: object) -> dict[str, object]:
    r = http.post("/external/ext_vel", json={"values": [1.0, 0.0, 0.0, 0.0], "validity_s": 0.5, **body})
    assert r.status_code == 200, r.text
    return r.json()


def test_stale_and_out_of_order_samples_are_dropped_over_http(served: tuple[QuadNode, httpx.Client]) -> None:
    node, http = served
    assert post(http, seq=5, sender="lease-a", age_ms=10) == {"accepted": True, "reason": None}
    # older than its validity when it arrives: dropped, the newest sample stays
    stale = post(http, values=[2.0, 0, 0, 0], seq=6, sender="lease-a", age_ms=600)
    assert stale["accepted"] is False and "stale" in str(stale["reason"])
    # a sequence number not above the sender's last: out of order, whatever its age
    for seq in (5, 4):
        late = post(http, values=[3.0, 0, 0, 0], seq=seq, sender="lease-a", age_ms=0)
        assert late["accepted"] is False and "out of order" in str(late["reason"]), late
    sample = node.queue.external_sample("ext_vel")
    assert sample is not None and sample.values == (1.0, 0.0, 0.0, 0.0)
    # the next one in order is taken, stamped ``age_ms`` before its arrival
    before = node.clock.now()
    assert post(http, values=[4.0, 0, 0, 0], seq=7, sender="lease-a", age_ms=200)["accepted"] is True
    sample = node.queue.external_sample("ext_vel")
    assert sample is not None and sample.values[0] == 4.0 and sample.t_s <= before - 0.15
    # a new lease counts from its own start
    assert post(http, values=[5.0, 0, 0, 0], seq=0, sender="lease-b")["accepted"] is True
    # malformed: a clear 400 naming the field, nothing changed
    for bad, field in (({"age_ms": -1}, "age_ms"), ({"seq": -3}, "seq"), ({"seq": 1.5}, "seq"),
                       ({"sender": ""}, "sender")):
        r = http.post("/external/ext_vel", json={"values": [9.0, 0, 0, 0], **bad})
        assert r.status_code == 400 and field in r.json()["error"], r.text
    sample = node.queue.external_sample("ext_vel")
    assert sample is not None and sample.values[0] == 5.0


def test_stale_sample_means_zero_velocity_after_its_validity() -> None:
    ext = ExternalData()
    assert ext.offer("ext_vel", (1, 0, 0, 0), 0.3, 10.0 - 0.1, seq=1, sender="s", now_s=10.0) is None
    assert ext.latest("ext_vel", 10.15) == (1.0, 0.0, 0.0, 0.0)
    assert ext.latest("ext_vel", 10.25) is None  # 0.3 s after it was made, not after it arrived
    # a sequence number from the same source wins over a jittered stamp; another source's older stamp loses
    assert ext.offer("ext_vel", (2, 0, 0, 0), 0.3, 9.95, seq=2, sender="s", now_s=10.0) is None
    assert ext.offer("ext_vel", (3, 0, 0, 0), 0.3, 9.9, now_s=10.0) == "older than the stream's newest sample"
    with pytest.raises(ExternalDataError, match="seq"):
        ext.offer("ext_vel", (1, 0, 0, 0), 0.3, 10.0, seq=True)
