"""The members of one process on one UDP team group share one socket and one receive thread."""

from __future__ import annotations

import threading

from companion.team.transport import open_transport
from companion.team.udp_shared import SharedGroupSocket
from harness.team import new_team_url
from harness.timing import wait_for


def test_one_socket_per_group_each_datagram_to_every_member_once() -> None:
    url = new_team_url() + "?iface=127.0.0.1"
    a, b, c = (open_transport(url) for _ in range(3))
    try:
        shared = {id(t._shared) for t in (a, b, c)}  # type: ignore[attr-defined]
        assert len(shared) == 1  # one socket, one thread for the three
        heard: dict[str, list[bytes]] = {"a": [], "b": []}
        lock = threading.Lock()

        def into(name: str):  # type: ignore[no-untyped-def]
            def cb(data: bytes) -> None:
                with lock:
                    heard[name].append(data)
            return cb

        assert a.subscribe(into("a")) and b.subscribe(into("b"))
        for i in range(20):
            c.send(f"packet {i}".encode())
        want = [f"packet {i}".encode() for i in range(20)]
        wait_for(lambda: len(heard["a"]) >= 20 and len(heard["b"]) >= 20, 10, "every packet at both members")
        assert heard["a"] == want and heard["b"] == want  # once each, in order; the sender's own echo too:
        wait_for(lambda: c.recv(0.0) == want[0], 5, "the sender (pull mode) hears its own first packet")
        assert [c.recv(1.0) for _ in range(19)] == want[1:]
        assert a.recv(0.05) is None  # pushed: nothing queued for recv
        sock = next(iter(SharedGroupSocket._registry.values())).sock
    finally:
        for t in (a, b, c):
            t.close()
    assert sock.fileno() == -1  # the last one out closed it
    assert all(k[1] != int(url.split(":")[2].split("?")[0]) for k in SharedGroupSocket._registry)


def test_a_lossy_member_drops_in_push_mode_too() -> None:
    url = new_team_url() + "?iface=127.0.0.1"
    lossy, clean, sender = open_transport(url + "&loss=0.5&seed=3"), open_transport(url), open_transport(url)
    try:
        got = {"lossy": 0, "clean": 0}

        def count(name: str):  # type: ignore[no-untyped-def]
            def cb(_data: bytes) -> None:
                got[name] += 1
            return cb

        assert lossy.subscribe(count("lossy")) and clean.subscribe(count("clean"))
        for i in range(200):
            sender.send(b"x%d" % i)
        wait_for(lambda: got["clean"] >= 200, 10, "every packet at the clean member")
        wait_for(lambda: lossy.passed + lossy.dropped_loss >= 200, 10, "every packet judged at the lossy one")  # type: ignore[attr-defined]
        assert got["lossy"] == lossy.passed and 60 < lossy.passed < 140  # type: ignore[attr-defined]
    finally:
        for t in (lossy, clean, sender):
            t.close()
