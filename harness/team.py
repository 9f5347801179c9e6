"""A team over loopback for the integration tests: seed 003's three aircraft, as processes.

:class:`TeamRig` starts

* a fleet of N bundled autopilot models in one process (:mod:`autopilot_model.fleet`, system ids 1..N,
  homes 5 m apart), each reachable on its own UDP port;
* N companions, each its own ``taskflight companion`` process joined to the team link (UDP multicast on
  loopback, a port of its own; ``?loss=`` drops that fraction of team packets at every member) with the
  outdoor platform, a flight log and an HTTP control surface;
* the team-control station in the test process (:class:`~companion.team.station.TeamControlStation`);
* a pymavlink ground station per vehicle on the model's own port (positions read from the autopilots over
  MAVLink, mode changes: the lowest tier of seed 003 Fig. 1).
"""

from __future__ import annotations

import contextlib
import math
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

from companion.flight.limits import Limits
from companion.flightlog import log_violations, read_flight_log
from companion.team.station import TeamControlStation
from companion.team.tasks import TaskDef
from companion.team.transport import open_transport
from companion.tst.platform import load_platform
from harness import ROOT
from harness.fleet import ports, start_fleet
from harness.observer import Gcs
from harness.timing import wait_for
from taskflight.sitlproc import stop_child
from taskflight_common.geo import ned_to_geodetic
from taskflight_common.ports import free_ports

PLATFORM = ROOT / "mission_specs" / "platform_outdoor.yaml"
#: the fleet's base home (the model's default, CMAC); vehicle i stands 5 i m east of it
HOME = (-35.363261, 149.165230, 584.0)


def geo(n: float, e: float, alt: float = 0.0) -> tuple[float, float, float]:
    """(lat, lon, alt above home) of the point n m north and e m east of the fleet's home."""
    lat, lon, _ = ned_to_geodetic(HOME, n, e, 0.0)
    return (lat, lon, alt)


def new_team_url() -> str:
    """A team link of its own: the project's multicast group on a UDP port free on every interface."""
    return f"udp://239.255.70.1:{free_ports(1, socket.SOCK_DGRAM, host='')[0]}"


def kill_group(p: subprocess.Popen[bytes]) -> None:
    """SIGKILL the session ``p`` leads (started with ``start_new_session``) and reap ``p``."""
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(p.pid, signal.SIGKILL)
    p.wait(10)


