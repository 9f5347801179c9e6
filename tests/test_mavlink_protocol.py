"""Protocol pieces of the MAVLink endpoint over real loopback UDP, with a stand-in vehicle.

The vehicle is not what is under test here: a clock, a parameter store and a function registry are
all the endpoint needs; a pymavlink connection plays the ground station.
"""

from __future__ import annotations

import itertools
import math
import os
import socket
import time
from collections.abc import Callable
from typing import Any

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from autopilot_model.mavlink.commands import ACCEPTED, DENIED, UNSUPPORTED, Command
from autopilot_model.mavlink.endpoint import MavlinkEndpoint
from autopilot_model.mavlink.framing import FrameParser
from autopilot_model.mavlink.signing import key_from_passphrase
from autopilot_model.mavlink.wiring import LinkProtocol, link_protocol
from autopilot_model.params import ParamStore
from taskflight_common.clock import SimClock
from taskflight_common.ports import free_ports


class StandIn:
    """Just enough of a vehicle for the endpoint: clock, params, function registry."""

    instance = 0

    def __init__(self) -> None:
        self.clock = SimClock(0)
        self.params = ParamStore()
        self.params.define("WPNAV_SPEED", 500, 20, 2000, doc="cm/s")
        self.params.define("FS_GCS_ENABLE", 0, 0, 5, "int")
        self.functions: dict[str, Callable[[], None]] = {}

    def register(self, name: str, fn: Callable[[], None]) -> None:
        self.functions[name] = fn

    def step(self, n: int = 1) -> None:
        for i in range(n):
            self.functions["mavlink.poll"]()
            if i % 10 == 0:
                self.functions["mavlink.telemetry"]()
            self.clock.advance(2000)


class Gcs:
    """A raw UDP ground station with its own pymavlink encoder/decoder."""

    def __init__(self, port: int, sysid: int = 255, key: bytes | None = None) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setblocking(False)
        self.addr = ("127.0.0.1", port)
        self.mav = mavlink2.MAVLink(None, sysid, 190)
        self.mav.robust_parsing = True
        if key is not None:
            self.mav.signing.secret_key = key
            self.mav.signing.sign_outgoing = True
            self.mav.signing.timestamp = int((time.time() - 1420070400) * 1e5)
        self.rx = mavlink2.MAVLink(None, 0, 0)
        self.rx.robust_parsing = True
        self.got: list[Any] = []

    def send(self, msg: Any) -> None:
        self.sock.sendto(msg.pack(self.mav), self.addr)
        self.mav.seq = (self.mav.seq + 1) % 256

    def raw(self, data: bytes) -> None:
        self.sock.sendto(data, self.addr)

    def drain(self) -> None:
        while True:
            try:
                data = self.sock.recv(4096)
            except BlockingIOError:
                return
            for m in self.rx.parse_buffer(data) or []:
                if m.get_type() != "BAD_DATA":
                    self.got.append(m)

    def wait(self, vehicle: StandIn, pred: Callable[[Any], bool], timeout_s: float = 2.0) -> Any:
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            vehicle.step(5)
            self.drain()
            for i, m in enumerate(self.got):
                if pred(m):
                    del self.got[i]
                    return m
        raise AssertionError("timed out waiting for a message")

    def command(self, vehicle: StandIn, cmd: int, *params: float, confirmation: int = 0) -> Any:
        p = list(params) + [0.0] * (7 - len(params))
        self.send(self.mav.command_long_encode(1, 1, cmd, confirmation, *p))
        return self.wait(vehicle, lambda m: m.get_type() == "COMMAND_ACK" and m.command == cmd)


def make_endpoint(v: StandIn, urls: list[str], signing_key: bytes | None = None) -> LinkProtocol:
    """The endpoint's core with the vehicle-independent pieces, its functions registered on ``v``."""
    ep = MavlinkEndpoint(v.clock, v.params, urls, signing_key=signing_key)
    v.register("mavlink.poll", ep.poll)
    v.register("mavlink.telemetry", ep.telemetry)
    return link_protocol(ep)


@pytest.fixture()
def setup(tmp_path: Any) -> Any:
    v = StandIn()
    port = free_ports(1, socket.SOCK_DGRAM)[0]
    proto = make_endpoint(v, [f"udpin:127.0.0.1:{port}"])
    ep = proto.endpoint
    proto.streams.add_builder("HEARTBEAT", lambda: ep.mav.heartbeat_encode(
        mavlink2.MAV_TYPE_QUADROTOR, mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA, 1, 4, 3))
    proto.streams.add_builder("SYSTEM_TIME", lambda: ep.mav.system_time_encode(0, v.clock.time_boot_ms))
    gcs = Gcs(port)
    yield v, proto, gcs
    ep.close()


