"""The GuidedSupervisor through a QuadNode against the scripted fake ArduCopter, and the RC stick mapping.

Each flight test starts its own :class:`FakeAutopilot` (real MAVLink 2 over loopback UDP, its clock
``SPEEDUP`` times the wall's) and its own :class:`QuadNode`, scripts the fake (refusals, missing ACKs,
a take-off that does not climb, RC sticks) and checks what reached the fake: the COMMAND_LONGs, their
spacing on the fake's clock (``time_boot_ms`` at arrival), the SET_POSITION_TARGET_LOCAL_NED stream,
and the queue's status and events. Deadlines are wall time derived from autopilot durations; there
are no sleeps. The RC tests at the end are pure unit tests of :mod:`companion.link.rc`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from itertools import pairwise
from typing import Any

import pytest

from companion.builder import CompanionConfig, build_companion
from companion.flight import Limits
from companion.flight import command_from_dict as cmd
from companion.flight.events import EventKind
from companion.flight.qapi import CommandStatus, QueueState
from companion.flight.setpoint import Setpoint
from companion.link import GuidedSupervisor, MavlinkLink, Phase, guided
from companion.link.rc import RcMapping, rc_velocity
from companion.link.setpoints import MASK_VELOCITY
from companion.node import QuadNode
from harness.fake_autopilot import GUIDED, LAND, FakeAutopilot, M, Received
from harness.timing import wait_for

pytestmark = pytest.mark.integration

SPEEDUP = 5.0
ARM = M.MAV_CMD_COMPONENT_ARM_DISARM
TAKEOFF_CMD = M.MAV_CMD_NAV_TAKEOFF
SET_MODE = M.MAV_CMD_DO_SET_MODE
TAKEOFF_ALT = 2.0
TAKEOFF = {"vertical": {"mode": "POS", "altitude": TAKEOFF_ALT, "take_off": True}, "end": {"e_v": True}}
LAND_HERE = {"vertical": {"mode": "POS", "altitude": 0.0, "allow_landing": True}, "end": {"e_v": True}}
RC_VEL = {"horizontal": {"mode": "RC_VEL"}, "vertical": {"mode": "RC_VEL"}, "heading": {"mode": "RC_VEL"},
          "end": {"e_user": True}}
#: RC_CHANNELS indices (0-based) of ArduPilot's default RCMAP
ROLL, PITCH, THROTTLE, YAW = 0, 1, 2, 3


def wall(autopilot_s: float) -> float:
    """A wall deadline for ``autopilot_s`` of the fake's time, with room for a loaded machine."""
    return autopilot_s / SPEEDUP + 5.0


class ScriptedFake(FakeAutopilot):
    """The fake plus two scripts its policies cannot express.

    ``grounded_takeoffs``: that many accepted NAV_TAKEOFFs do not climb (ArduCopter spooling up its
    motors: ACCEPTED, still on the ground). ``rc_rssi`` / ``rc_silent``: the RC receiver's RSSI in
    RC_CHANNELS, or no RC_CHANNELS at all.
    """

    def __init__(self, **kw: Any) -> None:
        super().__init__(**kw)
        self.grounded_takeoffs = 0
        self.rc_rssi = 255
        self.rc_silent = False

    def _effect(self, m: Any) -> int:
        if m.command == TAKEOFF_CMD and self.grounded_takeoffs > 0 \
                and self.armed and self.landed and self.mode == GUIDED and m.param7 > 0:
            self.grounded_takeoffs -= 1
            return M.MAV_RESULT_ACCEPTED
        return super()._effect(m)

    def _rc_channels(self) -> Any:
        if self.rc_silent:
            return None
        return M.MAVLink_rc_channels_message(self.time_boot_ms, 16, *list(self.rc)[:18], self.rc_rssi)


Fly = Callable[..., tuple[ScriptedFake, QuadNode]]


