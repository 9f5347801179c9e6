"""Unit tests of the companion's link pieces without an autopilot."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from companion.flight import Setpoint, SetpointKind
from companion.link import AutopilotClock, CommandState, CommandTracker, SyncTracker, parse_url, target_fields
from companion.link.mirror import PositionTargetEcho
from companion.link.setpoints import IGNORE_ACC, IGNORE_POS, IGNORE_VEL, IGNORE_YAW, IGNORE_YAW_RATE


class FakeWall:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_clock_follows_a_sped_up_autopilot_and_never_runs_away() -> None:
    wall = FakeWall()
    clock = AutopilotClock(wall=wall)
    assert not clock.synced
    for i in range(200):  # autopilot at 10x, samples every 5 ms wall, some 3 ms late
        wall.t = 100.0 + i * 0.005
        clock.observe(int(1000 * (5.0 + i * 0.05)), wall.t + (0.003 if i % 3 == 0 else 0.0))
    assert clock.synced and clock.rate == pytest.approx(10.0, rel=0.02)
    wall.t += 0.002
    assert clock.now() == pytest.approx(5.0 + 199 * 0.05 + 0.02, abs=0.005)
    assert clock.wall_until(clock.now() + 1.0) == pytest.approx(0.1, rel=0.05)
    wall.t += 10.0  # the autopilot went silent: time stops shortly after its last sample
    assert clock.now() <= 5.0 + 199 * 0.05 + 0.25 + 1e-9
    clock.observe(1000)  # it rebooted: the estimate restarts
    assert clock.resets == 1 and clock.now() == pytest.approx(1.0)


def test_command_retried_without_ack_then_error() -> None:
    sent: list[tuple[int, int]] = []
    tracker = CommandTracker(lambda c, conf, p: sent.append((c, conf)), timeout_s=1.0, attempts=3)
    req = tracker.request(400, (1,), 0.0)
    tracker.periodic(0.5)
    assert sent == [(400, 0)]
    tracker.periodic(1.0)
    tracker.periodic(2.0)
    assert sent == [(400, 0), (400, 1), (400, 2)]
    tracker.periodic(3.0)
    assert req.state is CommandState.TIMEOUT and "no COMMAND_ACK after 3 attempts" in tracker.errors[-1]
    ok = tracker.request(176, (1, 4), 3.0)
    tracker.on_ack(SimpleNamespace(command=176, result=0))
    assert ok.accepted and not tracker.pending
    denied = tracker.request(22, (), 3.0)
    tracker.on_ack(SimpleNamespace(command=22, result=2))
    assert denied.state is CommandState.REJECTED and "DENIED" in tracker.errors[-1]


def test_type_masks_as_arducopter_reads_them() -> None:
    sp = Setpoint(1.0, (1.0, 2.0, -3.0), (0.5, 0.0, 0.0), (0.1, 0.0, 0.0), 0.3, 0.1)
    f = target_fields(sp)
    assert f.type_mask == 0 and f.p == sp.p and f.v == sp.v and f.a == sp.a and f.yaw == 0.3
    fv = target_fields(Setpoint(1.0, (1, 2, 3), (1.0, 0.0, 0.2), (0, 0, 0), 0.3, 0.2, SetpointKind.VELOCITY))
    mask = fv.type_mask
    assert mask & IGNORE_POS == IGNORE_POS and mask & IGNORE_ACC == IGNORE_ACC and mask & IGNORE_YAW
    assert not mask & IGNORE_VEL and not mask & IGNORE_YAW_RATE and fv.v == (1.0, 0.0, 0.2)


def test_is_synced_from_the_echo() -> None:
    sync = SyncTracker()
    f = target_fields(Setpoint(0.0, (1.0, 2.0, -3.0), (0, 0, 0), (0, 0, 0), 0.0, 0.0))
    sync.sent(10.0, f)
    assert not sync.synced(10.0)
    sync.echo(PositionTargetEcho(10_050, 0, (5.0, 2.0, -3.0), (0, 0, 0)), 10.05)
    assert not sync.synced(10.05)  # echoes someone else's target
    sync.echo(PositionTargetEcho(10_100, 0, (1.0, 2.0, -3.0), (0, 0, 0)), 10.1)
    assert sync.synced(10.1)
    assert not sync.synced(12.0)  # stale


def test_is_synced_matches_an_echo_advanced_by_the_feed_forward() -> None:
    """ArduCopter integrates the pos-vel-accel target between our messages: at 5 m/s an echo 80 ms
    after the send is 0.4 m ahead of the sent position, and still the target we streamed."""
    sync = SyncTracker()
    f = target_fields(Setpoint(0.0, (10.0, 0.0, -5.0), (5.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0, 0.0))
    sync.sent(20.0, f)
    sync.echo(PositionTargetEcho(20_080, 0, (10.4, 0.0, -5.0), (5.0, 0.0, 0.0)), 20.08)
    assert sync.synced(20.08) and sync.last_error == pytest.approx(0.0, abs=1e-9)
    # the same echo without the advance (an autopilot stuck on the sent position) is not in sync ...
    stuck = SyncTracker()
    stuck.sent(20.0, f)
    stuck.echo(PositionTargetEcho(20_300, 0, (10.0, 0.0, -5.0), (5.0, 0.0, 0.0)), 20.3)
    assert not stuck.synced(20.3) and stuck.last_error == pytest.approx(1.5)
    # ... nor is an echo of an older target left behind by 1 m
    behind = SyncTracker()
    behind.sent(20.0, f)
    behind.echo(PositionTargetEcho(20_080, 0, (9.4, 0.0, -5.0), (5.0, 0.0, 0.0)), 20.08)
    assert not behind.synced(20.08)
    # acceleration is integrated too
    acc = SyncTracker()
    acc.sent(5.0, target_fields(Setpoint(0.0, (0.0, 0.0, -5.0), (1.0, 0.0, 0.0), (2.0, 0.0, 0.0), 0.0, 0.0)))
    acc.echo(PositionTargetEcho(5_500, 0, (0.75, 0.0, -5.0), (2.0, 0.0, 0.0)), 5.5)
    assert acc.synced(5.5)


@pytest.mark.parametrize(
    ("url", "expected"),
    [
        ("udpout:127.0.0.1:14550", ("udpout:127.0.0.1:14550", 57600)),
        ("udpin:0.0.0.0:14551", ("udpin:0.0.0.0:14551", 57600)),
        ("tcp:127.0.0.1:5760", ("tcp:127.0.0.1:5760", 57600)),
        ("serial:/dev/ttyACM0:921600", ("/dev/ttyACM0", 921600)),
        ("/dev/ttyUSB0", ("/dev/ttyUSB0", 57600)),
    ],
)
def test_urls(url: str, expected: tuple[str, int]) -> None:
    assert parse_url(url, 57600) == expected


def test_bad_url() -> None:
    with pytest.raises(ValueError, match="expected udpin"):
        parse_url("http://x", 57600)


@pytest.mark.parametrize("first_contact", [False, True])
def test_clock_rate_survives_a_stall_and_catch_up_burst(first_contact: bool) -> None:
    """A paced autopilot that stalls and then catches up in a burst (0.86 s of its time in 13 ms), later
    or at the companion's first contact (as the model does when a client first connects), must not
    leave the rate estimate inflated: an overestimate runs the companion's clock into its extrapolation
    cap, so setpoints are stamped ahead of the autopilot."""
    wall = FakeWall()
    clock = AutopilotClock(wall=wall)
    ap = 10.0

    def run(seconds: float) -> None:
        nonlocal ap
        for _ in range(round(seconds / 0.01)):  # 5x, a sample every 10 ms of wall time
            wall.t += 0.01
            ap += 0.05
            clock.observe(int(ap * 1000), wall.t)

    def burst(owed: float) -> None:
        nonlocal ap
        for _ in range(13):  # what the stall owed, 13 samples 1 ms apart
            wall.t += 0.001
            ap += owed / 13
            clock.observe(int(ap * 1000), wall.t)

    if first_contact:
        burst(0.86)
        run(0.5)  # no rate from the first 0.2 s, then a quarter second of samples
    else:
        run(1.0)
        assert clock.rate == pytest.approx(5.0, rel=0.02)
        wall.t += 0.15
        burst(0.75)
    for _ in range(20):  # every 0.1 s for the next 2 s
        run(0.1)
        assert clock.rate == pytest.approx(5.0, rel=0.06)
        assert clock.now() == pytest.approx(ap, abs=0.06)