def _hello(v: StandIn, gcs: Gcs) -> None:
    gcs.send(gcs.mav.heartbeat_encode(mavlink2.MAV_TYPE_GCS, mavlink2.MAV_AUTOPILOT_INVALID, 0, 0, 0))
    gcs.wait(v, lambda m: m.get_type() == "HEARTBEAT")


def test_heartbeat_answers_whoever_sends_and_gcs_heartbeat_is_recorded(setup: Any) -> None:
    v, proto, gcs = setup
    ep = proto.endpoint
    assert ep.last_gcs_heartbeat_s is None
    _hello(v, gcs)
    assert ep.last_gcs_heartbeat_s is not None
    hb = gcs.wait(v, lambda m: m.get_type() == "HEARTBEAT")
    assert hb.get_srcSystem() == 1 and hb.autopilot == mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA


def test_unknown_command_unsupported_and_denied_has_statustext(setup: Any) -> None:
    v, proto, gcs = setup
    _hello(v, gcs)
    assert gcs.command(v, 31999).result == UNSUPPORTED
    proto.commands.add(42424, lambda c, p: (DENIED, "Nope: because"))
    ack = gcs.command(v, 42424)
    assert ack.result == DENIED
    txt = gcs.wait(v, lambda m: m.get_type() == "STATUSTEXT")
    assert "because" in txt.text


def test_retransmission_executed_once_acked_twice(setup: Any) -> None:
    v, proto, gcs = setup
    ep = proto.endpoint
    _hello(v, gcs)
    calls: list[Command] = []
    proto.commands.add(42425, lambda c, p: (calls.append(c), (ACCEPTED, None))[1])
    assert gcs.command(v, 42425, 1.0).result == ACCEPTED
    assert gcs.command(v, 42425, 1.0, confirmation=1).result == ACCEPTED
    assert gcs.command(v, 42425, 1.0).result == ACCEPTED  # identical, within the window
    assert len(calls) == 1
    assert ep.stats["commands_duplicate"] == 2
    assert gcs.command(v, 42425, 2.0).result == ACCEPTED  # different parameters: a new command
    assert len(calls) == 2


def test_set_message_interval_and_request_message(setup: Any) -> None:
    v, _proto, gcs = setup
    _hello(v, gcs)
    ack = gcs.command(v, mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink2.MAVLINK_MSG_ID_SYSTEM_TIME, 20000)
    assert ack.result == ACCEPTED
    gcs.got.clear()
    t0 = v.clock.now()
    v.step(500)  # one simulated second
    gcs.drain()
    n = sum(1 for m in gcs.got if m.get_type() == "SYSTEM_TIME")
    assert 40 <= n <= 55, n
    assert v.clock.now() - t0 == pytest.approx(1.0)
    ack = gcs.command(v, mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink2.MAVLINK_MSG_ID_SYSTEM_TIME, -1)
    gcs.got.clear()
    v.step(500)
    gcs.drain()
    assert not any(m.get_type() == "SYSTEM_TIME" for m in gcs.got)
    ack = gcs.command(v, mavlink2.MAV_CMD_REQUEST_MESSAGE, mavlink2.MAVLINK_MSG_ID_SYSTEM_TIME)
    assert ack.result == ACCEPTED
    st = gcs.wait(v, lambda m: m.get_type() == "SYSTEM_TIME")
    assert st.time_boot_ms == pytest.approx(v.clock.time_boot_ms, abs=100)
    assert gcs.command(v, mavlink2.MAV_CMD_REQUEST_MESSAGE, 9999999).result == UNSUPPORTED


