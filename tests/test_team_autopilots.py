"""One team member flying each autopilot (seed 003 Sec. III): the bundled model, and
ArduPilot's own copter SITL with ``TASKFLIGHT_ARDUCOPTER`` (skipped, saying why, without it).

A companion process joins a team link (``--team``) with the outdoor platform; the team-control station
(in the test) gives a visit and a patrol line: the member claims each, takes off and flies the visit (the
autopilot's GLOBAL_POSITION_INT reaches it), flies the patrol back and forth until it is cancelled, then
loiters in the team; every streamed setpoint stays within the continuity bound.
"""

from __future__ import annotations

import math
import socket
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from companion.flight.limits import Limits
from companion.flightlog import log_violations, read_flight_log
from companion.team.station import TeamControlStation
from companion.team.tasks import TaskDef
from companion.team.transport import open_transport
from harness import ROOT
from harness.autopilot import AUTOPILOTS, Autopilot, start_autopilot
from harness.team import PLATFORM, distance_m, geo, new_team_url
from harness.timing import wait_for
from taskflight.sitlproc import stop_child
from taskflight_common.ports import free_ports

pytestmark = pytest.mark.integration

SPEEDUP = 3.0


class Member:
    def __init__(self, kind: str, tmp: Path) -> None:
        self.ap: Autopilot = start_autopilot(kind, tmp, SPEEDUP)
        self.url = new_team_url()
        self.port = free_ports(1, socket.SOCK_STREAM)[0]
        self.log = tmp / "flight.jsonl"
        out = open(tmp / "companion.out", "ab")  # noqa: SIM115 - the child owns it
        exe = str(Path(sys.executable).with_name("taskflight"))
        self.proc = subprocess.Popen(
            [exe, "companion", "--autopilot", self.ap.companion_url,
             "--team", self.url, "--control-port", str(self.port), "--platform", str(PLATFORM),
             "--flight-log", str(self.log)], stdout=out, stderr=subprocess.STDOUT, cwd=ROOT)
        out.close()
        self.station = TeamControlStation(open_transport(self.url)).start()

    def wall(self, sim_s: float) -> float:
        return 10.0 + 2.0 * sim_s / SPEEDUP

    def team(self) -> dict[str, Any]:
        with httpx.Client(base_url=f"http://127.0.0.1:{self.port}", timeout=10) as c:
            return c.get("/team").json()

    def state(self, tid: int) -> str:
        return dict((v.id, v.state) for v in self.station.tasks())[tid]

    def position(self) -> tuple[float, float, float] | None:
        m = self.ap.gcs.last.get("GLOBAL_POSITION_INT")
        return None if m is None else (m.lat * 1e-7, m.lon * 1e-7, m.relative_alt * 1e-3)

    def close(self) -> None:
        self.station.close()
        stop_child(self.proc, 10.0)
        self.ap.close()


@pytest.fixture(scope="module", params=AUTOPILOTS)
def member(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Member]:
    m = Member(request.param, tmp_path_factory.mktemp(f"team_{request.param}"))
    try:
        wait_for(lambda: len(m.station.vehicle_rows()) == 1, 60, "the vehicle heard on the team link")
        yield m
    finally:
        m.close()


def test_team_member_flies_a_visit_and_a_patrol_then_loiters(member: Member) -> None:
    st = member.station
    target = geo(15, 10, 8)
    visit = st.add(TaskDef("visit", (target,), name="visit")).ids[0]
    closest = math.inf

    def flown() -> bool:
        nonlocal closest
        p = member.position()
        if p is not None:
            closest = min(closest, distance_m(p, target))
        return member.state(visit) == "done"

    wait_for(flown, 120 + member.wall(120), f"the visit flown ({member.ap.describe()})", poll_s=0.1)
    assert closest < 1.5, f"closest approach {closest:.2f} m (the autopilot's GLOBAL_POSITION_INT)"
    patrol = st.add(TaskDef("patrol_line", (geo(15, -10, 8), geo(15, 10, 8)), name="patrol")).ids[0]
    wait_for(lambda: member.state(patrol) == "active", member.wall(60), "the patrol flown")
    ends = {False: False, True: False}

    def both_ends() -> bool:
        p = member.position()
        if p is not None:
            ends[False] |= distance_m(p, geo(15, -10)) < 2.0
            ends[True] |= distance_m(p, geo(15, 10)) < 2.0
        return ends[False] and ends[True]

    wait_for(both_ends, member.wall(90), "the patrol flown to both ends", poll_s=0.1)
    st.cancel(patrol)
    wait_for(lambda: (t := member.team())["controller"] == "loiter" and not t["claims"], member.wall(30),
             "loitering after the cancel")
    assert member.team()["status"] == "idle"
    assert log_violations(read_flight_log(member.log), Limits()) == []