class TeamRig:
    """See module docstring. ``speedup`` is the models' (the companions follow autopilot time)."""

    def __init__(self, tmp: Path, n: int = 3, speedup: float = 3.0, loss: float = 0.0,
                 policy: str = "greedy", team_url: str | None = None) -> None:
        self.tmp, self.n, self.speedup, self.loss, self.policy = tmp, n, speedup, loss, policy
        self.fleet, self.base = start_fleet(tmp / "fleet", n, speedup)
        self.team_url = team_url or new_team_url()  # e.g. a zenoh: URL (the fleet bus)
        sep = "&" if "?" in self.team_url else "?"
        self.member_url = self.team_url + (f"{sep}loss={loss}" if loss else "")
        self.control_ports = free_ports(n, socket.SOCK_STREAM)
        self.companions: list[subprocess.Popen[bytes] | None] = [None] * n
        self.logs: list[list[Path]] = [[] for _ in range(n)]
        self.station: TeamControlStation | None = None
        self.gcs: list[Gcs] = []
        try:
            for i in range(n):
                self.start_companion(i)
            self.station = TeamControlStation(open_transport(self.member_url, member=0,
                                                             position_of=lambda m: None)).start()
            for i in range(n):
                g = Gcs(ports(self.base + i)[1], speedup, background=True, target=i + 1)
                g.request_streams(10)
                self.gcs.append(g)
            wait_for(lambda: len(self.station.vehicle_rows()) == n, 90, f"{n} vehicles heard by the station")
            self._wait_control_surfaces(60)
        except BaseException:
            self.close()
            raise
        # the companions' queue limits: their platform's (a patrol flown at its own 6 m/s is within them)
        self.limits: Limits = load_platform(PLATFORM).flight_limits()

    # --- processes -----------------------------------------------------------------------------------
    def start_companion(self, i: int) -> None:
        log = self.tmp / f"flight{i}-{len(self.logs[i])}.jsonl"
        self.logs[i].append(log)
        exe = Path(sys.executable).with_name("taskflight")
        out = open(self.tmp / f"companion{i}.out", "ab")  # noqa: SIM115 - the child owns it
        self.companions[i] = subprocess.Popen(
            [str(exe), "companion", "--autopilot", f"udpout:127.0.0.1:{ports(self.base + i)[1]}",
             "--team", self.member_url, "--control-port", str(self.control_ports[i]),
             "--platform", str(PLATFORM), "--flight-log", str(log), "--team-policy", self.policy],
            stdout=out, stderr=subprocess.STDOUT, cwd=ROOT, start_new_session=True)
        out.close()

    def kill_companion(self, i: int) -> None:
        p = self.companions[i]
        if p is not None:
            kill_group(p)
        self.companions[i] = None

    def ensure_companions(self) -> None:
        """Every companion running and heard (a test that killed one leaves it to the next)."""
        for i, p in enumerate(self.companions):
            if p is None or p.poll() is not None:
                self.start_companion(i)
        wait_for(lambda: len(self.station.vehicle_rows()) == self.n, 60, "every vehicle in the team")
        self._wait_control_surfaces(60)
        for i in range(self.n):  # a test that failed half-way may have left a vehicle out of the team
            if self.team(i)["status"] == "taken":
                with self.http(i) as c:
                    c.post("/team/release")

    def close(self) -> None:
        for g in self.gcs:
            g.close()
        if self.station is not None:
            self.station.close()
        for p in self.companions:
            if p is not None:
                stop_child(p, 10.0)
                kill_group(p)  # what it started (a companion behind faketime is faketime's child)
        self.fleet.stop()

    def _control_up(self, i: int) -> bool:
        try:
            with self.http(i) as c:
                return c.get("/status").status_code == 200
        except httpx.HTTPError:
            return False

    def _wait_control_surfaces(self, timeout_s: float) -> None:
        """Every companion's control surface answers: the companion joins the team (and is heard) before
        its HTTP server starts, so a row on the team link does not mean the port is open yet."""
        for i in range(self.n):
            wait_for(lambda i=i: self._control_up(i), timeout_s, f"companion {i}'s control surface")

    # --- looking at the team -------------------------------------------------------------------------
    def http(self, i: int) -> httpx.Client:
        return httpx.Client(base_url=f"http://127.0.0.1:{self.control_ports[i]}", timeout=10.0)

    def team(self, i: int) -> dict[str, Any]:
        with self.http(i) as c:
            return c.get("/team").json()

    def wall(self, sim_s: float) -> float:
        """A wall deadline for ``sim_s`` of flight: twice the time at the speed-up, plus 10 s (a loaded
        machine runs the companions' ticks and the models late)."""
        return 10.0 + 2.0 * sim_s / self.speedup

    def position(self, i: int) -> tuple[float, float, float] | None:
        """Vehicle i's (lat, lon, alt above home) from its autopilot's GLOBAL_POSITION_INT."""
        m = self.gcs[i].last.get("GLOBAL_POSITION_INT")
        return None if m is None else (m.lat * 1e-7, m.lon * 1e-7, m.relative_alt * 1e-3)

    def holder(self, task_id: int) -> int | None:
        return dict((v.id, v.holder) for v in self.station.tasks()).get(task_id)

    def state(self, task_id: int) -> str:
        return dict((v.id, v.state) for v in self.station.tasks())[task_id]

    def add(self, defn: TaskDef) -> tuple[int, ...]:
        """Add a task; a divided task offered a smaller N is added with the offer (seed 003 Sec. II)."""
        result = self.station.add(defn)
        if result.offer is not None:
            result = self.station.add(TaskDef(**{**defn.__dict__, "n": result.offer}), force=True)
        assert result.ids, result
        return result.ids

    def discontinuities(self) -> list[Any]:
        """Continuity violations of every streamed setpoint of every companion run so far."""
        out = []
        for logs in self.logs:
            for path in logs:
                if path.is_file():
                    out += log_violations(read_flight_log(path), self.limits)
        return out


