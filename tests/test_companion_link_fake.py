"""The companion's MAVLink link against a scripted fake ArduCopter (tests/fake_autopilot_support.py).

Behavior the model cannot easily be made to show: no SET_MESSAGE_INTERVAL support (the link falls back
to REQUEST_DATA_STREAM) and a command that is never ACKed (retries, then an error). Real MAVLink 2 over
loopback UDP; the link only sends from ``periodic()``, which these tests call every ~20 ms.
"""

from __future__ import annotations

import socket
from collections.abc import Callable, Iterator
from itertools import pairwise
from typing import Any

import pytest

from companion.link import CommandState
from companion.link.connection import FALLBACK_GROUPS, MavlinkLink, stream_plan
from harness.fake_autopilot import GUIDED, STABILIZE, FakeAutopilot, M
from harness.timing import wait_for

pytestmark = pytest.mark.integration

RATE_HZ = 20.0


def pump(link: MavlinkLink, pred: Callable[[], Any], timeout_s: float, what: str) -> Any:
    """Drive ``link.periodic`` every ~20 ms until ``pred`` holds (AssertionError at the deadline)."""
    def step() -> Any:
        link.periodic(link.clock.now())
        return pred()

    return wait_for(step, timeout_s, what, poll_s=0.02)


@pytest.fixture
def connect() -> Iterator[Callable[[FakeAutopilot], MavlinkLink]]:
    links: list[MavlinkLink] = []

    def make(fake: FakeAutopilot) -> MavlinkLink:
        link = MavlinkLink(f"udpout:127.0.0.1:{fake.port}", rate_hz=RATE_HZ)
        link.start()
        links.append(link)
        return link

    yield make
    for link in links:
        link.close()


def test_falls_back_to_request_data_stream_without_message_interval(connect: Any) -> None:
    with FakeAutopilot(message_interval_supported=False) as fake:
        fake.position = (3.0, -2.0, 0.0)
        link = connect(fake)
        pump(link, lambda: len(fake.data_stream_requests) >= len(FALLBACK_GROUPS)
             and link.mirror.snapshot().position is not None, 15.0, "REQUEST_DATA_STREAMs and a position")

        tried = fake.commands(M.MAV_CMD_SET_MESSAGE_INTERVAL)
        assert tried and {int(c.param1) for c in tried} == {M.MAVLINK_MSG_ID_LOCAL_POSITION_NED}
        assert (M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAV_RESULT_UNSUPPORTED) in fake.acks
        # one request per ArduCopter group, started; POSITION (LOCAL_POSITION_NED) at the link's rate
        expected = {M.MAV_DATA_STREAM_POSITION: 20, M.MAV_DATA_STREAM_EXTRA1: 10,
                    M.MAV_DATA_STREAM_EXTENDED_STATUS: 5, M.MAV_DATA_STREAM_EXTRA3: 2,
                    M.MAV_DATA_STREAM_RC_CHANNELS: 10}
        assert {g for g, _ in FALLBACK_GROUPS} == set(expected)
        got = [(r.stream_id, r.rate_hz, r.start) for r in fake.data_stream_requests]
        assert got == [(g, expected[g], True) for g, _ in FALLBACK_GROUPS]
        for r in fake.messages("REQUEST_DATA_STREAM"):
            assert (r.msg.target_system, r.msg.target_component) == (1, 1)
        assert link.streams_mode == "data_stream"
        snap = link.mirror.snapshot()
        assert snap.position == pytest.approx((3.0, -2.0, 0.0))
        assert fake.stream_intervals["LOCAL_POSITION_NED"] == pytest.approx(1 / 20)
        pump(link, lambda: link.mirror.snapshot().landed is True and link.mirror.snapshot().attitude,
             5.0, "EXTENDED_SYS_STATE and ATTITUDE from the groups")
        assert fake.count("REQUEST_DATA_STREAM") == len(FALLBACK_GROUPS)


def test_uses_set_message_interval_when_supported(connect: Any) -> None:
    plan = stream_plan(RATE_HZ)
    with FakeAutopilot() as fake:
        link = connect(fake)

        def requested() -> list[int]:
            ids: list[int] = []
            for c in fake.commands(M.MAV_CMD_SET_MESSAGE_INTERVAL):
                if not ids or ids[-1] != int(c.param1):  # a retry repeats the same message
                    ids.append(int(c.param1))
            return ids

        pump(link, lambda: len(requested()) == len(plan) and link.mirror.snapshot().home is not None
             and link.mirror.snapshot().position is not None, 15.0, "every stream requested")
        assert requested() == [msg_id for msg_id, _ in plan]  # one at a time, in order
        for msg_id, hz in plan:
            sent = [c for c in fake.commands(M.MAV_CMD_SET_MESSAGE_INTERVAL) if int(c.param1) == msg_id]
            assert all(c.param2 == pytest.approx(1e6 / hz) for c in sent)
            name = M.mavlink_map[msg_id].msgname
            assert fake.stream_intervals[name] == pytest.approx(1 / hz, rel=1e-3)
        assert [int(c.param1) for c in fake.commands(M.MAV_CMD_REQUEST_MESSAGE)][:1] == \
            [M.MAVLINK_MSG_ID_HOME_POSITION]
        # well past a command timeout: still no legacy request
        t_end = link.clock.now() + 1.5
        pump(link, lambda: link.clock.now() > t_end, 10.0, "1.5 s of autopilot time")
        assert link.streams_mode == "message_interval"
        assert fake.count("REQUEST_DATA_STREAM") == 0
        assert not link.commands.errors