@pytest.fixture
def fly() -> Iterator[Fly]:
    """``fly(**fake_kw)``: a started fake and a node connected to it, the node's telemetry complete."""
    opened: list[Any] = []

    def make(**kw: Any) -> tuple[ScriptedFake, QuadNode]:
        kw.setdefault("speedup", SPEEDUP)
        fake = ScriptedFake(**kw)
        opened.append(fake)
        fake.start()
        companion = build_companion(CompanionConfig(f"udpout:127.0.0.1:{fake.port}", behaviors=False,
                                                    control_port=None))
        node = companion.node
        opened.append(companion)
        companion.start()

        def ready() -> bool:
            s = node.link.mirror.snapshot()
            return node.clock.synced and s.position is not None and s.global_position is not None \
                and s.home is not None and s.landed is True and s.rc is not None \
                and s.attitude is not None
        wait_for(ready, wall(15.0), "the node's telemetry (position, home, landed state, RC, attitude)")
        return fake, node

    yield make
    for thing in reversed(opened):  # the node before its fake
        thing.close()


def sent(fake: FakeAutopilot, command: int) -> list[Received]:
    """The COMMAND_LONGs ``command`` the fake received, with their arrival on its clock."""
    return [r for r in fake.messages("COMMAND_LONG") if r.msg.command == command]


def arms(fake: FakeAutopilot) -> list[Received]:
    return [r for r in sent(fake, ARM) if round(r.msg.param1) == 1]


def disarms(fake: FakeAutopilot) -> list[Received]:
    return [r for r in sent(fake, ARM) if round(r.msg.param1) == 0]


def land_requests(fake: FakeAutopilot) -> list[Received]:
    return [r for r in sent(fake, SET_MODE) if round(r.msg.param2) == LAND]


def gaps_s(received: list[Received]) -> list[float]:
    return [(b.time_boot_ms - a.time_boot_ms) / 1000.0 for a, b in pairwise(received)]


def acks(fake: FakeAutopilot, command: int) -> list[int]:
    return [result for c, result in list(fake.acks) if c == command]


def autopilot_wait(fake: FakeAutopilot, seconds: float) -> None:
    """Let ``seconds`` of the fake's time pass (a condition on its clock, not a sleep)."""
    end = fake.time_boot_ms + seconds * 1000.0
    wait_for(lambda: fake.time_boot_ms >= end, wall(seconds), f"{seconds:g} s of autopilot time")


def take_off(fake: ScriptedFake, node: QuadNode, altitude: float = TAKEOFF_ALT) -> int:
    """Queue and run a take-off; returns its id once it finished with the vehicle airborne in GUIDED."""
    data = {**TAKEOFF, "vertical": {**TAKEOFF["vertical"], "altitude": altitude}}
    cid = node.add_command(cmd(data))
    node.run()
    assert node.queue.events.wait_for(cid, {EventKind.FINISHED}, wall(30.0)) is not None, \
        f"take-off not finished: {node.status()['flight']}"
    assert fake.mode == GUIDED and fake.armed and not fake.landed
    return cid


# --- the take-off sequence --------------------------------------------------------------------------------
def test_arming_refused_twice_is_retried_after_the_pause_then_takes_off(fly: Fly) -> None:
    fake, node = fly()
    fake.refuse(ARM, times=2)
    cid = node.add_command(cmd(TAKEOFF))
    node.run()
    wait_for(lambda: node.supervisor.phase is Phase.ENGAGED, wall(30.0), "airborne after two refusals")
    wait_for(lambda: fake.setpoints(), wall(2.0), "setpoints streamed after lift-off")
    assert node.queue.events.wait_for(cid, {EventKind.FINISHED}, wall(20.0)) is not None
    assert fake.mode == GUIDED and fake.armed and not fake.landed

    tries = arms(fake)
    assert len(tries) == 3, [(r.msg.confirmation, r.time_boot_ms) for r in tries]
    assert acks(fake, ARM) == [M.MAV_RESULT_FAILED, M.MAV_RESULT_FAILED, M.MAV_RESULT_ACCEPTED]
    # each a new request of the supervisor after RETRY_PAUSE_S (not the command protocol's ACK-less retry)
    assert [r.msg.confirmation for r in tries] == [0, 0, 0]
    gaps = gaps_s(tries)
    assert all(0.9 * guided.RETRY_PAUSE_S <= g <= 2.5 * guided.RETRY_PAUSE_S for g in gaps), gaps
    refusals = [e for e in node.supervisor.errors if e.startswith("take-off arm") and "FAILED" in e]
    assert len(refusals) == 2, list(node.supervisor.errors)
    (takeoff,) = sent(fake, TAKEOFF_CMD)  # once, after the accepted arming
    assert takeoff.time_boot_ms >= tries[-1].time_boot_ms
    assert acks(fake, TAKEOFF_CMD) == [M.MAV_RESULT_ACCEPTED]
    st = node.queue.status()
    assert st.failure is None and st.queue_status is QueueState.RUNNING