def fly_nine_tasks(rig: TeamRig) -> None:
    """Seed 003 Sec. V: "A series of nine tasks was assigned to the three UAVs, including multiple-agent
    tasks such as cooperative border patrol. On three occasions, conflicts were declared ..."." Every
    vehicle's claims are sampled over the whole run (:class:`ClaimSampler`): no task is held twice; every
    visit was flown to (some vehicle's track, from its autopilot, came within 3 m of it)."""
    st = rig.station
    assert st is not None
    with ClaimSampler(rig) as claims:
        visits = _fly_nine_tasks(rig, st)
    claims.assert_no_task_held_twice()
    claims.assert_visited(visits, within_m=3.0)


def _fly_nine_tasks(rig: TeamRig, st: TeamControlStation) -> list[tuple[float, float, float]]:
    points = [geo(25, -15, 8), geo(-20, 25, 8), geo(35, 10, 8), geo(-10, -25, 8)]
    visits = [rig.add(TaskDef("visit", (points[0],), name="visit-1"))[0],
              rig.add(TaskDef("visit", (points[1],), name="visit-2"))[0]]
    area = rig.add(TaskDef("area_scan", (geo(15, 40), geo(15, 60), geo(45, 60), geo(45, 40)), n=2,
                           name="area"))
    wait_for(lambda: all(rig.state(t) == "done" for t in visits), rig.wall(120), "the first visits done")
    visits += [rig.add(TaskDef("visit", (points[2],), name="visit-3"))[0],
               rig.add(TaskDef("visit", (points[3],), name="visit-4"))[0]]
    # the tasks that end come first: a vehicle flying a patrol keeps it until it is cancelled
    wait_for(lambda: all(rig.state(t) == "done" for t in [*visits, *area]), rig.wall(240),
             "visits and area parts flown")
    patrol = rig.add(TaskDef("patrol_line", (geo(0, -30, 8), geo(20, -30, 8)), name="patrol"))[0]
    border = rig.add(TaskDef("border_patrol", (geo(-30, -10, 8), geo(-30, 10, 8), geo(-30, 30, 8)), n=2,
                             name="border"))
    ids = [*visits, *area, patrol, *border]
    assert len(ids) >= 8  # nine when the border kept N = 2 (a smaller N was offered otherwise)
    wait_for(lambda: rig.state(patrol) == "active" and all(rig.state(t) == "active" for t in border),
             rig.wall(120), "the patrol and the border flown")
    st.cancel(patrol)
    st.cancel(st.tasks()[[v.id for v in st.tasks()].index(border[0])].group or border[0])
    wait_for(lambda: all(rig.state(t) in ("done", "cancelled") for t in ids), rig.wall(240),
             "every task done or cancelled")
    assert {rig.state(t) for t in visits + list(area)} == {"done"}
    assert rig.state(patrol) == "cancelled" and {rig.state(t) for t in border} == {"cancelled"}
    # idle vehicles loiter: each in the team, holding no task, hovering where it is
    def loitering() -> bool:
        teams = [rig.team(i) for i in range(rig.n)]
        return all(t["status"] in ("idle", "landed") and not t["claims"] and t["controller"] == "loiter"
                   for t in teams)
    wait_for(loitering, rig.wall(60), "every vehicle idle")
    return points


