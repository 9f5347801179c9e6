"""``taskflight team control``: a station process giving a task file's tasks to a team.

The station under test runs as its own process on a real loopback multicast team link; the team is one
scripted member in the test process (a real GroupState and TeamLink, a collaborator not under test): it
claims every live task it hears of and reports it done a moment later. The station must add the tasks at
their times, print the assignment as it changes, mark the tasks done from the member's row, print the
final table and exit 0 once every task is over; a bad file exits 2 naming file, line and field.
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

from companion.team.groupstate import GroupState
from companion.team.link import TeamLink
from companion.team.transport import open_transport
from companion.team.types import Claim, ClaimState, MemberEntry, MemberStatus
from harness.team import geo, new_team_url

pytestmark = pytest.mark.integration

EXE = str(Path(sys.executable).with_name("taskflight"))


def _task_file(tmp: Path) -> Path:
    v1, v2 = geo(20, 0, 10), geo(-20, 0, 10)
    path = tmp / "tasks.yaml"
    path.write_text(f"""team: cli-test
tasks:
  - {{name: north, kind: visit, points: [[{v1[0]}, {v1[1]}]], altitude: 10, at: 0}}
  - {{name: south, kind: visit, points: [[{v2[0]}, {v2[1]}]], altitude: 10, at: 1.0}}
""")
    return path


def test_station_cli_gives_the_tasks_and_follows_the_team(tmp_path: Path) -> None:
    url = new_team_url()
    proc = subprocess.Popen([EXE, "team", "control", "--team", url, "--tasks", str(_task_file(tmp_path)),
                             "--duration", "60"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    state = GroupState(7)
    claims: dict[int, Claim] = {}
    first_seen: dict[int, float] = {}

    def own() -> MemberEntry:
        return MemberEntry(member=7, stamp=0.0, seq=0, position=geo(0, 0, 10), status=MemberStatus.IDLE,
                           claims=tuple(claims.values()), name="scripted")

    link = TeamLink(state, open_transport(url), period_s=0.2, own=own)
    try:
        deadline = time.monotonic() + 40
        while proc.poll() is None and time.monotonic() < deadline:
            link.step()
            now = time.monotonic()
            for t in state.board.live():
                first_seen.setdefault(t.id, now)
                done = now - first_seen[t.id] > 1.0
                claims[t.id] = Claim(t.id, t.version, 12.5, ClaimState.DONE if done else ClaimState.ACTIVE)
            for tid in [tid for tid in claims if (t := state.board.get(tid)) is not None and t.state.final]:
                del claims[tid]
            time.sleep(0.02)
        out, _ = proc.communicate(timeout=20)
    finally:
        link.close()
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, out
    assert "added" in out and "joined member=7" in out
    assert "state=active holder=7" in out and "state=done holder=7" in out
    table = out[out.index("task kind"):] if "task kind" in out else out.split("\n", 200)[-4:]
    assert "visit" in str(table) and str(table).count("done") == 2, out


def test_station_cli_refuses_a_bad_task_file(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("team: bad\ntasks:\n  - {name: x, kind: visit, points: [[95.0, 0.0]], at: 0}\n")
    r = subprocess.run([EXE, "team", "control", "--team", "udp://239.255.70.1:14650", "--tasks", str(bad)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2
    assert "bad.yaml:3" in r.stderr and "points" in r.stderr