def test_arming_always_refused_gives_up_at_the_deadline_and_run_tries_again(
        fly: Fly, monkeypatch: pytest.MonkeyPatch) -> None:
    deadline = 3.0
    monkeypatch.setitem(guided.STEP_DEADLINE_S, "arm", deadline)
    fake, node = fly()
    fake.refuse(ARM, times=10**6)
    cid = node.add_command(cmd(TAKEOFF))
    node.run()
    failed = node.queue.events.wait_for(cid, {EventKind.FAILED}, wall(deadline + 10.0))
    assert failed is not None, f"no FAILED event: {node.status()['flight']}"
    failed_at = fake.time_boot_ms

    st = node.queue.status()
    assert st.current_command_status is CommandStatus.FAILED
    assert st.current_command_id == cid and st.current_command_index == 0
    assert st.queue_status is QueueState.STOPPED
    assert st.failure is not None and "step 'arm'" in st.failure, st.failure
    assert "FAILED" in st.failure, st.failure  # the autopilot's last answer
    assert failed.detail == st.failure
    tries = arms(fake)
    # retried every RETRY_PAUSE_S until the step's deadline, then given up
    assert len(tries) >= math.floor(deadline / guided.RETRY_PAUSE_S), gaps_s(tries)
    assert all(g >= 0.9 * guided.RETRY_PAUSE_S for g in gaps_s(tries)), gaps_s(tries)
    assert (failed_at - tries[0].time_boot_ms) / 1000.0 >= deadline - 0.1
    assert (tries[-1].time_boot_ms - tries[0].time_boot_ms) / 1000.0 <= deadline + 0.1
    wait_for(lambda: node.supervisor.phase is Phase.IDLE, wall(2.0), "supervisor IDLE")

    # given up for good: no more arming, never a take-off, nothing streamed
    n_arms = len(arms(fake))
    autopilot_wait(fake, 2.0 * guided.RETRY_PAUSE_S)
    assert len(arms(fake)) == n_arms
    assert node.queue.status().current_command_status is CommandStatus.FAILED
    assert sent(fake, TAKEOFF_CMD) == []
    assert fake.setpoints() == [] and node.streamed == 0
    assert not fake.armed

    # run() clears the failure and tries the take-off again (and gives it up again at the deadline)
    node.run()
    st = node.queue.status()
    assert st.failure is None and st.current_command_status is CommandStatus.RUNNING
    wait_for(lambda: len(arms(fake)) > n_arms, wall(5.0), "arming requested again after run()")
    wait_for(lambda: len([e for e in node.queue.events.since(failed.seq)
                          if e.kind is EventKind.FAILED and e.command_id == cid]) == 1,
             wall(deadline + 10.0), "the second attempt given up too")
    assert sent(fake, TAKEOFF_CMD) == [] and fake.setpoints() == []


