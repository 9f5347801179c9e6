"""Each channel mode of seed 000 Fig. 7 flown through the queue (external modes fed via the streams)."""

from __future__ import annotations

import itertools
import math

import pytest

from companion.flight import (
    CommandQueue,
    EndCondition,
    FlightCommand,
    HeadingChannel,
    HeadingMode,
    HorizontalChannel,
    HorizontalMode,
    VerticalChannel,
    VerticalMode,
)
from companion.flight.reference import wrap_pi
from companion.flight.simulate import FlightSim, step_violations
from harness.flight_sim import LIMITS, takeoff


def fly(*commands: FlightCommand) -> FlightSim:
    q = CommandQueue(LIMITS)
    for c in (takeoff(), *commands):
        q.add_command(c)
    sim = FlightSim(q, dt=0.05)
    sim.tick()
    q.run()
    sim.run_until(lambda s: s.queue.status().current_command_index >= 1, 20)
    return sim


def until_index(sim: FlightSim, i: int, timeout: float = 40.0) -> float:
    return sim.run_until(lambda s: s.queue.status().current_command_index >= i, timeout)


def test_ext_pos_follows_a_moving_target_with_offset_and_holds_when_stale() -> None:
    cmd = FlightCommand(
        HorizontalChannel(HorizontalMode.EXT_POS, offset_north=-2.0, speed=4.0),
        VerticalChannel(VerticalMode.EXT_POS, offset=3.0),
        end=EndCondition(e_user=True),
    )
    sim = fly(cmd)
    target = {"t0": sim.t, "on": True}

    def feed(s: FlightSim) -> None:
        if target["on"]:
            east = 1.0 * (s.t - target["t0"])  # walking east at 1 m/s
            s.queue.push_external("ext_pos", (10.0, east, -1.0), 0.5, s.t)

    sim.on_tick.append(feed)
    sim.run_for(25.0)
    east_now = 1.0 * (sim.t - target["t0"])
    assert sim.last.p[0] == pytest.approx(8.0, abs=0.05)
    assert sim.last.p[1] == pytest.approx(east_now, abs=1.2)  # lags a moving target a little
    assert -sim.last.p[2] == pytest.approx(4.0, abs=1e-6)
    target["on"] = False
    sim.run_for(5.0)
    held = sim.last.p
    sim.run_for(2.0)
    assert sim.last.p == held and sim.last.v == (0.0, 0.0, 0.0)
    assert step_violations(sim.setpoints, LIMITS) == []


def test_ext_pos_end_flag_and_keep_distance() -> None:
    ext = FlightCommand(HorizontalChannel(HorizontalMode.EXT_POS), end=EndCondition(e_h=True))
    keep = FlightCommand(
        HorizontalChannel(HorizontalMode.KEEP_DISTANCE, distance=4.0, speed=2.0), end=EndCondition(e_h=True)
    )
    sim = fly(ext, keep)
    sim.on_tick.append(lambda s: s.queue.push_external("ext_pos", (6.0, 8.0, -5.0), 1.0, s.t))
    until_index(sim, 2)
    assert math.dist(sim.last.p[:2], (6.0, 8.0)) <= LIMITS.arrival_tolerance
    sim.on_tick[-1] = lambda s: s.queue.push_external("ext_pos", (0.0, 0.0, -5.0), 1.0, s.t)
    until_index(sim, 3)
    assert math.hypot(*sim.last.p[:2]) == pytest.approx(4.0, abs=LIMITS.arrival_tolerance)


def test_heading_ext_pos_and_ext_point() -> None:
    ext_heading = FlightCommand(
        heading=HeadingChannel(HeadingMode.EXT_POS, offset=10.0, speed=30.0), end=EndCondition(e_hd=True)
    )
    ext_point = FlightCommand(
        heading=HeadingChannel(HeadingMode.EXT_POINT, offset=-90.0), end=EndCondition(e_hd=True)
    )
    sim = fly(ext_heading, ext_point)
    sim.on_tick.append(lambda s: s.queue.push_external("ext_heading", (80.0,), 1.0, s.t))
    sim.on_tick.append(lambda s: s.queue.push_external("ext_point", (0.0, -10.0), 1.0, s.t))
    until_index(sim, 2)
    assert abs(wrap_pi(sim.last.yaw - math.radians(90))) <= math.radians(LIMITS.heading_tolerance)
    assert max(abs(sp.yaw_rate) for sp in sim.setpoints) <= math.radians(30) + 1e-9
    until_index(sim, 3)
    # bearing to (0, -10) is -90 deg; with the -90 deg offset: 180 deg
    assert abs(wrap_pi(sim.last.yaw - math.pi)) <= math.radians(LIMITS.heading_tolerance)


