"""A pilot's flight (sticks over MAVLink), run against any autopilot, recording what a ground station sees.

:class:`Sticks` is a transmitter: a thread that sends RC_CHANNELS_OVERRIDE (or
MANUAL_CONTROL) at 12.5 Hz of autopilot time until told to stop. :func:`observe_pilot` flies the same
scenario on the model and on ArduPilot's copter SITL (:mod:`autopilot_support`); the latter is given
``SIM_RC_FAIL=1`` (no receiver: its only RC is the override, as the model's) so that silence on the
override is an RC failsafe on both. ``tests/test_differential_pilot.py`` compares the observations;
``docs/conformance.md`` tabulates them. No tests here.
"""

from __future__ import annotations

import math
import threading
import time
from typing import Any

from harness.autopilot import Autopilot
from harness.observer import M
from harness.timing import wait_for
from taskflight_common.ardupilot import CopterMode

STABILIZE, ALT_HOLD, LOITER, RTL, POSHOLD = (
    CopterMode.STABILIZE, CopterMode.ALT_HOLD, CopterMode.LOITER, CopterMode.RTL, CopterMode.POSHOLD)
CENTRE = (1500, 1500, 1500, 1500)
IGNORE = 65535


class Sticks:
    """Roll, pitch, throttle, yaw as RC_CHANNELS_OVERRIDE (PWM) or MANUAL_CONTROL (x, y, z, r), ``hz``
    times a second of autopilot time (a transmitter's 12.5 Hz by default; ``hz`` * speedup of wall time)."""

    def __init__(self, ap: Autopilot, hz: float = 12.5) -> None:
        if not ap.speedup > 0:
            raise ValueError("Sticks: the autopilot must run at a speedup > 0 (the rate is on its clock)")
        self.conn = ap.gcs.conn
        self.period = 1.0 / (hz * ap.speedup)
        self.rc: tuple[int, int, int, int] | None = (1500, 1500, 1000, 1500)
        self.manual: tuple[int, int, int, int] | None = None
        self.sent = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="sticks", daemon=True)
        self._thread.start()

    def set(self, roll: int = 1500, pitch: int = 1500, throttle: int = 1500, yaw: int = 1500) -> None:
        self.manual = None
        self.rc = (roll, pitch, throttle, yaw)

    def set_manual(self, x: int = 0, y: int = 0, z: int = 500, r: int = 0) -> None:
        self.rc = None
        self.manual = (x, y, z, r)

    def silence(self) -> None:
        self.rc = self.manual = None

    def _run(self) -> None:
        while not self._stop.is_set():
            rc, manual = self.rc, self.manual
            if rc is not None:
                self.conn.mav.rc_channels_override_send(1, 1, *rc, IGNORE, IGNORE, IGNORE, IGNORE)
                self.sent += 1
            elif manual is not None:
                self.conn.mav.manual_control_send(1, *manual, 0)
                self.sent += 1
            time.sleep(self.period)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)


def _sim_s(ap: Autopilot) -> float:
    m = ap.gcs.last.get("LOCAL_POSITION_NED")
    return 0.0 if m is None else m.time_boot_ms / 1000.0


def _heading_of(vn: float, ve: float, yaw: float) -> float:
    """Direction of motion relative to the vehicle's heading (deg, -180..180; 0 forward, 90 right)."""
    d = math.degrees(math.atan2(ve, vn) - yaw)
    return (d + 180.0) % 360.0 - 180.0