def test_accepted_takeoff_is_not_resent_while_the_vehicle_spools_up(fly: Fly) -> None:
    fake, node = fly()
    fake.grounded_takeoffs = 1  # the first NAV_TAKEOFF is accepted but nothing climbs
    node.add_command(cmd(TAKEOFF))
    node.run()
    wait_for(lambda: sent(fake, TAKEOFF_CMD), wall(20.0), "the first NAV_TAKEOFF")
    first = sent(fake, TAKEOFF_CMD)[0]
    wait_for(lambda: len(sent(fake, TAKEOFF_CMD)) >= 2, wall(guided.LIFTOFF_TIMEOUT_S + 5.0),
             "NAV_TAKEOFF sent again after LIFTOFF_TIMEOUT_S")
    second = sent(fake, TAKEOFF_CMD)[1]
    waited = (second.time_boot_ms - first.time_boot_ms) / 1000.0
    # not again before LIFTOFF_TIMEOUT_S (ArduCopter would answer FAILED), but soon after it
    assert guided.LIFTOFF_TIMEOUT_S - 0.1 <= waited <= guided.LIFTOFF_TIMEOUT_S + 1.5, waited
    assert waited > guided.STATE_TIMEOUT_S + 1.0
    assert [r.msg.confirmation for r in (first, second)] == [0, 0]
    assert second.msg.param7 == pytest.approx(first.msg.param7)
    # the second one climbs: airborne, streaming, no third take-off
    wait_for(lambda: node.supervisor.phase is Phase.ENGAGED, wall(10.0), "airborne")
    wait_for(lambda: fake.setpoints(), wall(2.0), "setpoints streamed after lift-off")
    assert len(sent(fake, TAKEOFF_CMD)) == 2
    streamed = fake.messages("SET_POSITION_TARGET_LOCAL_NED")
    assert all(r.time_boot_ms >= second.time_boot_ms for r in streamed), "streamed before lift-off"
    assert acks(fake, TAKEOFF_CMD) == [M.MAV_RESULT_ACCEPTED, M.MAV_RESULT_ACCEPTED]
    assert list(node.supervisor.errors) == []  # nothing refused, nothing given up


@pytest.mark.parametrize("home_offset_m", [2.0, -1.5])
def test_takeoff_altitude_is_sent_above_home(fly: Fly, home_offset_m: float) -> None:
    target = 3.0
    fake, node = fly(home_offset_m=home_offset_m)
    s = node.link.mirror.snapshot()
    # the fake: relative_alt = -z + home_offset_m, so home is home_offset_m below the local origin
    assert s.global_position is not None and s.position is not None
    assert s.global_position[3] == pytest.approx(-s.position[2] + home_offset_m, abs=2e-3)
    node.add_command(cmd({**TAKEOFF, "vertical": {**TAKEOFF["vertical"], "altitude": target}}))
    node.run()
    wait_for(lambda: sent(fake, TAKEOFF_CMD), wall(20.0), "NAV_TAKEOFF")
    (takeoff,) = sent(fake, TAKEOFF_CMD)
    # home's height in the local frame is -home_offset_m: target - (-home_offset_m) above home
    expected = target + home_offset_m
    assert takeoff.msg.param7 == pytest.approx(expected, abs=5e-3)
    assert node.supervisor.status()["takeoff_altitude_above_home"] == pytest.approx(expected, abs=5e-3)


def test_stop_while_arming_is_outstanding_disarms_what_then_arms(fly: Fly) -> None:
    fake, node = fly()
    fake.ignore(ARM, times=2)  # the first two attempts unanswered: the third arms the vehicle
    cid = node.add_command(cmd(TAKEOFF))
    node.run()
    wait_for(lambda: arms(fake), wall(20.0), "the arm request")
    node.stop()
    assert not fake.armed and "MAV_CMD_COMPONENT_ARM_DISARM" in node.link.commands.pending
    st = node.queue.status()
    assert st.deferred is None, "stop() deferred although the take-off has not left the ground"
    assert st.queue_status is QueueState.STOPPED and st.current_command_status is CommandStatus.STOPPED

    wait_for(lambda: disarms(fake), wall(10.0), "the disarm of the cancelled take-off")
    wait_for(lambda: not fake.armed and node.supervisor.phase is Phase.IDLE, wall(5.0),
             "disarmed on the ground, supervisor IDLE")
    assert_disarmed_what_then_armed(fake)
    # and it stays so
    n = len(sent(fake, ARM))
    autopilot_wait(fake, 2.0 * guided.RETRY_PAUSE_S)
    assert len(sent(fake, ARM)) == n and not fake.armed and node.supervisor.phase is Phase.IDLE
    st = node.queue.status()
    assert st.current_command_id == cid and st.failure is None
    assert st.current_command_status is CommandStatus.STOPPED
    assert [e.kind for e in node.queue.events.since(0) if e.command_id == cid][-1] is EventKind.STOPPED


