"""MAVProxy (pip package), run non-interactively over TCP, connects and sees the mode and arming state.

The mode and arming are changed by a second ground station (pymavlink over UDP), so what is checked
is MAVProxy's own view of the vehicle: its console lines for the detected vehicle, the mode, ARMED,
DISARMED and the parameter download.
"""

from __future__ import annotations

import pytest

from harness.mavproxy import Lines
from harness.observer import Gcs, M

pytestmark = pytest.mark.integration


def test_mavproxy_sees_vehicle_mode_and_arming(mavproxy_out: tuple[Lines, Gcs]) -> None:
    m = M
    out, gcs = mavproxy_out
    out.wait("Detected vehicle 1:1", 30)
    out.wait("Mode STABILIZE", 20)
    out.wait("Received", 30)  # "Received N parameters": the paced parameter list went through
    gcs.wait_prearm(30)
    assert gcs.set_mode(4) == m.MAV_RESULT_ACCEPTED
    out.wait("Mode GUIDED", 10)
    assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1) == m.MAV_RESULT_ACCEPTED
    out.wait("ARMED", 10)
    assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 0) == m.MAV_RESULT_ACCEPTED
    out.wait("DISARMED", 10)
    assert not any("fence breach" in line for line in out.seen)
