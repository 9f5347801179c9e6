"""Pilot input on the model, in-process through its MAVLink handlers: the RC channel
semantics of RC_CHANNELS_OVERRIDE and MANUAL_CONTROL, the arming checks on the sticks, each pilot mode's
response, the RC failsafe and its options, RC_CHANNELS / SERVO_OUTPUT_RAW and their stream group.

The messages are built with pymavlink and given to ``endpoint.handle_message`` as if received from the
ground station (system 255); the vehicle runs on its Python API (same seed: deterministic). The same
behavior against ArduCopter SITL is in ``test_differential_pilot.py``.
"""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from autopilot_model.modules.flight_modes import ALT_HOLD, GUIDED, LAND, LOITER, POSHOLD, RTL, STABILIZE
from autopilot_model.modules.navigation import LANDED_IN_AIR, LANDED_ON_GROUND
from autopilot_model.sitl import Sitl

pytestmark = pytest.mark.integration

M = mavlink
IGNORE = 65535


class Peer:
    """Stands in for a link (the handlers only pass it on)."""

    name = "test"
    active = True
    closed = False
    state = None
    parser = None

    def send_bytes(self, data: bytes) -> bool:
        return True


class Pilot:
    def __init__(self, s: Sitl, sysid: int = 255) -> None:
        self.s = s
        self.mav = M.MAVLink(None, sysid, 190)
        self.peer = Peer()

    def _deliver(self, msg: object) -> None:
        buf = msg.pack(self.mav)  # type: ignore[attr-defined]
        decoded = M.MAVLink(None).parse_char(buf)
        self.s.endpoint.handle_message(decoded, self.peer)  # type: ignore[arg-type]

    def rc(self, *chans: int) -> None:
        ch = list(chans) + [IGNORE] * (8 - len(chans)) if len(chans) < 8 else list(chans)
        self._deliver(self.mav.rc_channels_override_encode(1, 1, *ch))

    def manual(self, x: int, y: int, z: int, r: int, target: int = 1) -> None:
        self._deliver(self.mav.manual_control_encode(target, x, y, z, r, 0))

    def fly(self, sim_s: float, *chans: int) -> None:
        """Hold the sticks for ``sim_s`` (sent at 10 Hz of simulated time)."""
        v = self.s.vehicle
        end = v.clock.now() + sim_s
        while v.clock.now() < end:
            self.rc(*chans)
            v.run_for(0.1)


def _airborne(s: Sitl, p: Pilot, mode: int) -> None:
    """Arm in ``mode`` with the throttle down, take off on the throttle to about 8 m, settle at mid-stick."""
    v = s.vehicle
    assert s.modes.set_mode(mode)[0]
    p.rc(1500, 1500, 1000, 1500)
    assert s.link.vehicle_commands.modes.pilot.arm_refusal(mode) is None
    assert v.nav.arm()[0]
    if mode == STABILIZE:
        p.fly(3.0, 1500, 1500, 1700, 1500)
    else:
        p.fly(5.0, 1500, 1500, 1850, 1500)
    p.fly(3.0, 1500, 1500, 1500, 1500)
    assert v.nav.landed_state == LANDED_IN_AIR
    assert -v.state.position_ned[2] > 4.0


def _forward_speed(s: Sitl) -> tuple[float, float]:
    """(speed along the heading, across it) in m/s."""
    vn, ve, _ = s.vehicle.state.velocity_ned
    yaw = s.vehicle.state.euler[2]
    return vn * math.cos(yaw) + ve * math.sin(yaw), -vn * math.sin(yaw) + ve * math.cos(yaw)


# --- channel semantics -------------------------------------------------------------------------------
def test_override_ignore_release_and_high_channels(sitl: Sitl) -> None:
    p = Pilot(sitl)
    rc = sitl.rc
    p.rc(1400, 1600, 1200, 1700)
    assert rc.radio_in[:4] == [1400, 1600, 1200, 1700] and rc.seen and rc.chancount == 4
    p.rc(IGNORE, 1550, IGNORE, IGNORE)  # 65535: no change
    assert rc.radio_in[:4] == [1400, 1550, 1200, 1700]
    p.rc(1500, 1500, 1200, 1500, 1800, IGNORE, IGNORE, IGNORE, 1300, *([0] * 7))
    assert rc.radio_in[4] == 1800 and rc.radio_in[8] == 1300 and rc.chancount == 9
    p.rc(1500, 1500, 1200, 1500, 0)  # 0 releases channel 5: it keeps its value (no receiver behind it)
    assert rc.radio_in[4] == 1800