def assert_disarmed_what_then_armed(fake: ScriptedFake) -> None:
    tries = arms(fake)
    assert [r.msg.confirmation for r in tries] == [0, 1, 2]  # the outstanding request's retries
    assert acks(fake, ARM)[0] == M.MAV_RESULT_ACCEPTED  # the third attempt armed the vehicle ...
    first_disarm = disarms(fake)[0]
    assert first_disarm.time_boot_ms >= tries[-1].time_boot_ms  # ... and was undone
    assert M.MAV_RESULT_ACCEPTED in acks(fake, ARM)[1:]
    assert sent(fake, TAKEOFF_CMD) == [] and fake.setpoints() == []
    assert fake.landed and not fake.armed


def test_supervisor_cancelled_while_arming_disarms_what_then_arms() -> None:
    """The supervisor's own part of the above, driven tick by tick as the node would (no queue)."""
    with ScriptedFake(speedup=SPEEDUP) as fake:
        link = MavlinkLink(f"udpout:127.0.0.1:{fake.port}")
        link.start()
        try:
            sup = GuidedSupervisor(link)
            takeoff_sp = Setpoint(0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0, 0.0,
                                  take_off=True, takeoff_altitude=TAKEOFF_ALT, command_index=0, command_id=1)
            idle_sp = Setpoint(0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0, 0.0)
            wanted = [True]
            streamed: list[float] = []

            def tick() -> bool:
                now = link.clock.now()
                link.periodic(now)
                s = link.mirror.snapshot()
                if not link.clock.synced or s.position is None or s.landed is None:
                    return False
                sup.observe(s)
                if sup.holds_queue:
                    sup.step_takeoff(wanted[0], s, now)
                elif sup.step(takeoff_sp if wanted[0] else idle_sp, s, now):
                    streamed.append(now)
                return True

            def pump(pred: Callable[[], Any], autopilot_s: float, what: str) -> None:
                wait_for(lambda: tick() and pred(), wall(autopilot_s), what, poll_s=0.01)

            fake.ignore(ARM, times=2)
            pump(lambda: arms(fake), 20.0, "the arm request")
            assert sup.phase is Phase.TAKING_OFF and not fake.armed
            wanted[0] = False  # the queue no longer executes the take-off
            tick()
            assert sup.phase is Phase.CANCELLING
            pump(lambda: disarms(fake) and not fake.armed and sup.phase is Phase.IDLE, 15.0,
                 "the vehicle armed by the outstanding request disarmed again, supervisor IDLE")
            assert_disarmed_what_then_armed(fake)
            assert streamed == []
            n = len(sent(fake, ARM))
            end = fake.time_boot_ms + 2000.0 * guided.RETRY_PAUSE_S
            pump(lambda: fake.time_boot_ms >= end, 2.0 * guided.RETRY_PAUSE_S, "two retry pauses")
            assert len(sent(fake, ARM)) == n and not fake.armed and sup.phase is Phase.IDLE
        finally:
            link.close()


# --- landing ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("answer", ["refused", "unacknowledged"])
def test_land_is_asked_again_until_the_mode_shows_land(fly: Fly, answer: str) -> None:
    fake, node = fly()
    take_off(fake, node)
    if answer == "refused":
        fake.refuse(SET_MODE, times=1)
    else:
        fake.ignore(SET_MODE, times=1)
    node.add_command(cmd(LAND_HERE))
    wait_for(lambda: fake.mode == LAND, wall(20.0), "LAND mode")
    wait_for(lambda: fake.landed and not fake.armed and node.supervisor.phase is Phase.IDLE, wall(15.0),
             "landed, disarmed, supervisor IDLE")
    tries = land_requests(fake)
    assert len(tries) == 2, [(r.msg.confirmation, r.time_boot_ms) for r in tries]
    if answer == "refused":
        assert acks(fake, SET_MODE)[-2:] == [M.MAV_RESULT_FAILED, M.MAV_RESULT_ACCEPTED]
        assert [r.msg.confirmation for r in tries] == [0, 0]  # the supervisor asked again
        assert any(e.startswith("land:") and "FAILED" in e for e in node.supervisor.errors), \
            list(node.supervisor.errors)
    else:  # the command protocol's retry of the same request
        assert acks(fake, SET_MODE)[-1] == M.MAV_RESULT_ACCEPTED
        assert [r.msg.confirmation for r in tries] == [0, 1]
        assert gaps_s(tries)[0] >= 0.9 * node.link.commands.timeout_s
    n = len(land_requests(fake))
    autopilot_wait(fake, 2.0 * guided.RETRY_PAUSE_S)
    assert len(land_requests(fake)) == n and fake.mode == LAND and not fake.armed


