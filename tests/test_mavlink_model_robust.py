"""Signing and invalid fields against the whole model process (issue 3 items 9 and 10).

A SITL with a signing key: an unsigned ground station is not acted on, a signed one is; NaN or
infinite fields in GUIDED targets change nothing and are counted; the vehicle keeps flying.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Iterator
from typing import Any

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil
from test_mavlink_support import SitlProcess, free_port

from autopilot_model.mavlink.signing import key_from_passphrase

M = mavutil.mavlink
GUIDED, LOITER = 4, 5
SPEEDUP = 10.0
POS_ONLY = 0b110111111000
VEL_ONLY = 0b110111000111
PASSPHRASE = "taskflight-signing-test"


class Station:
    def __init__(self, port: int, sysid: int, key: bytes | None) -> None:
        mavutil.set_dialect("ardupilotmega")
        self.conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=sysid,
                                               source_component=190)
        if key is not None:
            self.conn.setup_signing(key, sign_outgoing=True)
        self.last: dict[str, Any] = {}
        self.acks: list[Any] = []
        self._hb = 0.0

    def pump(self) -> None:
        if time.monotonic() - self._hb > 0.1:
            self._hb = time.monotonic()
            self.conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        while (m := self.conn.recv_match(blocking=False)) is not None:
            self.last[m.get_type()] = m
            if m.get_type() == "COMMAND_ACK":
                self.acks.append(m)

    def wait(self, pred: Any, timeout_s: float, what: str) -> Any:
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            self.pump()
            if r := pred():
                return r
            time.sleep(0.002)
        raise AssertionError(f"timed out waiting for {what}")

    def fresh(self, t: str) -> Any:
        self.last.pop(t, None)
        return self.wait(lambda: self.last.get(t), 10, t)

    def command(self, cmd: int, *p: float, timeout_s: float = 10) -> Any:
        params = list(p) + [0.0] * (7 - len(p))
        self.acks.clear()
        self.conn.mav.command_long_send(1, 1, cmd, 0, *params)
        return self.wait(lambda: next((a for a in self.acks if a.command == cmd), None), timeout_s,
                         f"ACK of {cmd}")


@pytest.fixture(scope="module")
def sitl(tmp_path_factory: pytest.TempPathFactory) -> Iterator[int]:
    port = free_port()
    proc = SitlProcess([f"udpin:127.0.0.1:{port}"], tmp_path_factory.mktemp("sitl"), speedup=SPEEDUP,
                       extra=["--signing-key", PASSPHRASE])
    try:
        yield port
    finally:
        proc.stop()


def test_unsigned_refused_signed_accepted_then_invalid_fields_ignored(sitl: int) -> None:
    key = key_from_passphrase(PASSPHRASE)
    gcs = Station(sitl, 255, key)
    gcs.wait(lambda: gcs.last.get("HEARTBEAT"), 20, "heartbeat")
    mode0 = gcs.fresh("HEARTBEAT").custom_mode
    assert mode0 != LOITER
    plain = Station(sitl, 250, None)
    plain.conn.mav.command_long_send(1, 1, M.MAV_CMD_DO_SET_MODE, 0, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                                     LOITER, 0, 0, 0, 0, 0)
    # two simulated seconds later: no ACK to the unsigned sender, no mode change
    end = time.monotonic() + 2.0 * 3 / SPEEDUP + 0.5
    while time.monotonic() < end:
        plain.pump()
        gcs.pump()
        time.sleep(0.002)
    assert not plain.acks
    assert gcs.fresh("HEARTBEAT").custom_mode == mode0

    assert gcs.command(M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, GUIDED).result == 0
    assert gcs.fresh("HEARTBEAT").custom_mode == GUIDED

    # fly, then send invalid GUIDED targets: nothing may move the vehicle
    gcs.wait(lambda: gcs.last.get("SYS_STATUS") and gcs.last["SYS_STATUS"].onboard_control_sensors_health
             & M.MAV_SYS_STATUS_PREARM_CHECK, 30, "pre-arm checks")
    assert gcs.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == 0
    assert gcs.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 5.0).result == 0

    def near(target: tuple[float, float, float], tol: float) -> bool:
        m = gcs.last.get("LOCAL_POSITION_NED")
        return m is not None and math.dist((m.x, m.y, m.z), target) < tol

    gcs.wait(lambda: near((0.0, 0.0, -5.0), 0.6), 30, "take-off to 5 m")
    before = gcs.fresh("LOCAL_POSITION_NED")
    for mask, vals in ((POS_ONLY, (math.nan, 0.0, -5.0, 0, 0, 0)), (POS_ONLY, (math.inf, 1.0, -5.0, 0, 0, 0)),
                       (VEL_ONLY, (0, 0, 0, math.nan, 2.0, 0.0)), (VEL_ONLY, (0, 0, 0, -math.inf, 0.0, 0.0))):
        gcs.conn.mav.set_position_target_local_ned_send(0, 1, 1, M.MAV_FRAME_LOCAL_NED, mask, *vals,
                                                         0, 0, 0, 0, 0)
    end = time.monotonic() + 2.0 * 3 / SPEEDUP + 0.5
    while time.monotonic() < end:
        gcs.pump()
        time.sleep(0.002)
    after = gcs.fresh("LOCAL_POSITION_NED")
    assert math.dist((before.x, before.y, before.z), (after.x, after.y, after.z)) < 0.5
    assert gcs.fresh("HEARTBEAT").custom_mode == GUIDED
    # a valid target still works afterwards
    gcs.conn.mav.set_position_target_local_ned_send(0, 1, 1, M.MAV_FRAME_LOCAL_NED, POS_ONLY, 10.0, 0.0, -5.0,
                                                    0, 0, 0, 0, 0, 0, 0, 0)
    gcs.wait(lambda: near((10.0, 0.0, -5.0), 0.6), 40, "valid target after invalid ones")
