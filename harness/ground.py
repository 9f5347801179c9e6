"""The ground service over loopback for the tests: in-process or as ``taskflight ground``.

* :class:`InProcessGround`: :class:`~groundstation.service.GroundService` + uvicorn in a thread on a free
  port (unit-ish API tests);
* :class:`GroundProcess`: ``taskflight ground`` as a child process (killed with SIGKILL and restarted
  on the same database by the restart test; the service the ground and UI benches load);
* :class:`GroundRig`: a fleet of N models in one process, N companion processes on a team link and the
  ground service as the team's station (no station in the test process), with a pymavlink ground
  station per vehicle (positions read from the autopilots, not from the service).
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import httpx
import uvicorn
import yaml
from websockets.sync.client import ClientConnection, connect

from groundstation.app import create_app
from groundstation.auth import Tokens
from groundstation.service import GroundService
from harness import ROOT
from harness.fleet import ports, start_fleet
from harness.observer import Gcs
from harness.team import PLATFORM, new_team_url
from harness.timing import wait_for
from taskflight.sitlproc import stop_child
from taskflight_common.ports import free_ports
from taskflight_common.tokens import TOKEN_ENV

OPERATOR, OBSERVER = "op-token-for-tests", "ob-token-for-tests"
#: a second operator (two operators' pages, one stick lease)
OPERATOR2 = "op2-token-for-tests"
TOKENS = {"operator": [OPERATOR, OPERATOR2], "observer": [OBSERVER]}
COMPANION_TOKEN = "companion-token-for-tests"


class _Api:
    """HTTP and WebSocket clients of a ground service at ``self.url``."""

    url: str

    def http(self, token: str | None = OPERATOR, timeout: float = 15.0) -> httpx.Client:
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        return httpx.Client(base_url=self.url, headers=headers, timeout=timeout)

    def ws(self, token: str | None = OPERATOR, in_query: bool = True) -> ClientConnection:
        ws_url = self.url.replace("http://", "ws://") + "/api/ws"
        if token and in_query:
            ws_url += f"?token={token}"
        c = connect(ws_url, open_timeout=10)
        if token and not in_query:
            c.send(json.dumps({"type": "auth", "token": token}))
        return c

    def alive(self) -> bool:
        try:
            with self.http() as c:
                return c.get("/api/whoami").status_code == 200
        except httpx.HTTPError:
            return False


class InProcessGround(_Api):
    """The service and uvicorn in this process (a thread), on a free port."""

    def __init__(self, tmp: Path, team_url: str | None = None, companions: dict[int, str] | None = None,
                 snapshot_period_s: float = 0.1, fence: list[list[float]] | None = None) -> None:
        self.team_url = team_url or new_team_url()
        self.service = GroundService(str(tmp / "ground.db"), Tokens(TOKENS), team_url=self.team_url,
                                     companions=companions, fence=fence).start()
        port = free_ports(1, socket.SOCK_STREAM)[0]
        self.url = f"http://127.0.0.1:{port}"
        config = uvicorn.Config(create_app(self.service, snapshot_period_s), host="127.0.0.1", port=port,
                                log_level="warning", ws="websockets-sansio")
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(target=self.server.run, daemon=True)
        self.thread.start()
        wait_for(self.alive, 30, "the ground service answering")

    def close(self) -> None:
        self.server.should_exit = True
        self.thread.join(10)
        self.service.close()


class GroundProcess(_Api):
    """``taskflight ground`` as a child process (a fixed port and database, so it can be restarted)."""

    def __init__(self, tmp: Path, team_url: str, companions: dict[int, str], port: int | None = None) -> None:
        self.tmp, self.team_url, self.companions = tmp, team_url, companions
        self.port = port or free_ports(1, socket.SOCK_STREAM)[0]
        self.url = f"http://127.0.0.1:{self.port}"
        self.db = tmp / "ground.db"
        self.tokens = tmp / "tokens.yaml"
        self.tokens.write_text(yaml.safe_dump(TOKENS))
        self.proc: subprocess.Popen[bytes] | None = None
        self.runs = 0

    def start(self) -> GroundProcess:
        # python -m from the repository root: this checkout's code (the console script may be another's)
        args = [sys.executable, "-m", "taskflight.cli", "ground", "--team", self.team_url,
                "--db", str(self.db),
                "--host", "127.0.0.1", "--port", str(self.port), "--tokens", str(self.tokens)]
        for vid, url in self.companions.items():
            args += ["--companion", f"{vid}={url}"]
        out = open(self.tmp / f"ground{self.runs}.out", "ab")  # noqa: SIM115 - the child owns it
        self.runs += 1
        # the token in the environment: never on a command line (ps shows it to every user)
        self.proc = subprocess.Popen(args, stdout=out, stderr=subprocess.STDOUT, cwd=ROOT,
                                     env={**os.environ, TOKEN_ENV: COMPANION_TOKEN})
        out.close()
        # a deadline for a machine loaded by other suites (start-up imports take ~1 min at load 40)
        wait_for(lambda: self.proc.poll() is not None or self.alive(), 180, "taskflight ground answering")
        assert self.proc.poll() is None, (self.tmp / f"ground{self.runs - 1}.out").read_text()
        return self

    def kill(self) -> None:
        """SIGKILL: no clean-up of any kind."""
        assert self.proc is not None
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(10)
        self.proc = None

    def close(self) -> None:
        if self.proc is not None:
            stop_child(self.proc, 10.0)
            self.proc = None


class GroundRig:
    """See module docstring. ``speedup`` is the models' (the companions follow autopilot time)."""

    def __init__(self, tmp: Path, n: int = 3, speedup: float = 3.0) -> None:
        self.tmp, self.n, self.speedup = tmp, n, speedup
        self.fleet, self.base = start_fleet(tmp / "fleet", n, speedup)
        self.team_url = new_team_url()
        self.control_ports = free_ports(n, socket.SOCK_STREAM)
        self.companions: list[subprocess.Popen[bytes] | None] = [None] * n
        self.gcs: list[Gcs] = []
        self.ground: GroundProcess | None = None
        try:
            for i in range(n):
                self.start_companion(i)
            urls = {i + 1: f"http://127.0.0.1:{self.control_ports[i]}" for i in range(n)}
            self.ground = GroundProcess(tmp, self.team_url, urls).start()
            self._observe()
        except BaseException:
            self.close()
            raise

    def _observe(self) -> None:
        """A pymavlink ground station per vehicle (target its system id), the 10 Hz track sampler, then
        the wait for every vehicle in the team with its companion answering."""
        for i in range(self.n):
            g = Gcs(ports(self.base + i)[1], self.speedup, background=True, target=i + 1)
            g.request_streams(10)
            self.gcs.append(g)
        self.tracks: list[list[tuple[float, float, float, float]]] = [[] for _ in range(self.n)]
        self._stop = threading.Event()
        self._sampler = threading.Thread(target=self._sample, daemon=True)
        self._sampler.start()
        wait_for(lambda: self.ready(), 120, f"{self.n} vehicles in the team, companions answering")

    def start_companion(self, i: int) -> None:
        exe = Path(sys.executable).with_name("taskflight")
        # vehicle 3's camera sees a person 1 m north of where it takes off (its home is 10 m east of the
        # fleet's), as soon as it climbs
        scenario = self.tmp / "scenario3.yaml"
        scenario.write_text("objects:\n  - {id: 7, class: person, position: [1.0, 0.0]}\n")
        extra = ["--scenario", str(scenario)] if i == 2 else []
        out = open(self.tmp / f"companion{i}.out", "ab")  # noqa: SIM115 - the child owns it
        self.companions[i] = subprocess.Popen(
            [str(exe), "companion", "--autopilot", f"udpout:127.0.0.1:{ports(self.base + i)[1]}",
             "--team", self.team_url, "--control-port", str(self.control_ports[i]),
             "--control-token", COMPANION_TOKEN, "--platform", str(PLATFORM),
             "--flight-log", str(self.tmp / f"flight{i}.jsonl"), *extra],
            stdout=out, stderr=subprocess.STDOUT, cwd=ROOT)
        out.close()

    def vehicles(self) -> dict[int, dict[str, Any]]:
        with self.ground.http() as c:
            return {v["id"]: v for v in c.get("/api/vehicles").json()["vehicles"]}

    def ready(self) -> bool:
        try:
            vs = self.vehicles()
        except (httpx.HTTPError, ValueError, KeyError):
            return False
        return len(vs) == self.n and all(v["team_state"] == "available" and v["companion"] == "ok"
                                         for v in vs.values())

    def _sample(self) -> None:
        """Every vehicle's MAVLink position at 10 Hz: (wall time, lat, lon, alt)."""
        while not self._stop.wait(0.1):
            for i in range(self.n):
                p = self.position(i)
                if p is not None:
                    self.tracks[i].append((time.monotonic(), *p))

    def close(self) -> None:
        if hasattr(self, "_stop"):
            self._stop.set()
        for g in self.gcs:
            g.close()
        if self.ground is not None:
            self.ground.close()
        for p in self.companions:
            if p is not None:
                stop_child(p, 10.0)
        self.fleet.stop()

    def position(self, i: int) -> tuple[float, float, float] | None:
        """Vehicle i's (lat, lon, alt above home) from its autopilot's GLOBAL_POSITION_INT (MAVLink)."""
        m = self.gcs[i].last.get("GLOBAL_POSITION_INT")
        return None if m is None else (m.lat * 1e-7, m.lon * 1e-7, m.relative_alt * 1e-3)

    def velocity(self, i: int) -> tuple[float, float, float] | None:
        m = self.gcs[i].last.get("GLOBAL_POSITION_INT")
        return None if m is None else (m.vx * 0.01, m.vy * 0.01, m.vz * 0.01)

    def wall(self, sim_s: float) -> float:
        return 5.0 + 2.0 * sim_s / self.speedup

    def tasks(self) -> dict[int, dict[str, Any]]:
        with self.ground.http() as c:
            return {t["id"]: t for t in c.get("/api/tasks").json()["tasks"]}


def track(rig: GroundRig, i: int, seconds: float, period_s: float = 0.1) -> list[tuple[float, float, float]]:
    """Vehicle i's positions over ``seconds`` of wall time (MAVLink)."""
    out = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        p = rig.position(i)
        if p is not None:
            out.append(p)
        time.sleep(period_s)
    return out