def test_refused_land_is_retried_after_the_retry_pause(fly: Fly) -> None:
    fake, node = fly()
    take_off(fake, node)
    fake.refuse(SET_MODE, times=1)
    node.add_command(cmd(LAND_HERE))
    wait_for(lambda: len(land_requests(fake)) >= 2, wall(20.0), "LAND asked again")
    gap = gaps_s(land_requests(fake)[:2])[0]
    assert gap >= 0.9 * guided.RETRY_PAUSE_S, f"LAND re-sent {gap:.3f} s after the refusal"


# --- RC_VEL: the pilot's sticks through RC_CHANNELS ------------------------------------------------------
def velocity_setpoints_after(fake: FakeAutopilot, t_ms: int) -> list[Received]:
    return [r for r in fake.messages("SET_POSITION_TARGET_LOCAL_NED")
            if r.time_boot_ms >= t_ms and r.msg.type_mask == MASK_VELOCITY]


def wait_velocity(fake: FakeAutopilot, want: tuple[float, float, float], what: str, tol: float = 0.05,
                  autopilot_s: float = 8.0) -> Received:
    """The first velocity-only setpoint (sent from now on) within ``tol`` of ``want`` (vx, vy, vz)."""
    t0 = fake.time_boot_ms

    def reached() -> Received | None:
        for r in velocity_setpoints_after(fake, t0):
            if max(abs(r.msg.vx - want[0]), abs(r.msg.vy - want[1]), abs(r.msg.vz - want[2])) <= tol:
                return r
        return None
    return wait_for(reached, wall(autopilot_s), what)


def test_rc_vel_flies_the_sticks_relative_to_the_heading(fly: Fly) -> None:
    fake, node = fly()
    take_off(fake, node)
    speed, climb = node.queue.limits.horizontal_speed, node.queue.limits.vertical_speed
    cid = node.add_command(cmd(RC_VEL))
    wait_for(lambda: node.queue.status().confirmation_required_status, wall(5.0), "RC_VEL running")

    fake.rc[PITCH] = 1100  # full forward, facing north
    wait_velocity(fake, (speed, 0.0, 0.0), "full speed north")
    fake.yaw = math.pi / 2  # the same stick facing east
    wait_velocity(fake, (0.0, speed, 0.0), "full speed east")
    fake.rc[ROLL] = 1900  # right of east is south: the diagonal is no faster than the limit
    r = wait_velocity(fake, (-speed / math.sqrt(2), speed / math.sqrt(2), 0.0), "south-east at the limit")
    assert math.hypot(r.msg.vx, r.msg.vy) <= speed + 0.05
    fake.rc[PITCH], fake.rc[ROLL] = 1520, 1480  # centred, inside the deadband
    wait_velocity(fake, (0.0, 0.0, 0.0), "stopped with the sticks centred")
    fake.rc[THROTTLE] = 1900  # throttle up climbs (NED: vz < 0)
    r = wait_velocity(fake, (0.0, 0.0, -climb), "climbing at the vertical limit")
    fake.rc[THROTTLE], fake.rc[YAW] = 1500, 1900  # yaw right: clockwise at the yaw-rate limit
    wait_velocity(fake, (0.0, 0.0, 0.0), "level again")
    want = math.radians(node.queue.limits.yaw_rate)
    wait_for(lambda: any(abs(s.msg.yaw_rate - want) < 0.02
                         for s in velocity_setpoints_after(fake, r.time_boot_ms)),
             wall(5.0), "turning right at the yaw-rate limit")
    # velocity only: no position target, the vehicle is not moved by one
    assert all(s.msg.type_mask == MASK_VELOCITY for s in velocity_setpoints_after(fake, r.time_boot_ms))
    assert node.queue.status().current_command_id == cid