def test_overrides_from_another_system_are_ignored(sitl: Sitl) -> None:
    Pilot(sitl, sysid=42).rc(1400, 1600, 1200, 1700)
    assert not sitl.rc.seen and sitl.rc.radio_in[:4] == [0, 0, 0, 0]
    assert sitl.endpoint.stats["pilot_not_gcs"] == 1


def test_manual_control_maps_onto_channels_1_to_4(sitl: Sitl) -> None:
    p = Pilot(sitl)
    p.manual(x=500, y=-500, z=250, r=1000)  # forward, left, quarter throttle, full right yaw
    # RC defaults 1100..1900: roll 1100 + 800 * 500 / 2000; pitch reversed; throttle 0..1000
    assert sitl.rc.radio_in[:4] == [1300, 1300, 1300, 1900]
    p.manual(x=0, y=0, z=-1, r=0)  # negative thrust: ignored (ArduCopter)
    assert sitl.rc.radio_in[:4] == [1300, 1300, 1300, 1900]
    p.manual(x=0, y=0, z=500, r=0, target=7)  # another vehicle's
    assert sitl.rc.radio_in[:4] == [1300, 1300, 1300, 1900]
    pilot = sitl.modes.pilot
    p.manual(x=1000, y=0, z=500, r=0)
    assert pilot.rc.stick(1) == pytest.approx(-1.0) and pilot.rc.throttle() == pytest.approx(480.5, abs=0.5)


def test_an_override_counts_as_the_ground_station(sitl: Sitl) -> None:
    assert sitl.endpoint.last_gcs_heartbeat_s is None
    Pilot(sitl).rc(1500, 1500, 1000, 1500)
    assert sitl.endpoint.last_gcs_heartbeat_s == sitl.vehicle.clock.now()


# --- arming checks -----------------------------------------------------------------------------------
def test_arming_refused_with_the_throttle_up(sitl: Sitl) -> None:
    p = Pilot(sitl)
    pilot = sitl.modes.pilot
    p.rc(1500, 1500, 1200, 1500)
    assert pilot.arm_refusal(STABILIZE) == "Arm: Throttle too high"
    assert pilot.arm_refusal(ALT_HOLD) is None  # below the dead band: fine outside STABILIZE
    p.rc(1500, 1500, 1700, 1500)
    assert pilot.arm_refusal(LOITER) == "Arm: Throttle too high"
    assert pilot.arm_refusal(GUIDED) is None  # GCS arming in GUIDED skips the throttle checks
    p.rc(1500, 1500, 950, 1500)
    assert pilot.arm_refusal(STABILIZE) == "PreArm: Throttle below failsafe"


def test_no_rc_no_rc_checks(sitl: Sitl) -> None:
    """Without any RC the model arms as before (the companion's GUIDED flights)."""
    assert sitl.modes.pilot.arm_refusal(STABILIZE) is None
    assert sitl.modes.pilot.arm_refusal(GUIDED) is None


# --- the modes -----------------------------------------------------------------------------------------
@pytest.mark.parametrize("mode", [LOITER, ALT_HOLD, POSHOLD, STABILIZE])
def test_pitch_forward_flies_forward_and_roll_right_flies_right(sitl: Sitl, mode: int) -> None:
    p = Pilot(sitl)
    _airborne(sitl, p, mode)
    thr = 1500
    p.fly(4.0, 1500, 1300, thr, 1500)
    fwd, side = _forward_speed(sitl)
    assert fwd > 2.0 and abs(side) < 0.3 * fwd, (fwd, side)
    p.fly(8.0, 1500, 1500, thr, 1500)
    p.fly(4.0, 1700, 1500, thr, 1500)
    fwd, side = _forward_speed(sitl)
    assert side > 1.5, (fwd, side)


