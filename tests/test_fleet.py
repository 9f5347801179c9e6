"""Many vehicles in one process on one clock (:mod:`autopilot_model.fleet`).

The fleet runs in its own process (``python -m autopilot_model.fleet``, as ``taskflight up`` will start it)
and is reached over real loopback sockets with pymavlink: each vehicle on its own UDP and TCP ports with its
own system id, each flown independently, every port released when the fleet stops.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path

import pytest
from pymavlink import mavutil

from autopilot_model.fleet import Fleet, fleet_homes, template_urls
from harness.fleet import ports, start_fleet
from harness.observer import GUIDED, Gcs, M
from harness.timing import wait_for
from taskflight.sitlproc import ModelProcess
from taskflight_common.geo import geodetic_to_ned
from taskflight_common.ports import base_free

pytestmark = pytest.mark.integration

SPEEDUP = 5.0
N = 3


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[ModelProcess, int, list[Gcs]]]:
    proc, base = start_fleet(tmp_path_factory.mktemp("fleet"))
    stations: list[Gcs] = []
    try:
        for i in range(N):
            g = Gcs(ports(base + i)[1], SPEEDUP, background=True, target=i + 1)
            stations.append(g)
        for i, g in enumerate(stations):
            wait_for(lambda g=g: g.last.get("HEARTBEAT") is not None, 30, f"vehicle {i}'s first heartbeat")
            g.request_streams(10)
        yield proc, base, stations
    finally:
        for g in stations:
            g.close()
        proc.stop()


def test_ready_line_names_every_vehicle(fleet: tuple[ModelProcess, int, list[Gcs]]) -> None:
    proc, base, _ = fleet
    assert proc.ready_line.startswith(f"READY vehicles={N} ")
    for i in range(N):
        tcp, udp = ports(base + i)
        assert f"sysid={i + 1} tcpin:127.0.0.1:{tcp},udpin:127.0.0.1:{udp}" in proc.ready_line


def test_each_vehicle_answers_on_its_own_udp_port_with_its_own_sysid(
        fleet: tuple[ModelProcess, int, list[Gcs]]) -> None:
    _, _, stations = fleet
    for i, g in enumerate(stations):
        hb = g.wait(lambda g=g: g.last.get("HEARTBEAT"), 10, "HEARTBEAT")
        assert hb.get_srcSystem() == i + 1
        assert hb.type == M.MAV_TYPE_QUADROTOR
        # a parameter read through this port is this vehicle's own
        g.conn.mav.param_request_read_send(i + 1, 1, b"MAV_SYSID", -1)
        g.wait(lambda g=g: "MAV_SYSID" in g.params, 10, "PARAM_VALUE MAV_SYSID")
        assert g.params["MAV_SYSID"][0] == i + 1


def test_homes_are_spaced_east(fleet: tuple[ModelProcess, int, list[Gcs]]) -> None:
    _, _, stations = fleet
    homes = [g.home() for g in stations]
    for i, h in enumerate(homes):
        n, e, d = geodetic_to_ned(homes[0], *h)
        assert abs(n) < 0.05 and abs(d) < 0.05
        assert e == pytest.approx(5.0 * i, abs=0.05)


def test_each_vehicle_flies_independently(fleet: tuple[ModelProcess, int, list[Gcs]]) -> None:
    """Vehicle 1 arms and takes off in GUIDED; vehicles 0 and 2 stay disarmed on the ground."""
    _, _, stations = fleet
    flier = stations[1]
    flier.wait_prearm(flier.wall(60))
    flier.takeoff(5.0)
    for i in (0, 2):
        g = stations[i]
        assert not g.armed(), f"vehicle {i} armed with vehicle 1"
        assert g.mode() != GUIDED, f"vehicle {i} switched to GUIDED with vehicle 1"
        gp = g.fresh("GLOBAL_POSITION_INT")
        assert gp.get_srcSystem() == i + 1
        assert abs(gp.relative_alt) < 300, f"vehicle {i} left the ground: {gp.relative_alt} mm"
    assert flier.mode() == GUIDED
    gp = flier.fresh("GLOBAL_POSITION_INT")
    assert gp.get_srcSystem() == 2 and gp.relative_alt > 4000
    flier.land_and_disarm()


def test_mavproxy_tcp_port_answers_for_each_vehicle(fleet: tuple[ModelProcess, int, list[Gcs]]) -> None:
    _, base, _ = fleet
    for i in range(N):
        conn = mavutil.mavlink_connection(f"tcp:127.0.0.1:{ports(base + i)[0]}", source_system=254)
        try:
            hb = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=15)
            assert hb is not None, f"no HEARTBEAT on vehicle {i}'s TCP port"
            assert hb.get_srcSystem() == i + 1
        finally:
            conn.close()


def test_stopping_the_fleet_releases_every_port(tmp_path: Path) -> None:
    proc, base = start_fleet(tmp_path, n=2, speedup=2.0)
    try:
        assert not base_free(base, 2)
        g = Gcs(ports(base + 1)[1], 2.0, background=True, target=2)
        try:
            wait_for(lambda: g.last.get("HEARTBEAT") is not None, 30, "vehicle 1's heartbeat")
        finally:
            g.close()
    finally:
        assert proc.stop() == 0
    wait_for(lambda: base_free(base, 2), 10, "every port of the stopped fleet free again")


# --- in process: construction and lockstep ----------------------------------------------------------------
def test_lockstep_fleet_in_process_advances_every_vehicle_together(tmp_path: Path) -> None:
    with Fleet(2, speedup=0.0, state_dir=tmp_path, urls=[["udpin:127.0.0.1:0"]] * 2, persist=False) as f:
        done = f.run(1.0)
        assert done == 500 and f.rounds == 500  # the first period is the warm-up round, unpaced
        assert [s.vehicle.clock.now_us for s in f.vehicles] == [1_000_000, 1_000_000]
        assert [s.endpoint.sysid for s in f.vehicles] == [1, 2]
        a, b = (s.link.telemetry for s in f.vehicles)
        assert a.unix0_us == b.unix0_us  # one SYSTEM_TIME base
        # the vehicles' main loops run untimed: the fleet measures its shared period's lateness
        assert [s.vehicle.loop.stats.as_dict()["timed"] for s in f.vehicles] == [False, False]
        assert all(not g.buf for s in f.vehicles for g in s.vehicle.loop.stats.groups.values())
        assert f.lateness_s == type(f.lateness_s)()  # lockstep: never paced
        assert f.run(0.001) == 0 and f.run(0.003) == 2
        with pytest.raises(ValueError, match="duration"):
            f.run(-1.0)


def test_bad_input_is_refused_before_any_port_is_bound(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="at least one vehicle"):
        Fleet(0, state_dir=tmp_path)
    with pytest.raises(ValueError, match="2 homes for 3 vehicles"):
        Fleet(3, homes=[(0, 0, 0), (0, 0, 0)], state_dir=tmp_path)
    with pytest.raises(ValueError, match="system ids"):
        Fleet(3, first_sysid=254, state_dir=tmp_path)
    with pytest.raises(ValueError, match="speedup"):
        Fleet(1, speedup=-1, state_dir=tmp_path)
    with pytest.raises(ValueError, match="bad MAVLink URL template"):
        template_urls(["udpin:127.0.0.1:{port}"], 0)
    assert not list(tmp_path.iterdir())


def test_homes_and_templates() -> None:
    homes = fleet_homes(3, (-35.0, 149.0, 500.0, 90.0), spacing_m=10.0)
    assert homes[0] == (-35.0, 149.0, 500.0, 90.0)
    for i, h in enumerate(homes):
        assert len(h) == 4 and h[3] == 90.0
        n, e, d = geodetic_to_ned(homes[0][:3], *h[:3])
        assert math.isclose(e, 10.0 * i, abs_tol=1e-3) and abs(n) < 1e-6 and d == 0
    assert template_urls(["tcpin:0.0.0.0:{tcp}", "udpin:0.0.0.0:{udp}"], 3) == \
        ["tcpin:0.0.0.0:5790", "udpin:0.0.0.0:14580"]
    assert template_urls(["udpout:10.0.0.{sysid}:{udp}"], 7, sysid=2) == ["udpout:10.0.0.2:14620"]
    with pytest.raises(ValueError):
        fleet_homes(2, (1.0, 2.0))


def test_real_time_fleet_sleeps_instead_of_spinning(tmp_path: Path) -> None:
    """Paced on the wall (1 s simulated takes at least 1 s), waiting by sleeping only, never spinning (the
    clock's own counts of its sleeps and busy-wait looks). What that costs in CPU (a few percent of a core
    for 3 idle vehicles against ~45 % for one spinning vehicle) and how late periods start are bench
    figures, not asserted here: ``python -m bench.bench_fleet``."""
    import time

    with Fleet(3, speedup=1.0, state_dir=tmp_path, urls=[["udpin:127.0.0.1:0"]] * 3, persist=False) as f:
        f.run(0.1)  # warm-up round and first periods
        t0, sleeps0 = time.perf_counter(), f.clock.sleeps
        f.run(1.0)
        wall = time.perf_counter() - t0
        assert wall >= 0.98, f"not paced: 1 s simulated in {wall:.2f} s"  # a loaded machine only adds
        assert f.clock.spins == 0 and f.clock.sleeps > sleeps0
        assert len(f.lateness_s) >= 495  # every paced period's lateness is kept for the bench
        assert [s.vehicle.clock.now_us for s in f.vehicles] == [1_100_000] * 3


def test_sim_clock_without_spinning_sleeps_to_the_deadline() -> None:
    """``SimClock(spin_s=0)`` (the fleet's pacing) sleeps out each period, never spins; a clock with
    ``spin_s`` does spin (what the counter would show if the fleet did); bad spins refused."""
    from taskflight_common.clock import SimClock

    clock = SimClock(1.0, spin_s=0.0)
    for _ in range(25):
        clock.advance(2000)
        clock.pace()
        assert clock.wall_lag() >= 0.0  # never returns before the deadline
    assert clock.spins == 0 and clock.sleeps >= 1
    spinning = SimClock(1.0, spin_s=0.01)
    for _ in range(10):  # 20 ms periods: sleeps to 10 ms before each deadline, then spins
        spinning.advance(20_000)
        spinning.pace()
    assert spinning.spins > 0
    for bad in (-0.001, 0.5):
        with pytest.raises(ValueError, match="spin_s"):
            SimClock(1.0, spin_s=bad)


def test_command_line_refuses_bad_input_and_is_a_taskflight_command(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    from autopilot_model.fleet import main
    from taskflight.cli import build_parser

    assert main(["--vehicles", "0", "--state-dir", str(tmp_path)]) == 2
    assert "at least one vehicle" in caplog.text
    assert main(["--vehicles", "2", "--base-instance", "254", "--state-dir", str(tmp_path)]) == 2
    assert "not all within 0..254" in caplog.text
    assert not list(tmp_path.iterdir())
    args = build_parser().parse_args(["fleet", "--vehicles", "4", "--speedup", "2", "--spacing", "8"])
    assert (args.command, args.vehicles, args.speedup, args.spacing) == ("fleet", 4, 2.0, 8.0)
    assert args._handlers["fleet"].__name__ == "_cmd_fleet"


def test_homes_in_rows_of_ten_inside_the_platform_envelope() -> None:
    from autopilot_model.fleet import fleet_homes
    from taskflight_common.geo import geodetic_to_ned

    homes = fleet_homes(50, (-35.363261, 149.165230, 584.0), spacing_m=5.0)
    ned = [geodetic_to_ned((-35.363261, 149.165230, 584.0), *h[:3]) for h in homes]
    assert [(round(n, 3), round(e, 3)) for n, e, _ in ned[:12]] == [
        *((0.0, 5.0 * c) for c in range(10)), (-5.0, 0.0), (-5.0, 5.0)]
    assert len({(round(n, 1), round(e, 1)) for n, e, _ in ned}) == 50  # no two vehicles on one spot
    assert all(-20.01 <= n <= 0.0 and 0.0 <= e <= 45.01 for n, e, _ in ned)  # inside +-200 m, with room