def test_param_protocol_list_read_set_and_rejects(setup: Any, tmp_path: Any) -> None:
    v, proto, gcs = setup
    ep = proto.endpoint
    v.params.attach_file(tmp_path / "params.json")
    _hello(v, gcs)
    gcs.send(gcs.mav.param_request_list_encode(1, 1))
    seen: dict[int, Any] = {}
    end = time.monotonic() + 3
    while len(seen) < len(v.params) and time.monotonic() < end:
        v.step(5)
        gcs.drain()
        for m in gcs.got:
            if m.get_type() == "PARAM_VALUE":
                seen[m.param_index] = m
        gcs.got.clear()
    assert len(seen) == len(v.params)
    gcs.send(gcs.mav.param_request_read_encode(1, 1, b"WPNAV_SPEED", -1))
    pv = gcs.wait(v, lambda m: m.get_type() == "PARAM_VALUE")
    assert pv.param_id == "WPNAV_SPEED" and pv.param_value == 500
    gcs.send(gcs.mav.param_set_encode(1, 1, b"WPNAV_SPEED", 750.0, mavlink2.MAV_PARAM_TYPE_REAL32))
    pv = gcs.wait(v, lambda m: m.get_type() == "PARAM_VALUE")
    assert pv.param_value == 750 and v.params.get("WPNAV_SPEED") == 750
    assert "WPNAV_SPEED" in (tmp_path / "params.json").read_text()
    gcs.send(gcs.mav.param_set_encode(1, 1, b"WPNAV_SPEED", 99999.0, mavlink2.MAV_PARAM_TYPE_REAL32))
    txt = gcs.wait(v, lambda m: m.get_type() == "STATUSTEXT")
    assert "out of range" in txt.text
    pv = gcs.wait(v, lambda m: m.get_type() == "PARAM_VALUE")
    assert pv.param_value == 750 and v.params.get("WPNAV_SPEED") == 750
    gcs.send(gcs.mav.param_set_encode(1, 1, b"FS_GCS_ENABLE", 1.5, mavlink2.MAV_PARAM_TYPE_INT32))
    gcs.wait(v, lambda m: m.get_type() == "STATUSTEXT" and "integer" in m.text)
    gcs.send(gcs.mav.param_set_encode(1, 1, b"WPNAV_SPEED", math.nan, mavlink2.MAV_PARAM_TYPE_REAL32))
    gcs.wait(v, lambda m: m.get_type() == "STATUSTEXT")
    assert v.params.get("WPNAV_SPEED") == 750 and ep.stats["invalid_field"] == 1


def test_robustness_counts_and_never_acts(setup: Any) -> None:
    v, proto, gcs = setup
    ep = proto.endpoint
    _hello(v, gcs)
    calls: list[Command] = []
    proto.commands.add(42426, lambda c, p: (calls.append(c), (ACCEPTED, None))[1])
    good = gcs.mav.command_long_encode(1, 1, 42426, 0, 1, 2, 3, 4, 5, 6, 7).pack(gcs.mav)
    gcs.raw(os.urandom(40).replace(b"\xfd", b"\x00").replace(b"\xfe", b"\x00"))  # garbage
    gcs.raw(good[:20])  # truncated
    bad = bytearray(good)
    bad[-1] ^= 0xFF
    gcs.raw(bytes(bad))  # bad CRC
    unknown = bytearray(good)
    unknown[7:10] = (0xFFFFF0).to_bytes(3, "little")
    gcs.raw(bytes(unknown))  # unknown message id
    gcs.send(gcs.mav.command_long_encode(7, 1, 42426, 0, 1, 2, 3, 4, 5, 6, 7))  # another system
    v.step(50)
    assert calls == []
    for k in ("garbage", "truncated", "bad_crc", "unknown", "wrong_target"):
        assert ep.stats[k] >= 1, k
    gcs.raw(good)
    gcs.wait(v, lambda m: m.get_type() == "COMMAND_ACK")
    assert len(calls) == 1


def test_tcp_stream_split_frames() -> None:
    stats: dict[str, int] = __import__("collections").Counter()
    p = FrameParser(stats, stream=True)
    mav = mavlink2.MAVLink(None, 255, 190)
    data = b"".join(mav.heartbeat_encode(6, 8, 0, 0, 0).pack(mav) for _ in range(5))
    out = []
    for i in range(0, len(data), 7):
        out += p.feed(data[i:i + 7])
    assert [m.get_type() for m in out] == ["HEARTBEAT"] * 5 and sum(stats.values()) == 0


def test_signing_unsigned_refused_signed_accepted() -> None:
    v = StandIn()
    port = free_ports(1, socket.SOCK_DGRAM)[0]
    key = key_from_passphrase("taskflight")
    proto = make_endpoint(v, [f"udpin:127.0.0.1:{port}"], signing_key=key)
    ep = proto.endpoint
    proto.streams.add_builder("HEARTBEAT", lambda: ep.mav.heartbeat_encode(2, 3, 1, 4, 3))
    calls: list[Command] = []
    proto.commands.add(42427, lambda c, p: (calls.append(c), (ACCEPTED, None))[1])
    try:
        plain = Gcs(port)
        plain.send(plain.mav.command_long_encode(1, 1, 42427, 0, 1, 0, 0, 0, 0, 0, 0))
        v.step(50)
        assert calls == [] and ep.signing.stats.unsigned_rejected == 1
        wrong = Gcs(port, key=key_from_passphrase("wrong"))
        wrong.send(wrong.mav.command_long_encode(1, 1, 42427, 0, 1, 0, 0, 0, 0, 0, 0))
        v.step(50)
        assert calls == [] and ep.signing.stats.bad_signature == 1
        signed = Gcs(port, key=key)
        signed.rx.signing.secret_key = key
        ack = signed.command(v, 42427, 1.0)
        assert ack.result == ACCEPTED and len(calls) == 1 and ack._signed
    finally:
        ep.close()


