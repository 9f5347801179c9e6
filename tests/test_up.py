"""``taskflight up``: the whole simulated fleet in one command, as a user runs it.

``taskflight up --vehicles 3 --speedup 3`` in a child process, on a free block of instance numbers
(``--base-instance``): READY within a deadline; each vehicle's MAVLink TCP port answers with its system id
(a pymavlink ground station, as MAVProxy connects); every companion's row is heard on the team link (a
listener in the test decoding the real packets); SIGINT stops everything, no child is left and the ports
are free again. Start-up failures: a MAVLink port already taken (a clear message, nothing started) and a
companion that dies while starting (its log's tail reported, the fleet stopped).
"""

from __future__ import annotations

import os
import signal
import socket
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from harness.timing import wait_for
from harness.up import Summary, UpProcess, alive, processes_mentioning
from taskflight_common.ports import free_base, free_ports, port_free

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil

from companion.team.auth import load_key
from companion.team.transport import open_transport
from companion.team.wire import WireError, decode_packet
from taskflight.team_tasking import HttpError, http_json

pytestmark = pytest.mark.integration

N = 3
SPEEDUP = 3.0
READY_S = 120.0


def has_ground() -> bool:
    """``taskflight ground`` exists (the ground service)."""
    from taskflight.cli import build_parser

    return "ground" in build_parser().get_default("_handlers")


def ground_args() -> list[str]:
    if not has_ground():
        return ["--no-ground"]
    return ["--ground-port", str(free_ports(1, socket.SOCK_STREAM)[0])]


class Running:
    def __init__(self, up: UpProcess, summary: Summary, base: int, state: Path) -> None:
        self.up, self.summary, self.base, self.state = up, summary, base, state


@pytest.fixture(scope="module")
def running(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Running]:
    state = tmp_path_factory.mktemp("up")
    base = free_base(N)
    up = UpProcess(["--vehicles", str(N), "--speedup", str(SPEEDUP), "--base-instance", str(base),
                    "--no-persist", *ground_args()], state)
    try:
        summary = up.wait_ready(READY_S)  # a deadline; how long start-up takes: bench/bench_up.py
        yield Running(up, summary, base, state)
    finally:
        up.close()


def test_ready_with_every_child_and_port_listed(running: Running) -> None:
    s = running.summary
    assert s.tcp == [5760 + 10 * (running.base + i) for i in range(N)]
    assert len(s.companions) == N and {f"companion{i + 1}" for i in range(N)} <= set(s.pids)
    assert all(alive(pid) for pid in s.pids.values())
    assert running.up.proc.poll() is None


def test_each_vehicle_answers_on_its_tcp_port_with_its_system_id(running: Running) -> None:
    for i, port in enumerate(running.summary.tcp):
        conn = mavutil.mavlink_connection(f"tcp:127.0.0.1:{port}", source_system=255, autoreconnect=False)
        try:
            hb = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=30)
            assert hb is not None, f"no HEARTBEAT on TCP {port}"
            assert hb.get_srcSystem() == i + 1
        finally:
            conn.close()


def test_every_companion_row_is_heard_on_the_team_link(running: Running) -> None:
    url = running.summary.team.split("?")[0]  # the test listens without the members' test loss
    key = load_key(running.state / "team.key")  # the fleet's generated team key: every packet is signed
    transport = open_transport(url, member=0, position_of=lambda m: None)
    key = load_key(running.state / "team.key")  # up signs its fleet's packets with the key it generated
    heard: set[int] = set()
    try:
        end = time.monotonic() + 30
        while not set(range(1, N + 1)) <= heard and time.monotonic() < end:  # the station sends too
            data = transport.recv(0.5)
            if data is None:
                continue
            try:
                pkt = decode_packet(data, key=key)
            except WireError:
                continue
            heard.add(pkt.sender)  # each companion's own packets, not rows relayed
    finally:
        transport.close()
    assert set(range(1, N + 1)) <= heard


