"""A team on several hosts for the tests: a ground host and two vehicle hosts (:class:`~harness.netns.Lan`).

:class:`HostsRig` starts ``taskflight ground`` on host ``g`` and ``taskflight up --no-ground --vehicles 1
--first-sysid K`` on hosts ``a`` (K = 1) and ``b`` (K = 2), each in its own network namespace, with nothing
in common but the team URL and the files an operator copies to every host (the team key, the control
token). It observes each vehicle with a pymavlink ground station on its model's TCP port inside the
vehicle's host (the autopilot's own MAVLink stream, not the companion's report), and samples the ground
service's view of the team (``GET /api/vehicles``: each vehicle's team state and claims) for the whole run.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from pathlib import Path
from typing import Any

import httpx
import yaml

from companion.team.auth import generate_key_file
from harness import ROOT
from harness.ground import COMPANION_TOKEN, OPERATOR, TOKENS
from harness.netns import InHost, Lan
from harness.observer import Gcs
from harness.timing import wait_for
from taskflight_common.tokens import TOKEN_ENV

GROUND_PORT = 8700
#: the model's TCP port of instance 0 (a ground station's): every vehicle host runs instance 0
MODEL_TCP = 5760
VEHICLE_HOSTS = {"a": 1, "b": 2}  # host -> first system id


class HostsRig:
    """See module docstring. ``speedup`` is the models' (the companions follow autopilot time)."""

    def __init__(self, tmp: Path, team_url: str, speedup: float = 3.0) -> None:
        self.tmp, self.team_url, self.speedup = tmp, team_url, speedup
        self.transport = team_url.split(":", 1)[0]
        self.lan = Lan(["g", *VEHICLE_HOSTS])
        self.ids = list(VEHICLE_HOSTS.values())
        self.gcs: dict[int, Gcs] = {}
        self.tracks: dict[int, list[tuple[float, float, float, float]]] = {k: [] for k in self.ids}
        self.samples: list[tuple[float, dict[int, dict[str, Any]]]] = []
        self.sample_errors: list[str] = []
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self.ground = InHost(self.lan, "g")
        self._sampler_host = InHost(self.lan, "g")
        self.vehicle_hosts = {k: InHost(self.lan, h) for h, k in VEHICLE_HOSTS.items()}
        try:
            self._start()
        except BaseException:
            self.close()
            raise

    def _start(self) -> None:
        key = generate_key_file(self.tmp / "team.key")
        tokens = self.tmp / "tokens.yaml"
        tokens.write_text(yaml.safe_dump(TOKENS))
        pp = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH", "")) if p)
        env = {"PYTHONPATH": pp, TOKEN_ENV: COMPANION_TOKEN}
        exe = [sys.executable, "-m", "taskflight.cli"]
        self.lan.popen("g", [*exe, "ground", "--team", self.team_url, "--team-key", str(key),
                             "--db", str(self.tmp / "ground.db"), "--host", "127.0.0.1",
                             "--port", str(GROUND_PORT), "--tokens", str(tokens)],
                       self.tmp / "ground.out", env, ROOT)
        self.up_logs = {}
        for host, k in VEHICLE_HOSTS.items():
            self.up_logs[k] = self.tmp / f"up-{host}.out"
            self.lan.popen(host, [*exe, "up", "--no-ground", "--vehicles", "1", "--first-sysid", str(k),
                                  "--team", self.team_url, "--team-key", str(key),
                                  "--speedup", f"{self.speedup:g}",
                                  "--state-dir", str(self.tmp / f"up-{host}"),
                                  "--control-host", "0.0.0.0", "--no-persist", "--ready-timeout", "300"],
                           self.up_logs[k], env, ROOT)
        for log_path in self.up_logs.values():
            self._wait_ready(log_path)
        for k, h in self.vehicle_hosts.items():
            g = h.call(Gcs, 0, self.speedup, url=f"tcp:127.0.0.1:{MODEL_TCP}", background=True, target=k)
            g.request_streams(10)
            self.gcs[k] = g
        for fn in (self._track, self._sample):
            t = threading.Thread(target=fn, daemon=True)
            t.start()
            self._threads.append(t)

    @staticmethod
    def _wait_ready(log_path: Path) -> None:
        """``taskflight up`` printed READY (or failed: its output is the message)."""
        def said() -> bool:
            text = log_path.read_text()
            return "READY" in text or "taskflight up: " in text
        wait_for(said, 360, lambda: f"taskflight up READY in {log_path}: {log_path.read_text()[-2000:]}",
                 poll_s=0.5)
        assert "READY" in log_path.read_text(), log_path.read_text()[-3000:]

    # --- the ground service's REST API (in host g) -------------------------------------------------
    def api(self, method: str, path: str, body: Any = None, host: InHost | None = None) -> httpx.Response:
        def go() -> httpx.Response:
            with httpx.Client(base_url=f"http://127.0.0.1:{GROUND_PORT}", timeout=15.0,
                              headers={"Authorization": f"Bearer {OPERATOR}"}) as c:
                return c.request(method, path, json=body)
        return (host or self.ground).call(go)

    def vehicles(self, host: InHost | None = None) -> dict[int, dict[str, Any]]:
        return {v["id"]: v for v in self.api("GET", "/api/vehicles", host=host).json()["vehicles"]}

    def tasks(self) -> dict[int, dict[str, Any]]:
        return {t["id"]: t for t in self.api("GET", "/api/tasks").json()["tasks"]}

    def try_vehicles(self) -> dict[int, dict[str, Any]]:
        try:
            return self.vehicles()
        except (httpx.HTTPError, ValueError, KeyError):
            return {}

    # --- observers ---------------------------------------------------------------------------------
    def position(self, k: int) -> tuple[float, float, float] | None:
        """Vehicle k's (lat, lon, alt above home) from its autopilot's GLOBAL_POSITION_INT (MAVLink)."""
        m = self.gcs[k].last.get("GLOBAL_POSITION_INT")
        return None if m is None else (m.lat * 1e-7, m.lon * 1e-7, m.relative_alt * 1e-3)

    def _track(self) -> None:
        while not self._stop.wait(0.1):
            for k in self.ids:
                p = self.position(k)
                if p is not None:
                    self.tracks[k].append((time.monotonic(), *p))

    def _sample(self) -> None:
        """The ground's view every 0.25 s: vehicle -> {team_state, claims (task ids not done)}."""
        client = httpx.Client(base_url=f"http://127.0.0.1:{GROUND_PORT}", timeout=15.0,
                              headers={"Authorization": f"Bearer {OPERATOR}"})
        try:
            while not self._stop.wait(0.25):
                try:  # the client's connection is opened (and reused) in host g
                    vs = self._sampler_host.call(client.get, "/api/vehicles").json()["vehicles"]
                except (httpx.HTTPError, ValueError, KeyError, RuntimeError) as exc:
                    self.sample_errors.append(repr(exc))
                    continue
                self.samples.append((time.monotonic(), {
                    v["id"]: {"team_state": v["team_state"], "age_s": v["age_s"],
                              "claims": [c["task"] for c in v["claims"] if c["state"] != "done"],
                              "raw": [(c["task"], c["version"], c["state"]) for c in v["claims"]]}
                    for v in vs}))
        finally:
            client.close()

    def close(self) -> None:
        self._stop.set()
        for t in self._threads:
            t.join(5)
        for g in self.gcs.values():
            g.close()
        for h in (self.ground, self._sampler_host, *self.vehicle_hosts.values()):
            h.close()
        self.lan.close()


#: a vehicle the ground last heard longer ago than this is shown "stale" on the operator's page
#: (``linkOf`` in groundstation/static/js/lists.js): its claims are what it said then, not what it holds now
LIVE_S = 2.0


def held_twice(sample: dict[int, dict[str, Any]]) -> dict[int, list[int]]:
    """Tasks claimed (not done) by two or more vehicles the ground service hears: not gone, and heard within
    :data:`LIVE_S` (a vehicle cut off keeps its last row at the ground until its voc runs out, 5 s of the
    ground's clock, while the other side, following a faster autopilot clock, may already have taken its
    task over)."""
    holders: dict[int, list[int]] = {}
    for vid, v in sample.items():
        age = v.get("age_s")
        if v["team_state"] in ("available", "taken") and age is not None and age <= LIVE_S:
            for t in v["claims"]:
                holders.setdefault(t, []).append(vid)
    return {t: h for t, h in holders.items() if len(h) > 1}