def test_only_the_configured_gcs_system_counts_for_the_gcs_failsafe(setup: Any) -> None:
    """ArduCopter counts heartbeats from MAV_GCS_SYSID only: a companion (the vehicle's own system,
    component 191) or another system's ground station does not keep the GCS failsafe quiet."""
    v, proto, gcs = setup
    ep = proto.endpoint
    companion = mavlink2.MAVLink(None, 1, 191)
    gcs.raw(companion.heartbeat_encode(mavlink2.MAV_TYPE_ONBOARD_CONTROLLER, mavlink2.MAV_AUTOPILOT_INVALID,
                                       0, 0, 0).pack(companion))
    other = mavlink2.MAVLink(None, 42, 190)
    beat = other.heartbeat_encode(mavlink2.MAV_TYPE_GCS, mavlink2.MAV_AUTOPILOT_INVALID, 0, 0, 0)
    gcs.raw(beat.pack(other))
    v.step(20)
    assert ep.last_gcs_heartbeat_s is None
    v.params.set("MAV_GCS_SYSID", 42)
    gcs.raw(beat.pack(other))
    v.step(20)
    assert ep.last_gcs_heartbeat_s is not None


def test_a_telemetry_ticks_packets_go_gathered_in_order_and_no_datagram_passes_1400_bytes(setup: Any) -> None:
    """What one telemetry call sends to a link is written at its end, several packets to a datagram (as
    ArduPilot's serial drivers write their buffer), in sequence, split before 1,400 bytes; a command's ACK
    sent while a poll dispatches still arrives."""
    v, proto, gcs = setup
    ep = proto.endpoint
    _hello(v, gcs)
    assert gcs.command(v, mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink2.MAVLINK_MSG_ID_SYSTEM_TIME,
                       20000).result == ACCEPTED
    texts = [f"burst {i:02d}: " + "x" * 40 for i in range(30)]  # ~2 kB of STATUSTEXT in one call
    burst = [True]

    def once() -> None:
        if burst.pop() if burst else False:
            for t in texts:
                ep.statustext(6, t)
    ep.periodic.append(once)
    while True:  # what came before
        try:
            gcs.sock.recv(4096)
        except BlockingIOError:
            break
    datagrams: list[list[Any]] = []
    for _ in range(100):
        v.step(10)  # one telemetry call each
        while True:
            try:
                data = gcs.sock.recv(65535)
            except BlockingIOError:
                break
            assert len(data) <= 1400, len(data)
            datagrams.append([m for m in gcs.rx.parse_buffer(data) or [] if m.get_type() != "BAD_DATA"])
    msgs = [m for d in datagrams for m in d]
    got = [m.text for m in msgs if m.get_type() == "STATUSTEXT"]
    assert got == texts  # every one, in order
    seqs = [m.get_seq() for m in msgs]
    assert all((b - a) % 256 == 1 for a, b in itertools.pairwise(seqs)), seqs  # none lost between
    assert any(len(d) > 1 for d in datagrams)
    assert sum(1 for m in msgs if m.get_type() == "SYSTEM_TIME") >= 90
    assert ep.stats["tx_dropped"] == 0


def test_a_write_that_fails_counts_each_message_it_carried_as_dropped(setup: Any) -> None:
    v, proto, gcs = setup
    ep = proto.endpoint
    _hello(v, gcs)
    (peer,) = ep.peers()
    peer._sender = lambda data: False  # the socket refuses every write (full, or the peer gone)
    tx, dropped = ep.stats["tx"], ep.stats["tx_dropped"]
    ep.periodic.append(lambda: [ep.statustext(6, f"lost {i}") for i in range(3)])
    ep.telemetry()  # one gathered write of at least the three texts
    assert ep.stats["tx"] == tx and ep.stats["tx_dropped"] - dropped >= 3
    ep.periodic.pop()
    before = ep.stats["tx_dropped"]
    ep.statustext(6, "outside a telemetry call: one write")
    assert ep.stats["tx_dropped"] == before + 1
