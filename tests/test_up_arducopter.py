"""``taskflight up --autopilot arducopter`` and the team demo on three ArduPilot copter SITLs.

The demo (``taskflight demo-team --autopilot arducopter``, what ``scripts/demo --autopilot arducopter``
runs) starts three ArduCopter SITL processes, their companions and the ground service, prints READY once
every vehicle's EKF uses GPS, and flies its scenario: the scan-and-search mission on vehicle 1, a visit and
a patrol line for the team. The report must say every task flown; a pymavlink ground station on each
SITL's SERIAL1 (the TCP port the summary prints) judges it independently from the autopilots' own
LOCAL_POSITION_NED: vehicle 1 scanned north of its home, flew to the fly-to point and landed; the visit's
holder reached the visit point, the patrol's holder both ends of the line. When the demo has ended no
SITL, companion or ground service is left. Needs ``TASKFLIGHT_ARDUCOPTER`` (skipped, saying why, without
it); the error without the variable is checked everywhere.
"""

from __future__ import annotations

import logging
import math
import os
import re
import signal
import socket
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path

import pytest

from harness.arducopter import arducopter_missing
from harness.observer import GUIDED, Gcs
from harness.timing import wait_for
from harness.up import UpProcess, alive, child_env, processes_mentioning
from taskflight import arducopter_fleet
from taskflight.up import ground_available
from taskflight_common.geo import home_offset
from taskflight_common.ports import free_base, free_ports, port_free

pytestmark = pytest.mark.integration
MAV_RESULT_ACCEPTED, MAV_CMD_COMPONENT_ARM_DISARM = 0, 400
log = logging.getLogger(__name__)

N = 3
SPEEDUP = 3.0
#: the fleet's home (CMAC); vehicle i stands 5 i m east of it, and its local positions are from its own
VISIT = (-20.0, 25.0)
PATROL = ((0.0, -30.0), (20.0, -30.0))
FLY_TO = (0.0, 2.0, -5.0)  # scan_and_search_outdoor.yaml's fly-to point, north/east/down of home
REACHED_M = 3.0


def free_arducopter_base(n: int) -> int:
    """A base instance whose model ports and ArduCopter's own (SERIAL2, RC input) are all free."""
    for _ in range(20):
        base = free_base(n)
        if not arducopter_fleet.ports_taken(base, n, 1):
            return base
    raise RuntimeError(f"no block of {n} instances with every ArduCopter port free")


def local(point: tuple[float, float], index: int) -> tuple[float, float]:
    """``point`` (north, east of the fleet's home) in vehicle ``index``'s own frame."""
    north, east = home_offset(index, arducopter_fleet.SPACING_M)
    return point[0] - north, point[1] - east


def closest(track: list[tuple[float, float, float]], point: tuple[float, float]) -> float:
    return min((math.hypot(n - point[0], e - point[1]) for n, e, _ in track), default=math.inf)


