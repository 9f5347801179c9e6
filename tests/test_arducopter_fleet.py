"""``taskflight up --autopilot arducopter``'s SITL command lines: each vehicle's instance, system id and
home (spaced as the model's fleet spaces them), ArduPilot's parameter file, a wiped EEPROM, the rate, and
SERIAL0 sending to its companion's port; the ports it needs beyond the model's."""

from __future__ import annotations

import socket
from pathlib import Path

import pytest

from autopilot_model.fleet import fleet_homes
from taskflight import arducopter_fleet as acf


def test_homes_are_the_model_fleets_homes() -> None:
    model = fleet_homes(4)
    for i, home in enumerate(model):
        lat, lon, alt, hdg = map(float, acf.home(i).split(","))
        assert (lat, lon, alt, hdg) == pytest.approx(home, abs=1e-7)


def test_each_vehicle_gets_its_instance_sysid_home_and_port() -> None:
    argv = acf.sitl_argv("/x/arducopter", Path("/p/copter.parm"), 42, 7, 2, 3.0, 14970)
    argv = argv[argv.index("/x/arducopter"):]  # after setpriv --pdeathsig, where there
    assert argv[:3] == ["/x/arducopter", "--model", "+"]
    assert "-I42" in argv and "-w" in argv
    assert argv[argv.index("--sysid") + 1] == "7"
    assert argv[argv.index("--speedup") + 1] == "3"
    assert argv[argv.index("--defaults") + 1] == "/p/copter.parm"
    assert argv[argv.index("--home") + 1] == acf.home(2)
    assert argv[argv.index("--serial0") + 1] == "udpclient:127.0.0.1:14970"
    assert argv[argv.index("--serial1") + 1] == "tcp:0"  # 5760+10I: the model's ground-station port


def test_the_ports_beyond_the_models_are_checked() -> None:
    base = 200
    assert acf.gcs_port(base) == 5760 + 10 * base and acf.watch_port(base) == 5763 + 10 * base
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("127.0.0.1", acf.watch_port(base + 1)))
        except OSError:
            pytest.skip("the port is in use here")
        s.listen()
        taken = acf.ports_taken(base, 2, 5)
    assert any(f"TCP {acf.watch_port(base + 1)} (vehicle 1, sysid 6, ArduCopter SERIAL2)" == t for t in taken)