class ClaimSampler:
    """Every vehicle's claims, read from its companion (``GET /team``) every ``period_s`` in a thread for
    the whole run: each sample is (wall time, {task: [vehicles holding it]}, [packets each vehicle sent])
    over the claims held (not done, not failed); and every vehicle's track (its autopilot's
    GLOBAL_POSITION_INT, when the rig has ground stations) every ``period_s / 5``.

    :meth:`assert_no_task_held_twice` checks every sample of the run, not its end: by default it fails when
    a task is held by two vehicles in two samples in a row (seed 003 Sec. II: a conflict is declared and
    resolved, so a double claim may be seen once, while one vehicle's release and the next one's claim are
    read a few milliseconds apart; one that lasts a whole period is a task flown twice); with
    ``max_packets`` it fails when a stretch of samples holding a task twice lasted more than that many
    team-link packets sent by one of the vehicles (a conflict's length counted in the link's own periods,
    so a loaded machine that runs the link late does not lengthen it). The message shows the samples that
    broke it. :meth:`assert_visited`: each point came within a distance of some vehicle's track."""

    def __init__(self, rig: TeamRig, period_s: float = 0.25) -> None:
        self.rig, self.period_s = rig, period_s
        self.samples: list[tuple[float, dict[int, list[int]]]] = []
        self.sent: list[list[int]] = []
        self.tracks: list[list[tuple[float, float, float]]] = [[] for _ in range(rig.n)]
        self.errors: list[str] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="claim-sampler", daemon=True)
        self._tracker = threading.Thread(target=self._track, name="track-sampler", daemon=True)

    def __enter__(self) -> ClaimSampler:
        self._thread.start()
        if getattr(self.rig, "gcs", None):
            self._tracker.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(10.0)
        if self._tracker.is_alive():
            self._tracker.join(10.0)

    def sample(self) -> dict[int, list[int]]:
        holders: dict[int, list[int]] = {}
        sent: list[int] = []
        for i in range(self.rig.n):
            team = self.rig.team(i)
            sent.append(int(team.get("link", {}).get("packets_sent", 0)))
            for c in team["claims"]:
                if c["state"] not in ("done", "failed"):
                    holders.setdefault(c["task"], []).append(i)
        self.sent.append(sent)
        return holders

    def _run(self) -> None:
        while not self._stop.wait(self.period_s):
            try:
                self.samples.append((time.monotonic(), self.sample()))
            except (httpx.HTTPError, ValueError, KeyError) as e:  # a companion killed or restarting
                self.errors.append(repr(e))

    def _track(self) -> None:
        while not self._stop.wait(self.period_s / 5):
            for i in range(self.rig.n):
                p = self.rig.position(i)
                if p is not None:
                    self.tracks[i].append(p)

    def assert_no_task_held_twice(self, max_packets: int | None = None) -> None:
        assert self.samples, f"no claims sampled (errors: {self.errors[-3:]})"
        t0 = self.samples[0][0]
        if max_packets is None:
            for (t_a, a), (t_b, b) in zip(self.samples, self.samples[1:], strict=False):
                twice = {task: (a[task], b[task]) for task in a.keys() & b.keys()
                         if len(set(a[task])) > 1 and set(a[task]) == set(b[task])}
                assert not twice, (f"task(s) held by two vehicles in two samples in a row, at "
                                   f"{t_a - t0:.2f} s and {t_b - t0:.2f} s: {twice}; samples: {a} then {b} "
                                   f"({len(self.samples)} samples)")
            return
        since: dict[int, int] = {}  # task held twice now -> the sample where that began
        for k, (t_k, held) in enumerate(self.samples):
            twice = {task for task, who in held.items() if len(set(who)) > 1}
            for task in twice:
                began = since.setdefault(task, k)
                packets = max(b - a for a, b in zip(self.sent[began], self.sent[k], strict=True))
                assert packets <= max_packets, (
                    f"task {task} held by two vehicles from {self.samples[began][0] - t0:.2f} s to "
                    f"{t_k - t0:.2f} s ({packets} packets sent by one of them meanwhile): "
                    f"{[s for _, s in self.samples[began:k + 1]]}")
            for task in set(since) - twice:
                del since[task]

    def assert_visited(self, points: list[tuple[float, float, float]], within_m: float) -> None:
        for p in points:
            nearest = min((distance_m(q, p) for track in self.tracks for q in track), default=math.inf)
            assert nearest <= within_m, f"no vehicle came within {within_m} m of {p}: nearest {nearest:.1f} m"


def distance_m(a: tuple[float, float, float], b: tuple[float, float, float]) -> float:
    """Horizontal metres between two (lat, lon, alt) points (flat earth: tests span < 1 km)."""
    dn = (a[0] - b[0]) * 111_320.0
    de = (a[1] - b[1]) * 111_320.0 * math.cos(math.radians(a[0]))
    return math.hypot(dn, de)
