"""Nothing flies from an old run by itself, and no token is on a command line.

The state folder of an earlier run holds a ground database with an open visit (made here by the ground
service's own code). ``taskflight up --vehicles 2`` on that folder: the visit comes back *held*; sampled
for 10 s with both vehicles in the team, it stays held and no vehicle claims or flies it; released
through REST, the team flies it. ``ps`` (every process's command line in /proc) shows neither the
ground's companion token nor any ``--companion-token``.
"""

from __future__ import annotations

import socket
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from companion.team.tasks import TaskDef
from groundstation.auth import Tokens
from groundstation.service import GroundService
from harness.ground import OPERATOR, TOKENS
from harness.team import geo, new_team_url
from harness.timing import wait_for
from harness.up import Summary, UpProcess, processes_mentioning
from taskflight.team_tasking import http_json
from taskflight_common.ports import free_base, free_ports
from taskflight_common.tokens import TOKEN_ENV

pytestmark = pytest.mark.integration

#: 15 m north-east of the models' home, 6 m up (the outdoor platform's floor is 3 m)
POINT = tuple(geo(15, 15, 6))


class Run:
    def __init__(self, up: UpProcess, summary: Summary, task: int, state: Path) -> None:
        self.up, self.summary, self.task, self.state = up, summary, task, state

    def get(self, path: str) -> dict:
        assert self.summary.ground
        return http_json("GET", self.summary.ground + path, OPERATOR, timeout_s=10.0)


@pytest.fixture(scope="module")
def old_run(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Run]:
    state = tmp_path_factory.mktemp("old_run")
    earlier = GroundService(str(state / "ground.db"), Tokens(TOKENS), team_url=new_team_url())
    task = earlier.station.add(TaskDef("visit", (POINT,), name="left from an earlier run")).ids[0]
    earlier.close()
    tokens = state / "tokens.yaml"
    tokens.write_text(f"operator: [{OPERATOR}]\nobserver: [{TOKENS['observer'][0]}]\n")
    tokens.chmod(0o600)
    up = UpProcess(["--vehicles", "2", "--speedup", "3", "--base-instance", str(free_base(2)),
                    "--ground-port", str(free_ports(1, socket.SOCK_STREAM)[0]), "--tokens", str(tokens),
                    "--no-persist"], state)
    try:
        yield Run(up, up.wait_ready(300.0), task, state)
    finally:
        up.close()


def test_the_open_task_of_an_earlier_run_is_held_until_released(old_run: Run) -> None:
    def task() -> dict:
        return next(t for t in old_run.get("/api/tasks")["tasks"] if t["id"] == old_run.task)

    wait_for(lambda: all(v["team_state"] == "available" for v in old_run.get("/api/vehicles")["vehicles"]),
             60, "both vehicles in the team")
    end = time.monotonic() + 10.0
    samples = 0
    while time.monotonic() < end:  # the invariant over a window with both vehicles free to claim it
        assert task()["state"] == "held", task()
        for v in old_run.get("/api/vehicles")["vehicles"]:
            assert v["task"] != old_run.task and all(c["task"] != old_run.task for c in v["claims"]), v
        samples += 1
        time.sleep(0.5)
    assert samples >= 5
    assert any(e["kind"] == "restored" and old_run.task in e["data"].get("held", [])
               for e in old_run.get("/api/events")["events"])
    assert old_run.summary.ground
    released = http_json("POST", old_run.summary.ground + "/api/tasks/release", OPERATOR,
                         {"ids": [old_run.task]})
    assert released["released"] == [old_run.task] and released["held"] == []
    wait_for(lambda: task()["state"] in ("assigned", "active", "done"), 120,
             "the released task taken by the team")


def test_no_token_on_any_command_line(old_run: Run) -> None:
    ground = old_run.summary.pids["ground"]
    cmdline = Path(f"/proc/{ground}/cmdline").read_bytes().split(b"\0")
    assert not any(a.startswith(b"--companion-token") for a in cmdline), cmdline
    raw = Path(f"/proc/{ground}/environ").read_bytes().split(b"\0")
    environ = dict(e.split(b"=", 1) for e in raw if b"=" in e)
    token = environ[TOKEN_ENV.encode()].decode()  # the ground service has it, in its environment
    assert len(token) >= 16 and processes_mentioning(token) == []