@pytest.mark.parametrize("mode", [LOITER, POSHOLD])
def test_centred_sticks_brake_and_hold_the_position(sitl: Sitl, mode: int) -> None:
    p = Pilot(sitl)
    v = sitl.vehicle
    _airborne(sitl, p, mode)
    p.fly(4.0, 1500, 1300, 1500, 1500)
    p.fly(6.0, 1500, 1500, 1500, 1500)
    assert math.hypot(*v.state.velocity_ned[:2]) < 0.6  # the outdoor estimate's wander (~0.3 m/s)
    here = v.state.position_ned
    p.fly(5.0, 1500, 1500, 1500, 1500)
    assert math.dist(here[:2], v.state.position_ned[:2]) < 1.5


def test_alt_hold_climb_rate_and_dead_band(sitl: Sitl) -> None:
    p = Pilot(sitl)
    v = sitl.vehicle
    _airborne(sitl, p, ALT_HOLD)
    z = v.state.position_ned[2]
    p.fly(3.0, 1500, 1500, 1560, 1500)  # inside THR_DZ: holds
    assert abs(v.state.position_ned[2] - z) < 0.5
    p.fly(3.0, 1500, 1500, 1900, 1500)  # full throttle: PILOT_SPEED_UP (2.5 m/s)
    assert -v.state.velocity_ned[2] == pytest.approx(2.5, abs=0.3)
    assert sitl.modes.pilot.climb_rate() == pytest.approx(2.5)


def test_yaw_stick_turns(sitl: Sitl) -> None:
    p = Pilot(sitl)
    v = sitl.vehicle
    _airborne(sitl, p, LOITER)
    yaw0 = v.state.euler[2]
    p.fly(1.0, 1500, 1500, 1500, 1900)
    turned = (v.state.euler[2] - yaw0 + math.pi) % (2 * math.pi) - math.pi
    assert turned > math.radians(30)


def test_throttle_down_lands_and_disarms_after_disarm_delay(sitl: Sitl) -> None:
    p = Pilot(sitl)
    v = sitl.vehicle
    _airborne(sitl, p, LOITER)
    p.fly(15.0, 1500, 1500, 1000, 1500)
    assert v.nav.landed_state == LANDED_ON_GROUND and v.nav.armed  # landed, motors at idle
    p.fly(11.0, 1500, 1500, 1000, 1500)
    assert not v.nav.armed  # DISARM_DELAY 10 s
    assert sitl.modes.mode == LOITER and not sitl.rc.failsafe


def test_stabilize_throttle_is_the_collective(sitl: Sitl) -> None:
    p = Pilot(sitl)
    v = sitl.vehicle
    _airborne(sitl, p, STABILIZE)
    p.fly(2.0, 1500, 1500, 1900, 1500)
    assert -v.state.velocity_ned[2] > 2.0  # full throttle climbs hard
    p.fly(1.5, 1500, 1500, 1150, 1500)
    assert v.state.velocity_ned[2] > 0.5  # near-zero throttle falls


# --- the RC failsafe -----------------------------------------------------------------------------------
def test_silence_triggers_the_radio_failsafe_rtl(sitl: Sitl) -> None:
    p = Pilot(sitl)
    v = sitl.vehicle
    _airborne(sitl, p, LOITER)
    t0 = sitl.rc.last_input_s
    assert t0 is not None and v.run_until(lambda: sitl.modes.mode == RTL, 5.0)
    assert 1.0 <= v.clock.now() - t0 <= 1.1  # RC_FS_TIMEOUT after the last override
    assert sitl.rc.failsafe and sitl.link.telemetry.system_status() == M.MAV_STATE_CRITICAL
    assert v.run_until(lambda: not v.nav.armed, 120.0)  # RTL lands at home and disarms
    p.rc(1500, 1500, 1000, 1500)
    assert not sitl.rc.failsafe


def test_throttle_below_fs_thr_value_is_a_failsafe(sitl: Sitl) -> None:
    p = Pilot(sitl)
    _airborne(sitl, p, ALT_HOLD)
    p.fly(0.3, 1500, 1500, 900, 1500)
    assert sitl.rc.failsafe and sitl.modes.mode == RTL