@pytest.mark.skipif(not has_ground(), reason="the ground service (taskflight ground) is not installed")
def test_the_ground_service_answers_with_the_printed_tokens(running: Running) -> None:
    s = running.summary
    assert s.ground and s.operator and s.observer and "ground" in s.pids
    tokens = running.state / "tokens.yaml"
    assert tokens.stat().st_mode & 0o777 == 0o600
    assert s.operator in tokens.read_text() and s.observer in tokens.read_text()
    for token in (s.operator, s.observer):
        rows = http_json("GET", s.ground + "/api/vehicles", token)["vehicles"]
        assert sorted(r["id"] for r in rows) == [1, 2, 3]
    with pytest.raises(HttpError) as err:
        http_json("GET", s.ground + "/api/vehicles", "not-a-token")
    assert err.value.status == 401


def test_sigint_stops_everything_and_frees_the_ports(running: Running) -> None:
    """Last in this module: Ctrl-C stops the children, none is left, the MAVLink ports are free."""
    pids = dict(running.summary.pids)
    rc = running.up.interrupt(60)
    assert rc == 0, running.up.output
    assert "taskflight up: stopped" in running.up.output
    assert [p for p in pids.values() if alive(p)] == []
    assert processes_mentioning(str(running.state)) == []
    for port in running.summary.tcp:  # a listener can bind each port again
        wait_for(lambda port=port: port_free(socket.SOCK_STREAM, port), 10, f"TCP {port} free")


def test_a_port_already_taken_is_a_clear_error_and_nothing_starts(tmp_path: Path) -> None:
    base = free_base(2)
    tcp = 5760 + 10 * (base + 1)
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as blocker:
        blocker.bind(("127.0.0.1", tcp))
        blocker.listen()
        up = UpProcess(["--vehicles", "2", "--base-instance", str(base), "--no-ground", "--no-persist"],
                       tmp_path)
        try:
            rc = up.proc.wait(60)
        finally:
            up.close()
    assert rc == 2
    assert f"TCP {tcp} (vehicle 1, sysid 2)" in up.output and "already in use" in up.output
    assert not (tmp_path / "logs").exists()  # nothing was started
    assert processes_mentioning(str(tmp_path)) == []


def test_a_companion_dying_at_start_up_is_reported_and_everything_stops(tmp_path: Path) -> None:
    bad = tmp_path / "platform.yaml"
    bad.write_text("name: broken\nendurance_s: [not a number\n", encoding="utf-8")
    up = UpProcess(["--vehicles", "2", "--base-instance", str(free_base(2)), "--no-ground", "--no-persist",
                    "--platform", str(bad)], tmp_path / "state")
    try:
        rc = up.proc.wait(120)
    finally:
        up.close()
    assert rc == 1, up.output
    assert "exited with status 2 during start-up" in up.output
    assert "platform.yaml" in up.output  # the companion's own error, from the tail of its log
    assert processes_mentioning(str(tmp_path)) == []


def test_sigkill_of_up_stops_every_child_by_itself(tmp_path: Path) -> None:
    """``taskflight up`` killed with SIGKILL cannot stop its children: each stops by itself on the kernel's
    parent-death signal (taskflight_common.runtime.die_with_parent), as on Ctrl-C; nothing is left running."""
    up = UpProcess(["--vehicles", "1", "--base-instance", str(free_base(1)), "--no-persist", *ground_args()],
                   tmp_path)
    try:
        pids = dict(up.wait_ready(READY_S).pids)
        assert len(pids) >= 2 and all(alive(p) for p in pids.values()), pids
        up.proc.send_signal(signal.SIGKILL)
        up.proc.wait(10)
        wait_for(lambda: not [p for p in pids.values() if alive(p)], 30,
                 f"every child of the killed taskflight up gone: {pids}")
        wait_for(lambda: processes_mentioning(str(tmp_path)) == [], 10, "no process of its state dir left")
    finally:
        up.close()
        for pid in processes_mentioning(str(tmp_path)):  # the old behavior: clean up what it left
            os.kill(pid, signal.SIGKILL)