def observe_pilot(ap: Autopilot) -> dict[str, Any]:
    """Fly the pilot scenario on ``ap`` (just started, on the ground); return the observations."""
    g = ap.gcs
    obs: dict[str, Any] = {}
    states: list[int] = []

    def record() -> None:
        m = g.last.get("EXTENDED_SYS_STATE")
        if m is not None and (not states or states[-1] != m.landed_state):
            states.append(m.landed_state)

    def sim_wait(pred: Any, sim_s: float, what: str) -> Any:
        return g.wait(lambda: (record(), pred())[1], g.wall(sim_s), what)

    def pause(sim_s: float) -> None:
        t0 = _sim_s(ap)
        sim_wait(lambda: _sim_s(ap) >= t0 + sim_s, sim_s + 5, f"{sim_s} s of autopilot time")

    def lpn() -> Any:
        return g.last["LOCAL_POSITION_NED"]

    def speed() -> float:
        m = lpn()
        return math.hypot(m.vx, m.vy)

    obs["intervals"] = [g.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 100_000)
                        for msg_id in (M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE, M.MAVLINK_MSG_ID_RC_CHANNELS,
                                       M.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW)]
    wait_for(lambda: g.last.get("LOCAL_POSITION_NED") is not None, g.wall(60), "LOCAL_POSITION_NED")
    sticks = Sticks(ap)
    try:
        for name, value in (("RC_FS_TIMEOUT", 2.0), *((f"RC{c}_{k}", v) for c in range(1, 5)
                                                      for k, v in (("MIN", 1000), ("MAX", 2000)))):
            g.set_param(name, value)
        if ap.kind == "arducopter":
            g.set_param("SIM_RC_FAIL", 1)  # no receiver: the override is the only RC, as on the model
        pause(1.0)
        rc = sim_wait(lambda: (m := g.last.get("RC_CHANNELS")) is not None and m.chan3_raw == 1000 and m,
                      10, "RC_CHANNELS with the override")
        obs["rc_channels"] = (rc.chan1_raw, rc.chan2_raw, rc.chan3_raw, rc.chan4_raw, rc.chancount >= 4)
        servo = g.msg("SERVO_OUTPUT_RAW", g.wall(10))
        obs["servo_disarmed"] = (servo.servo1_raw, servo.servo2_raw, servo.servo3_raw, servo.servo4_raw)

        # STABILIZE: arming refused with the throttle up
        sticks.set(throttle=1300)
        pause(0.5)
        obs["arm_throttle_high_stabilize"] = g.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
        sticks.set(throttle=1000)
        pause(0.5)

        # LOITER: arm with the throttle down, take off with the throttle up
        obs["set_loiter"] = g.set_mode(LOITER)
        results: list[int] = []
        g.wait(lambda: results.append(g.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1)) or results[-1] == 0,
               g.wall(90), "arming in LOITER")
        obs["arm_loiter"] = results[-1]
        record()
        sticks.set(throttle=1800)
        sim_wait(lambda: lpn().z < -8.0, 40, "8 m up on the throttle")
        sticks.set(throttle=1500)
        sim_wait(lambda: abs(lpn().vz) < 0.3, 20, "climb stopped at mid-stick")
        obs["climb_stops_at_mid_stick"] = True
        servo = g.fresh("SERVO_OUTPUT_RAW", g.wall(5))
        obs["servo_hover"] = (servo.servo1_raw, servo.servo2_raw, servo.servo3_raw, servo.servo4_raw)
        z0 = lpn().z
        pause(3.0)
        obs["loiter_hold_alt_change_m"] = abs(lpn().z - z0)

        # LOITER: pitch forward, then centre
        sticks.set(pitch=1300)
        pause(6.0)
        m, att = lpn(), g.last["ATTITUDE"]
        obs["loiter_pitch_fwd"] = (_heading_of(m.vx, m.vy, att.yaw), speed())
        sticks.set()
        t0 = _sim_s(ap)
        sim_wait(lambda: speed() < 0.3, 30, "LOITER stopped with the sticks centred")
        obs["loiter_stop_s"] = _sim_s(ap) - t0

        # MANUAL_CONTROL: roll right
        sticks.set_manual(y=500)
        pause(5.0)
        m, att = lpn(), g.last["ATTITUDE"]
        obs["manual_roll_right"] = (_heading_of(m.vx, m.vy, att.yaw), speed())
        sticks.set_manual()
        sim_wait(lambda: speed() < 0.3, 30, "stopped after MANUAL_CONTROL")

        # ALT_HOLD: hold at mid-stick, climb above it
        obs["set_alt_hold"] = g.set_mode(ALT_HOLD)
        sticks.set()
        z0 = lpn().z
        pause(3.0)
        obs["alt_hold_alt_change_m"] = abs(lpn().z - z0)
        sticks.set(throttle=1900)
        pause(2.0)
        obs["alt_hold_climb_mps"] = -lpn().vz
        sticks.set()
        sim_wait(lambda: abs(lpn().vz) < 0.3, 20, "ALT_HOLD climb stopped")

        # POSHOLD: pitch forward, centre, it brakes and holds
        obs["set_poshold"] = g.set_mode(POSHOLD)
        sticks.set(pitch=1300)
        pause(4.0)
        m, att = lpn(), g.last["ATTITUDE"]
        obs["poshold_pitch_fwd"] = (_heading_of(m.vx, m.vy, att.yaw), speed())
        sticks.set()
        t0 = _sim_s(ap)
        sim_wait(lambda: speed() < 0.3, 30, "POSHOLD stopped with the sticks centred")
        obs["poshold_stop_s"] = _sim_s(ap) - t0

        # RC failsafe: the override stops
        sticks.silence()
        t0 = _sim_s(ap)
        sim_wait(lambda: g.modes_seen[-1] == RTL, 15, "RTL after the override stopped")
        obs["failsafe_after_s"] = _sim_s(ap) - t0
        sim_wait(lambda: not g.last["HEARTBEAT"].base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, 150,
                 "landed and disarmed by the failsafe RTL")
        obs["rc_failsafe_text"] = any("failsafe" in t.lower() and "radio" in t.lower() for t in g.texts)
    finally:
        sticks.close()
    record()
    obs["landed_states"] = states
    obs["modes"] = list(g.modes_seen)
    return obs
