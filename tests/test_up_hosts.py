"""``taskflight up --companions-per-process K``: the companions of a simulated fleet, K to a process
(``taskflight companion-host``, :mod:`companion.host`), each still the companion a real vehicle runs.

Six vehicles, three companions to a host: two host processes, each vehicle's companion answering on its
own control surface and heard by the ground service; a visit flown by a vehicle of each host (judged by the
models' MAVLink, read by a pymavlink ground station per vehicle, not by what the companions report); Ctrl-C
stops the models, both hosts and the ground service, and no process of the run is left.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from harness.team import HOME, geo
from harness.timing import wait_for
from harness.up import UpRig, alive, processes_mentioning
from taskflight.team_tasking import HttpError, http_json

pytestmark = pytest.mark.integration

N, K = 6, 3


@pytest.fixture(scope="module")
def rig(tmp_path_factory: pytest.TempPathFactory) -> Iterator[UpRig]:
    r = UpRig(tmp_path_factory.mktemp("up_hosts"), n=N, speedup=3.0,
              extra=["--companions-per-process", str(K)])
    yield r
    r.close()


def host_of(rig: UpRig) -> dict[int, int]:
    """Each vehicle's (system id's) companion process id, from ``taskflight up``'s summary."""
    return {i + 1: rig.summary.pids[f"companion{i + 1}"] for i in range(N)}


def east_north(p: tuple[float, ...]) -> tuple[float, float]:
    return ((p[1] - HOME[1]) * 111_320.0 * math.cos(math.radians(HOME[0])), (p[0] - HOME[0]) * 111_320.0)


def test_six_vehicles_run_in_two_hosts_each_its_own_companion(rig: UpRig) -> None:
    hosts = host_of(rig)
    assert len(set(hosts.values())) == N // K, rig.up.output
    assert hosts[1] == hosts[2] == hosts[3] != hosts[4] == hosts[5] == hosts[6]
    assert "companion hosts: 2 processes of up to 3 companions" in rig.up.output
    assert set(rig.vehicles()) == set(range(1, N + 1)), rig.report()
    heard = [v for v in rig.vehicles().values() if v.get("team_state") not in ("unknown", "gone")]
    assert len(heard) == N, rig.report()
    urls = rig.summary.companions  # each vehicle its own control surface, each asking for the token
    assert len(set(urls)) == N
    for url in urls:
        with pytest.raises(HttpError) as refused:
            http_json("GET", url + "/status", None, timeout_s=10.0)
        assert refused.value.status == 401


def test_a_visit_flown_by_a_vehicle_of_each_host(rig: UpRig) -> None:
    """Visits far west of vehicle 1 and far east of vehicle 6 (homes 5 m apart eastwards): each is flown,
    as the autopilots' MAVLink shows, and the two vehicles that flew them run in different hosts."""
    t0 = time.monotonic()
    points = {"west": (15.0, -40.0), "east": (15.0, 65.0)}
    ids = {}
    for name, (n, e) in points.items():
        with rig.ground.http() as c:
            r = c.post("/api/tasks", json={"type": "visit", "point": list(geo(n, e, 6)), "name": name})
        assert r.status_code == 201, r.text
        ids[name] = r.json()["ids"][0]
    wait_for(lambda: all(rig.tasks()[t]["state"] == "done" for t in ids.values()), rig.wall(300),
             lambda: f"both visits flown: {rig.report()}")
    flown_by = {}
    for name, (n, e) in points.items():
        near = [i for i in range(N) if any(math.dist(east_north(s[1:]), (e, n)) <= 2.5
                                           for s in list(rig.tracks[i]) if s[0] >= t0)]
        assert near, f"no vehicle's MAVLink track reached the {name} visit point: {rig.report()}"
        flown_by[name] = near[0] + 1
    hosts = host_of(rig)
    assert hosts[flown_by["west"]] != hosts[flown_by["east"]], (flown_by, hosts)


def test_ctrl_c_stops_the_models_the_hosts_and_the_ground_service(rig: UpRig) -> None:
    """Last in this module."""
    pids = dict(rig.summary.pids)
    assert rig.up.interrupt(60) == 0, rig.up.output
    assert "taskflight up: stopped" in rig.up.output
    assert [p for p in set(pids.values()) if alive(p)] == []
    state: Path = rig.tmp / "state"
    assert processes_mentioning(str(state)) == []