def test_one_refused_stream_does_not_switch_to_the_legacy_requests(connect: Any) -> None:
    """An autopilot that knows SET_MESSAGE_INTERVAL but not one message (the model has no RC_CHANNELS;
    here ATTITUDE is refused) keeps the per-message intervals for the rest: falling back to
    REQUEST_DATA_STREAM would lose EXTENDED_SYS_STATE on ArduCopter (it is in no stream group)."""
    plan = stream_plan(RATE_HZ)
    refused = M.MAVLINK_MSG_ID_ATTITUDE
    with FakeAutopilot() as fake:
        fake.policy[M.MAV_CMD_SET_MESSAGE_INTERVAL] = (
            lambda m: M.MAV_RESULT_UNSUPPORTED if int(m.param1) == refused else M.MAV_RESULT_ACCEPTED)
        link = connect(fake)

        def requested() -> set[int]:
            return {int(c.param1) for c in fake.commands(M.MAV_CMD_SET_MESSAGE_INTERVAL)}

        pump(link, lambda: requested() == {msg_id for msg_id, _ in plan}, 15.0, "every stream requested")
        pump(link, lambda: link.mirror.snapshot().landed_state != 0, 5.0, "EXTENDED_SYS_STATE")
        assert link.streams_mode == "message_interval"
        assert fake.count("REQUEST_DATA_STREAM") == 0
        assert "ATTITUDE" not in fake.stream_intervals


def test_unacknowledged_command_is_retried_then_times_out(connect: Any) -> None:
    with FakeAutopilot(speedup=2.0) as fake:
        fake.ignore(M.MAV_CMD_DO_SET_MODE, times=10)
        link = connect(fake)
        pump(link, lambda: link.mirror.snapshot().position is not None and link.clock.synced, 15.0,
             "telemetry")
        req = link.set_mode(GUIDED, link.clock.now())
        pump(link, lambda: req.done, 20.0, "the command to finish")

        assert req.state is CommandState.TIMEOUT
        assert link.commands.errors[-1] == "MAV_CMD_DO_SET_MODE: no COMMAND_ACK after 3 attempts"
        sent = [r for r in fake.messages("COMMAND_LONG") if r.msg.command == M.MAV_CMD_DO_SET_MODE]
        assert [r.msg.confirmation for r in sent] == [0, 1, 2]
        assert all(int(r.msg.param2) == GUIDED for r in sent)
        timeout_s = link.commands.timeout_s
        gaps = [(b.time_boot_ms - a.time_boot_ms) / 1000.0 for a, b in pairwise(sent)]
        assert all(0.8 * timeout_s <= g <= 2.5 * timeout_s for g in gaps), gaps
        assert not any(cmd == M.MAV_CMD_DO_SET_MODE for cmd, _ in fake.acks)
        assert fake.mode == STABILIZE
        t_end = link.clock.now() + 1.5 * timeout_s  # and no fourth attempt
        pump(link, lambda: link.clock.now() > t_end, 10.0, "another timeout of autopilot time")
        assert len(fake.commands(M.MAV_CMD_DO_SET_MODE)) == 3


def test_a_malformed_datagram_is_counted_and_two_messages_in_one_datagram_both_arrive(connect: Any) -> None:
    """The UDP receive parses each datagram whole: garbage is counted as bad data and changes nothing,
    every message of a datagram that carries several reaches the mirror, and the link keeps listening."""
    ap = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    ap.bind(("127.0.0.1", 0))
    ap.settimeout(0.05)
    link = MavlinkLink(f"udpout:127.0.0.1:{ap.getsockname()[1]}", rate_hz=RATE_HZ)
    link.start()
    try:
        def heard() -> Any:  # the link's first heartbeat: where it listens
            try:
                return ap.recvfrom(2048)[1]
            except TimeoutError:
                return None
        to = pump(link, heard, 10.0, "the companion's heartbeat")
        mav = M.MAVLink(None, srcSystem=1, srcComponent=1)
        hb = mav.heartbeat_encode(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                  M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, GUIDED, M.MAV_STATE_STANDBY,
                                  3).pack(mav)
        pos = mav.local_position_ned_encode(1000, 1.5, -2.5, -3.0, 0.0, 0.0, 0.0).pack(mav)
        # a MAVLink 2 start, a length and junk past the frame's end (no partial frame left waiting)
        ap.sendto(b"\xfd\x09" + b"garbage, not MAVLink at all" * 2, to)
        pump(link, lambda: link.stats["rx_bad"] >= 1, 10.0, "the garbage counted as bad data")
        assert link.target_system is None and link.mirror.snapshot().position is None  # nothing changed
        ap.sendto(hb + pos, to)
        pump(link, lambda: link.mirror.snapshot().position is not None, 10.0,
             lambda: f"both messages of one datagram: {link.stats}, {link.mirror.snapshot()}")
        assert link.target_system == 1 and link.connected
        assert tuple(link.mirror.snapshot().position)[:3] == pytest.approx((1.5, -2.5, -3.0))
        assert link.stats["rx"] == 2 and link.stats["rx_handler_error"] == 0
    finally:
        link.close()
        ap.close()