@pytest.mark.skipif(arducopter_missing() is not None, reason=arducopter_missing() or "")
def test_the_team_demo_flies_on_three_arducopter_sitls(
        tmp_path: Path, record_property: Callable[[str, object], None]) -> None:
    base = free_arducopter_base(N)
    args = ["--autopilot", "arducopter", "--speedup", f"{SPEEDUP:g}", "--patrol", "40",
            "--base-instance", str(base)]
    args += ["--ground-port", str(free_ports(1, socket.SOCK_STREAM)[0])] if ground_available() else \
        ["--no-ground"]
    t0 = time.monotonic()
    demo = UpProcess(args, tmp_path / "demo", command="demo-team")
    observers: list[Gcs] = []
    try:
        summary = demo.wait_ready(300)
        ready = demo.wait_line("READY", 1)
        assert "ArduCopter SITL (every EKF using GPS)" in ready, ready
        started = float(ready.rsplit("started in ", 1)[1].split()[0])
        assert summary.tcp == [5760 + 10 * (base + i) for i in range(N)]
        sitls = {k: p for k, p in summary.pids.items() if k.startswith("arducopter")}
        assert len(sitls) == N and all(alive(p) for p in sitls.values()), summary.pids
        for i, port in enumerate(summary.tcp):  # an independent ground station on each SITL's SERIAL1
            gcs = Gcs(0, SPEEDUP, url=f"tcp:127.0.0.1:{port}", background=True, target=i + 1)
            observers.append(gcs)

            def streaming(gcs: Gcs = gcs) -> bool:
                gcs.request_streams(10)
                return bool(gcs.positions)

            wait_for(streaming, 30, f"LOCAL_POSITION_NED from vehicle {i + 1}", poll_s=0.5)
        demo.wait_line("=== team demo report ===", 600)  # the mission has ended, vehicle 1 has landed
        tracks = [list(g.positions) for g in observers]
        for g in observers:  # before the demo stops the SITLs
            g.close()
        rc = demo.proc.wait(120)
        wall_s = time.monotonic() - t0
        out = demo.output
        assert rc == 0, out
        log.info("ArduCopter team demo: start-up (until ready) %.1f s, demo wall time %.1f s",
                 started, wall_s)
        record_property("startup_s", started)
        record_property("demo_wall_s", wall_s)

        # the report: the mission succeeded, the visit done and the patrol cancelled by vehicles 2 and 3
        assert "vehicle 1: mission scan-and-search-outdoor: succeeded" in out
        # each task's holders in the order they held it (the team may hand a task on): the last flew it
        held = {kind: (state, [int(v) for v in re.findall(r"\d+", who)]) for kind, state, who in re.findall(
            r"^\s+\d+ (visit|patrol_line)\s+\S+\s+(\w+)\s+held by ((?:vehicle \d+(?:, )?)+)$", out, re.M)}
        assert {k: s for k, (s, _) in held.items()} == {"visit": "done", "patrol_line": "cancelled"}, out
        assert all(set(who) <= {2, 3} for _, who in held.values()), out  # vehicle 1 flies its mission
        flown = re.findall(r"flight time ([\d.]+) s, (\d+) m flown; tracking h rms ([\d.]+) m", out)
        assert len(flown) == N and all(float(t) > 5 and float(h) < 1.0 for t, _d, h in flown), out

        # judged from the autopilots themselves
        for i, track in enumerate(tracks):
            assert max(-z for *_, z in track) > 4.0, f"vehicle {i + 1} never climbed: {track[-3:]}"
        v1 = tracks[0]
        assert max(n for n, _, _ in v1) > 6.0, "vehicle 1 did not scan the area 2-10 m north of its home"
        assert min(math.dist(p, FLY_TO) for p in v1) < 1.5, "vehicle 1 did not reach its fly-to point"
        assert -v1[-1][2] < 1.0, f"vehicle 1 did not land: {v1[-1]}"
        visitor, patroller = held["visit"][1][-1], held["patrol_line"][1][-1]
        missed = {"visit": closest(tracks[visitor - 1], local(VISIT, visitor - 1)),
                  **{f"patrol end {end}": closest(tracks[patroller - 1], local(end, patroller - 1))
                     for end in PATROL}}
        log.info("closest approach (m): %s", ", ".join(f"{k} {v:.2f}" for k, v in missed.items()))
        assert all(v < REACHED_M for v in missed.values()), missed
    finally:
        for g in observers:
            g.close()
        demo.close()
    # nothing left behind: no SITL, companion or ground service; every SITL port free again
    assert [p for p in summary.pids.values() if alive(p)] == []
    assert processes_mentioning(str(tmp_path)) == []
    for i in range(N):
        for port in (5760 + 10 * (base + i), arducopter_fleet.watch_port(base + i)):
            wait_for(partial(port_free, socket.SOCK_STREAM, port), 10, f"TCP {port} free")


@pytest.mark.parametrize("value", [None, "/nonexistent/arducopter"])
def test_without_the_binary_up_says_which_variable_and_starts_nothing(tmp_path: Path,
                                                                       value: str | None) -> None:
    env = child_env()
    env.pop("TASKFLIGHT_ARDUCOPTER", None)
    if value is not None:
        env["TASKFLIGHT_ARDUCOPTER"] = value
    state = tmp_path / "state"
    up = UpProcess(["--autopilot", "arducopter", "--vehicles", "2", "--base-instance", str(free_base(2)),
                    "--no-ground"], state, env=env)
    try:
        rc = up.proc.wait(60)
    finally:
        up.close()
    assert rc == 2, up.output
    assert "TASKFLIGHT_ARDUCOPTER" in up.output and "error" in up.output
    assert (value or "needs TASKFLIGHT_ARDUCOPTER=") in up.output
    assert not state.exists()  # nothing was started, nothing written
    assert processes_mentioning(str(tmp_path)) == []


def test_a_missing_parameter_file_is_named_and_nothing_starts(tmp_path: Path) -> None:
    env = {**child_env(), "TASKFLIGHT_ARDUCOPTER": "/bin/true",
           "TASKFLIGHT_ARDUCOPTER_DEFAULTS": str(tmp_path / "nowhere.parm")}
    up = UpProcess(["--autopilot", "arducopter", "--vehicles", "1", "--no-ground"], tmp_path / "state",
                   env=env)
    try:
        rc = up.proc.wait(60)
    finally:
        up.close()
    assert rc == 2 and f"copter.parm not found at {tmp_path / 'nowhere.parm'}" in up.output, up.output
    assert "TASKFLIGHT_ARDUCOPTER_DEFAULTS" in up.output and not (tmp_path / "state").exists()