@pytest.mark.parametrize("loss", ["no_rc_channels", "rssi_0", "channels_unused"])
def test_rc_vel_stops_when_the_rc_is_lost(fly: Fly, loss: str) -> None:
    fake, node = fly()
    take_off(fake, node)
    speed = node.queue.limits.horizontal_speed
    node.add_command(cmd(RC_VEL))
    fake.rc[PITCH] = 1100
    wait_velocity(fake, (speed, 0.0, 0.0), "full speed north", tol=0.002)
    validity = node.rc_mapping.validity_s
    lost_at = fake.time_boot_ms
    if loss == "no_rc_channels":
        fake.rc_silent = True
    elif loss == "rssi_0":
        fake.rc_rssi = 0
    else:
        fake.rc = [0] * 18
    stopped = wait_velocity(fake, (0.0, 0.0, 0.0), "stopped after the RC loss")
    after = velocity_setpoints_after(fake, lost_at)
    # the last sample stays valid for validity_s (one RC period of it may have passed), then the
    # velocity ramps down at the acceleration limit
    slowing = next(r for r in after if r.msg.vx < speed - 0.02)
    held_s = (slowing.time_boot_ms - lost_at) / 1000.0
    assert validity - 0.15 <= held_s <= validity + 0.35, held_s
    lim = node.queue.limits
    ramp_s = speed / lim.horizontal_acceleration + lim.horizontal_acceleration / lim.horizontal_jerk
    took_s = (stopped.time_boot_ms - lost_at) / 1000.0
    assert took_s <= validity + ramp_s + 1.5, took_s
    assert all(abs(r.msg.vy) < 0.05 and abs(r.msg.vz) < 0.05 for r in after)
    assert node.supervisor.phase is Phase.ENGAGED  # still flying, holding still


# --- companion.link.rc: the stick mapping (pure) -----------------------------------------------------------
LIMITS = Limits()


def sticks(roll: int = 1500, pitch: int = 1500, throttle: int = 1500, yaw: int = 1500) -> list[int]:
    return [roll, pitch, throttle, yaw] + [1500] * 12


@pytest.mark.parametrize(("pwm", "expected"), [
    (1500, 0.0), (1530, 0.0), (1470, 0.0), (1531, 1 / 370), (1900, 1.0), (1100, -1.0),
    (1715, 0.5), (1285, -0.5), (2100, 1.0), (900, -1.0),
])
def test_stick_deadband_linear_and_clipped(pwm: int, expected: float) -> None:
    assert RcMapping().stick(pwm) == pytest.approx(expected)


def test_stick_with_an_off_centre_trim_reaches_full_deflection_at_both_ends() -> None:
    m = RcMapping(trim_us=1400.0, deadband_us=20.0)
    assert m.stick(1100) == pytest.approx(-1.0) and m.stick(1900) == pytest.approx(1.0)
    assert m.stick(1250) == pytest.approx(-(150 - 20) / (300 - 20))
    assert m.stick(1650) == pytest.approx((250 - 20) / (500 - 20))
    assert m.stick(1420) == 0.0 and m.stick(1380) == 0.0


@pytest.mark.parametrize(("channels", "yaw", "expected"), [
    (sticks(), 0.0, (0.0, 0.0, 0.0, 0.0)),
    (sticks(roll=1520, pitch=1480, throttle=1525, yaw=1475), 1.0, (0.0, 0.0, 0.0, 0.0)),
    (sticks(pitch=1100), 0.0, (5.0, 0.0, 0.0, 0.0)),  # forward = north when facing north
    (sticks(pitch=1900), 0.0, (-5.0, 0.0, 0.0, 0.0)),
    (sticks(pitch=1100), math.pi / 2, (0.0, 5.0, 0.0, 0.0)),  # facing east: forward = east
    (sticks(roll=1900), 0.0, (0.0, 5.0, 0.0, 0.0)),  # right of north = east
    (sticks(roll=1900), math.pi / 2, (-5.0, 0.0, 0.0, 0.0)),  # right of east = south
    (sticks(pitch=1100), math.pi, (-5.0, 0.0, 0.0, 0.0)),
    (sticks(throttle=1900), 0.0, (0.0, 0.0, -2.0, 0.0)),  # throttle up climbs (down < 0)
    (sticks(throttle=1100), 0.0, (0.0, 0.0, 2.0, 0.0)),
    (sticks(yaw=1900), 0.0, (0.0, 0.0, 0.0, 90.0)),
    (sticks(yaw=1100), 0.0, (0.0, 0.0, 0.0, -90.0)),
    (sticks(pitch=1285), 0.0, (2.5, 0.0, 0.0, 0.0)),
])
def test_rc_velocity(channels: list[int], yaw: float, expected: tuple[float, ...]) -> None:
    got = rc_velocity(channels, yaw, LIMITS)
    assert got is not None
    assert got == pytest.approx(expected, abs=1e-9)