def test_failsafe_in_guided_and_its_option(sitl: Sitl) -> None:
    p = Pilot(sitl)
    v = sitl.vehicle
    _airborne(sitl, p, LOITER)
    assert sitl.modes.set_mode(GUIDED)[0]
    v.params.set("FS_OPTIONS", 16 | 4)  # RC_CONTINUE_IF_GUIDED
    v.run_for(1.5)
    assert sitl.rc.failsafe and sitl.modes.mode == GUIDED
    p.rc(1500, 1500, 1500, 1500)
    v.params.set("FS_OPTIONS", 16)
    v.run_for(1.5)
    assert sitl.modes.mode == RTL  # ArduCopter's default: any mode


def test_failsafe_landed_disarms_and_disabled_does_nothing(sitl: Sitl) -> None:
    p = Pilot(sitl)
    v = sitl.vehicle
    assert sitl.modes.set_mode(LOITER)[0]
    p.rc(1500, 1500, 1000, 1500)
    assert v.nav.arm()[0]
    v.run_for(1.5)
    assert not v.nav.armed and sitl.modes.mode == LOITER  # on the ground: disarmed
    p.rc(1500, 1500, 1000, 1500)
    v.params.set("FS_THR_ENABLE", 0)
    _airborne(sitl, p, ALT_HOLD)
    v.run_for(5.0)
    assert not sitl.rc.failsafe and sitl.modes.mode == ALT_HOLD


def test_no_rc_means_no_failsafe_and_unchanged_modes(sitl: Sitl) -> None:
    """The companion's flights: no RC ever, GUIDED, then LOITER holds as before."""
    v = sitl.vehicle
    assert sitl.modes.set_mode(GUIDED)[0]
    assert v.nav.arm()[0] and v.nav.takeoff(5.0)[0]
    assert v.run_until(lambda: v.nav.landed_state == LANDED_IN_AIR, 30.0)
    assert sitl.modes.set_mode(LOITER)[0]
    here = v.state.position_ned
    v.run_for(5.0)
    assert math.dist(here, v.state.position_ned) < 1.0
    assert not sitl.rc.failsafe and sitl.modes.mode == LOITER and v.lean is None


def test_failsafe_continues_landing_with_its_option(sitl: Sitl) -> None:
    p = Pilot(sitl)
    v = sitl.vehicle
    _airborne(sitl, p, LOITER)
    v.params.set("FS_OPTIONS", 16 | 8)  # CONTINUE_IF_LANDING
    assert sitl.modes.set_mode(LAND)[0]
    v.run_for(1.5)
    assert sitl.rc.failsafe and sitl.modes.mode == LAND


# --- telemetry -----------------------------------------------------------------------------------------
def test_rc_channels_and_servo_output_raw(sitl: Sitl) -> None:
    link = sitl.link.pilot
    m = link.rc_channels()
    assert m.chancount == 0 and m.chan1_raw == 0 and m.rssi == 255  # nothing before any RC
    p = Pilot(sitl)
    p.rc(1450, 1550, 1000, 1500)
    m = link.rc_channels()
    assert (m.chancount, m.chan1_raw, m.chan2_raw, m.chan3_raw, m.chan4_raw) == (4, 1450, 1550, 1000, 1500)
    s = link.servo_output_raw()
    assert (s.servo1_raw, s.servo2_raw, s.servo3_raw, s.servo4_raw) == (1000, 1000, 1000, 1000)
    _airborne(sitl, p, LOITER)
    s = link.servo_output_raw()
    assert all(1300 < x < 1800 for x in (s.servo1_raw, s.servo2_raw, s.servo3_raw, s.servo4_raw))
    sitl.vehicle.run_for(1.5)
    assert link.rc_channels().rssi == 0  # in RC failsafe


def test_rc_stream_group(sitl: Sitl) -> None:
    from autopilot_model.mavlink.streams import STREAM_GROUPS

    assert STREAM_GROUPS[M.MAV_DATA_STREAM_RC_CHANNELS] == ("RC_CHANNELS", "SERVO_OUTPUT_RAW")
    streams = sitl.link.streams
    assert streams.supports("RC_CHANNELS") and streams.supports("SERVO_OUTPUT_RAW")