def test_heading_pos_without_stop_keeps_turning_and_raises_the_flag_when_passing() -> None:
    spin = FlightCommand(
        heading=HeadingChannel(HeadingMode.POS, heading=90, rate=45, stop_at_heading=False),
        end=EndCondition(e_hd=True, e_user=True),
    )
    sim = fly(spin)
    sim.run_for(1.0)
    assert sim.queue.status().current_command_index != 2
    sim.run_for(2.5)  # 45 deg/s, reaches 90 deg after about 2.3 s
    yaw_then = sim.last.yaw
    sim.run_for(1.0)
    assert sim.last.yaw_rate == pytest.approx(math.radians(45))
    assert wrap_pi(sim.last.yaw - yaw_then) == pytest.approx(math.radians(45), abs=1e-6)
    sim.queue.user_confirm()  # Hd_end has been raised (passed 90 deg): the conjunction now holds
    assert sim.queue.status().current_command_index == 2
    sim.run_for(3.0)
    assert sim.last.yaw_rate == 0.0  # comes to rest smoothly afterwards


def test_body_relative_and_relative_targets_resolve_at_start_and_survive_a_pause() -> None:
    turn = FlightCommand(heading=HeadingChannel(HeadingMode.POS, heading=90), end=EndCondition(e_hd=True))
    forward = FlightCommand(
        HorizontalChannel(HorizontalMode.POS, north=10, east=2, frame="body_relative"),
        VerticalChannel(VerticalMode.POS, altitude=3, frame="relative"),
        end=EndCondition(e_h=True, e_v=True),
    )
    sim = fly(turn, forward)
    until_index(sim, 2)
    assert sim.last.yaw == pytest.approx(math.pi / 2)
    sim.run_for(1.5)
    sim.queue.pause_direct()
    sim.run_for(3.0)
    sim.queue.run()
    until_index(sim, 3)
    # forward = east, right = south; relative altitude from the 5 m the command started at
    assert sim.last.p == pytest.approx((-2.0, 10.0, -8.0), abs=1e-9)


@pytest.mark.parametrize("yaw_deg", [30.0, 135.0, -60.0, 0.0])
def test_body_relative_target_is_forward_and_right_of_any_heading(yaw_deg: float) -> None:
    """forward 10, right 2 of the heading the command starts with, at headings that tell sine from
    cosine and both signs apart (90 degrees alone does not)."""
    turn = FlightCommand(heading=HeadingChannel(HeadingMode.POS, heading=yaw_deg),
                         end=EndCondition(e_hd=True))
    forward = FlightCommand(
        HorizontalChannel(HorizontalMode.POS, north=10, east=2, frame="body_relative"),
        end=EndCondition(e_h=True),
    )
    sim = fly(turn, forward)
    until_index(sim, 2)
    start = sim.last.p
    until_index(sim, 3)
    y = math.radians(yaw_deg)
    expected = (start[0] + 10 * math.cos(y) - 2 * math.sin(y), start[1] + 10 * math.sin(y) + 2 * math.cos(y))
    assert sim.last.p[:2] == pytest.approx(expected, abs=1e-9)


def test_e_any_ends_with_the_first_channel() -> None:
    cmd = FlightCommand(
        HorizontalChannel(HorizontalMode.POS, north=3, east=0),
        VerticalChannel(VerticalMode.POS, altitude=15),
        end=EndCondition(e_any=True),
    )
    sim = fly(cmd)
    until_index(sim, 2)
    assert sim.last.p[0] == 3.0 and -sim.last.p[2] < 15.0


def test_rc_velocity_is_the_rc_vel_stream() -> None:
    cmd = FlightCommand(
        HorizontalChannel(HorizontalMode.RC_VEL),
        VerticalChannel(VerticalMode.RC_VEL),
        HeadingChannel(HeadingMode.RC_VEL),
        EndCondition(e_user=True),
    )
    sim = fly(cmd)
    sim.on_tick.append(lambda s: s.queue.push_external("ext_vel", (3.0, 0.0, 0.0, 0.0), 0.5, s.t))
    sim.run_for(2.0)
    assert sim.last.v == (0.0, 0.0, 0.0)  # ext_vel is not the RC
    sim.on_tick.append(lambda s: s.queue.push_external("rc_vel", (0.0, -1.0, 0.0, 0.0), 0.5, s.t))
    sim.run_for(3.0)
    assert sim.last.v == pytest.approx((0.0, -1.0, 0.0), abs=1e-9)


def test_flight_direction_with_heading_modifier_turns_before_speeding_up() -> None:
    cmd = FlightCommand(
        HorizontalChannel(HorizontalMode.POS, north=0, east=-20, speed_modified_by=["heading"]),
        heading=HeadingChannel(HeadingMode.FLIGHT_DIR),
        end=EndCondition(e_h=True),
    )
    sim = fly(cmd)
    t0 = sim.t
    until_index(sim, 2)
    assert sim.last.p[:2] == (0.0, -20.0)
    assert wrap_pi(sim.last.yaw + math.pi / 2) == pytest.approx(0.0, abs=math.radians(1))
    leg = [sp for sp in sim.setpoints if sp.t_s > t0]
    for prev, sp in itertools.pairwise(leg):  # Hd_sm: speed <= speed * cos(heading error)
        err = abs(wrap_pi(prev.yaw + math.pi / 2))
        assert (
            math.hypot(*sp.v[:2])
            <= LIMITS.horizontal_speed * max(0.05, math.cos(min(err, math.pi / 2))) + 1e-6
        )
    assert any(abs(wrap_pi(sp.yaw + math.pi / 2)) > math.radians(60) for sp in leg)
    assert step_violations(sim.setpoints, LIMITS) == []