def test_a_sitl_dying_at_start_up_is_reported_and_everything_stops(tmp_path: Path) -> None:
    """A SITL that exits while the fleet starts (here a "binary" that exits 1 at once): its name and exit
    status are reported, every other child is stopped (exit 1)."""
    parm = tmp_path / "copter.parm"
    parm.write_text("FRAME_CLASS 1\n")
    env = {**child_env(), "TASKFLIGHT_ARDUCOPTER": "/bin/false", "TASKFLIGHT_ARDUCOPTER_DEFAULTS": str(parm)}
    up = UpProcess(["--autopilot", "arducopter", "--vehicles", "2", "--base-instance",
                    str(free_arducopter_base(2)), "--no-ground"], tmp_path / "state", env=env)
    try:
        rc = up.proc.wait(120)
    finally:
        up.close()
    assert rc == 1, up.output
    assert re.search(r"arducopter\d \(pid \d+\) exited with status 1 during start-up", up.output), up.output
    assert processes_mentioning(str(tmp_path)) == []


@pytest.mark.parametrize(("option", "said"), [(["--speedup", "0"], "--speedup 0 (as fast as possible)"),
                                               (["--mavlink-host", "10.1.2.3"], "every interface")])
def test_what_arducopter_cannot_do_is_refused(tmp_path: Path, option: list[str], said: str) -> None:
    """``--speedup 0`` (the model's lockstep) and a MAVLink bind address SITL cannot honour are refused,
    saying why, rather than run some other way."""
    env = child_env()
    env["TASKFLIGHT_ARDUCOPTER"] = os.environ.get("TASKFLIGHT_ARDUCOPTER", "/bin/true")
    up = UpProcess(["--autopilot", "arducopter", "--vehicles", "1", *option, "--no-ground"],
                   tmp_path / "state", env=env)
    try:
        rc = up.proc.wait(60)
    finally:
        up.close()
    assert rc == 2 and said in up.output and "ArduCopter" in up.output, up.output
    assert not (tmp_path / "state").exists()


@pytest.mark.skipif(arducopter_missing() is not None, reason=arducopter_missing() or "")
def test_ready_means_ready_to_arm_and_ctrl_c_stops_every_sitl(tmp_path: Path) -> None:
    """READY only once each vehicle can arm (GUIDED and arming accepted at the first try, from a ground
    station on its SERIAL1); Ctrl-C then stops every SITL, companion and the ground service, ports freed."""
    base = free_arducopter_base(2)
    up = UpProcess(["--autopilot", "arducopter", "--vehicles", "2", "--speedup", f"{SPEEDUP:g}",
                    "--base-instance", str(base), "--no-ground"], tmp_path / "state")
    try:
        summary = up.wait_ready(300)
        sitls = [summary.pids[f"arducopter{i + 1}"] for i in range(2)]
        assert all(alive(p) for p in sitls)
        for i, port in enumerate(summary.tcp):
            gcs = Gcs(0, SPEEDUP, url=f"tcp:127.0.0.1:{port}", background=True, target=i + 1)
            try:
                assert gcs.set_mode(GUIDED) == MAV_RESULT_ACCEPTED, gcs.texts[-5:]
                assert gcs.command(MAV_CMD_COMPONENT_ARM_DISARM, 1) == MAV_RESULT_ACCEPTED, gcs.texts[-5:]
            finally:
                gcs.close()
        assert up.interrupt(60) == 0, up.output
        assert "taskflight up: stopped" in up.output
    finally:
        up.close()
    assert [p for p in summary.pids.values() if alive(p)] == []
    assert processes_mentioning(str(tmp_path)) == []
    for i in range(2):
        for port in (5760 + 10 * (base + i), arducopter_fleet.watch_port(base + i)):
            wait_for(partial(port_free, socket.SOCK_STREAM, port), 10, f"TCP {port} free")


@pytest.mark.skipif(arducopter_missing() is not None, reason=arducopter_missing() or "")
def test_sigkill_of_up_stops_its_sitl_by_itself(tmp_path: Path) -> None:
    """``taskflight up`` killed outright: its SITL stops on the parent-death signal, as the model does."""
    up = UpProcess(["--autopilot", "arducopter", "--vehicles", "1", "--speedup", f"{SPEEDUP:g}",
                    "--base-instance", str(free_arducopter_base(1)), "--no-ground"], tmp_path / "state")
    pids: dict[str, int] = {}
    try:
        pids = dict(up.wait_ready(300).pids)
        assert "arducopter1" in pids and all(alive(p) for p in pids.values()), pids
        up.proc.send_signal(signal.SIGKILL)
        up.proc.wait(10)
        wait_for(lambda: not [p for p in pids.values() if alive(p)], 30,
                 f"every child of the killed taskflight up gone: {pids}")
    finally:
        up.close()
        for pid in [p for p in pids.values() if alive(p)]:
            os.kill(pid, signal.SIGKILL)