@pytest.mark.parametrize("yaw", [0.0, 0.7, -2.0])
def test_rc_velocity_diagonal_is_limited_to_the_horizontal_speed(yaw: float) -> None:
    got = rc_velocity(sticks(roll=1900, pitch=1100), yaw, LIMITS)
    assert got is not None
    assert math.hypot(got[0], got[1]) == pytest.approx(LIMITS.horizontal_speed)
    # forward-right of the heading: 45 degrees clockwise of it
    assert math.atan2(got[1], got[0]) == pytest.approx(math.remainder(yaw + math.pi / 4, 2 * math.pi))
    half = rc_velocity(sticks(roll=1715, pitch=1285), 0.0, LIMITS)  # half and half: under the limit
    assert half is not None and half[:2] == pytest.approx((2.5, 2.5))


def test_rc_velocity_scales_with_the_limits() -> None:
    limits = Limits(horizontal_speed=3.0, vertical_speed=1.0, yaw_rate=45.0)
    got = rc_velocity(sticks(pitch=1100, throttle=1900, yaw=1100), 0.0, limits)
    assert got == pytest.approx((3.0, 0.0, -1.0, -45.0))


@pytest.mark.parametrize(("channels", "rssi"), [
    (sticks(pitch=0), 255), (sticks(yaw=65535), 255), (sticks(roll=0, throttle=0), 255),
    (sticks(pitch=1100), 0), ([1500, 1500, 1500], 255), ([], 255),
])
def test_rc_velocity_without_a_usable_report_is_none(channels: list[int], rssi: int) -> None:
    assert rc_velocity(channels, 0.0, LIMITS, rssi=rssi) is None


def test_rc_velocity_ignores_unused_channels_outside_the_mapping() -> None:
    channels = sticks(pitch=1100)
    channels[7] = 0
    channels[10] = 65535
    assert rc_velocity(channels, 0.0, LIMITS) == pytest.approx((5.0, 0.0, 0.0, 0.0))


def test_rc_velocity_follows_the_channel_map() -> None:
    mode1 = RcMapping(roll=1, pitch=3, throttle=2, yaw=4)  # "mode 1" transmitters swap pitch and throttle
    channels = sticks(pitch=1900, throttle=1100)  # channel 2 high, channel 3 low
    assert rc_velocity(channels, 0.0, LIMITS, mode1) == pytest.approx((5.0, 0.0, -2.0, 0.0))
    far = RcMapping(roll=5, pitch=6, throttle=7, yaw=8)
    channels = [1500] * 4 + [1900, 1500, 1500, 1500]
    assert rc_velocity(channels, 0.0, LIMITS, far) == pytest.approx((0.0, 5.0, 0.0, 0.0))
    assert rc_velocity(channels[:7], 0.0, LIMITS, far) is None  # channel 8 not reported


@pytest.mark.parametrize("kw", [
    {"pitch": 1}, {"yaw": 3}, {"roll": 0}, {"yaw": 19},
    {"deadband_us": 400.0}, {"min_us": 1600.0}, {"max_us": 1400.0}, {"trim_us": 1890.0},
])
def test_bad_rc_mapping_is_refused(kw: dict[str, float]) -> None:
    with pytest.raises(ValueError, match="rc mapping"):
        RcMapping(**kw)  # type: ignore[arg-type]

