"""A team on several hosts: a ground host and two vehicle hosts (network namespaces joined by a bridge,
:mod:`harness.netns`), joined only by the team URL, on the Zenoh fleet bus and on raw UDP multicast.

``taskflight ground`` runs on one host and ``taskflight up --no-ground --vehicles 1 --first-sysid K`` on
each of the two others (:class:`harness.hosts.HostsRig`). Both vehicles appear in the ground service (on
``zenoh:`` with their control surfaces found through the bus); a visit and a patrol given through its REST
API are flown, judged by a pymavlink ground station reading each model's MAVLink stream inside its own host;
the patrol holder's host is cut off for 20 s (its switch port down) and the patrol goes to the other
vehicle, which flies it; once healed, no task is held by two vehicles, sampled from the ground's view over
the whole run. Root only (``ip netns``); skipped elsewhere with the reason.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Iterator
from typing import Any

import pytest
from shapely.geometry import LineString, Point

from harness.hosts import VEHICLE_HOSTS, HostsRig, held_twice
from harness.netns import netns_unavailable
from harness.team import HOME, geo
from harness.timing import wait_for

pytestmark = [pytest.mark.integration,
              pytest.mark.skipif(netns_unavailable() is not None, reason=str(netns_unavailable()))]

#: the models' speedup: the companions follow autopilot time (the vote of confidence's 5 s is 5/3 s wall)
SPEEDUP = 3.0
PARTITION_S = 20.0
HOST_OF = {k: h for h, k in VEHICLE_HOSTS.items()}


def team_url(transport: str, tag: str) -> str:
    # the hosts are a LAN of their own: a fixed multicast port is nobody else's; the Zenoh team is named
    return {"zenoh": f"zenoh:?team={tag}", "udp": "udp://239.255.70.1:14650"}[transport]


@pytest.fixture(scope="module", params=["zenoh", "udp"])
def hosts(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Iterator[HostsRig]:
    tmp = tmp_path_factory.mktemp(f"hosts-{request.param}")
    rig = HostsRig(tmp, team_url(request.param, tmp.name.replace("-", "_")), SPEEDUP)
    try:
        yield rig
    finally:
        rig.close()


def local(p: tuple[float, ...] | list[float]) -> tuple[float, float]:
    """(east, north) metres of a (lat, lon, ...) point from the fleet's home."""
    return ((p[1] - HOME[1]) * 111_320.0 * math.cos(math.radians(HOME[0])), (p[0] - HOME[0]) * 111_320.0)


def came_near(rig: HostsRig, k: int, shape: Any, tol: float, since: float) -> bool:
    """Vehicle k's MAVLink track came within ``tol`` m of ``shape`` (horizontally, >= 2 m up) after
    ``since``."""
    return any(s[3] >= 2.0 and shape.distance(Point(local(s[1:3]))) <= tol
               for s in list(rig.tracks[k]) if s[0] >= since)


def holders(vs: dict[int, dict[str, Any]], task: int) -> list[int]:
    """The vehicles the ground hears that claim ``task`` (not done)."""
    return [k for k, v in vs.items() if v["team_state"] in ("available", "taken")
            and any(c["task"] == task and c["state"] != "done" for c in v["claims"])]


def add(rig: HostsRig, body: dict[str, Any]) -> int:
    r = rig.api("POST", "/api/tasks", body)
    assert r.status_code == 201, r.text
    return int(r.json()["ids"][0])


def test_both_vehicles_appear_in_the_ground_service(hosts: HostsRig) -> None:
    def both() -> bool:
        vs = hosts.try_vehicles()
        return all(vs.get(k, {}).get("team_state") == "available" for k in hosts.ids)
    wait_for(both, 120, lambda: f"vehicles {hosts.ids} available in the ground service: "
                                f"{hosts.try_vehicles()}", poll_s=0.5)
    if hosts.transport == "zenoh":
        def reachable() -> bool:
            vs = hosts.try_vehicles()
            return all(vs.get(k, {}).get("companion") == "ok" and vs[k]["control_url"] for k in hosts.ids)
        wait_for(reachable, 60, lambda: f"control surfaces found on the bus: {hosts.try_vehicles()}",
                 poll_s=0.5)
        vs = hosts.vehicles()
        for k in hosts.ids:  # the URL each companion published, on its own host's address
            assert vs[k]["control_url"].startswith(f"http://{hosts.lan.addr(HOST_OF[k])}:"), vs[k]
            r = hosts.api("GET", f"/api/vehicles/{k}/processes")  # the ground calls it there
            assert r.status_code == 200 and isinstance(r.json(), list), r.text


def test_visit_and_patrol_flown_and_a_partitioned_hosts_patrol_reassigned(hosts: HostsRig) -> None:
    wait_for(lambda: all(hosts.try_vehicles().get(k, {}).get("team_state") == "available" for k in hosts.ids),
             120, "both vehicles available", poll_s=0.5)
    t0 = time.monotonic()
    point = geo(15, 10, 6)
    visit = add(hosts, {"type": "visit", "point": list(point), "name": "visit"})
    wait_for(lambda: hosts.tasks()[visit]["state"] == "done", 180,
             lambda: f"the visit done: {hosts.tasks()[visit]}", poll_s=0.5)
    assert any(came_near(hosts, k, Point(local(point)), 2.5, t0) for k in hosts.ids), \
        "nobody flew to the visit point (MAVLink)"

    t1 = time.monotonic()
    line = [geo(-10, -8, 6), geo(-10, -20, 6)]
    shape = LineString([local(p) for p in line])
    patrol = add(hosts, {"type": "patrol_line", "points": [list(p) for p in line], "name": "patrol"})
    wait_for(lambda: hosts.tasks()[patrol]["state"] == "active" and hosts.tasks()[patrol]["holder"], 120,
             lambda: f"the patrol active: {hosts.tasks()[patrol]}", poll_s=0.5)
    x = int(hosts.tasks()[patrol]["holder"])
    (y,) = [k for k in hosts.ids if k != x]
    ends = [Point(local(p)) for p in line]
    wait_for(lambda: all(came_near(hosts, x, e, 2.0, t1) for e in ends), 120,
             f"vehicle {x} flying the patrol from end to end (MAVLink)", poll_s=0.5)

    t_cut = time.monotonic()
    hosts.lan.unplug(HOST_OF[x])
    try:
        wait_for(lambda: hosts.tasks()[patrol]["holder"] == y, PARTITION_S,
                 lambda: f"the patrol reassigned to vehicle {y}: {hosts.tasks()[patrol]}", poll_s=0.25)
        t_moved = time.monotonic()
        wait_for(lambda: came_near(hosts, y, shape, 2.0, t_moved), 60,
                 f"vehicle {y} on the patrol line (MAVLink)", poll_s=0.5)
        wait_for(lambda: time.monotonic() >= t_cut + PARTITION_S, PARTITION_S + 5, "the partition's 20 s",
                 poll_s=0.2)
    finally:
        hosts.lan.plug(HOST_OF[x])
    t_heal = time.monotonic()
    wait_for(lambda: hosts.try_vehicles().get(x, {}).get("team_state") == "available", 90,
             lambda: f"vehicle {x} heard again: {hosts.try_vehicles().get(x)}", poll_s=0.25)
    t_back = time.monotonic()
    wait_for(lambda: len(holders(hosts.try_vehicles(), patrol)) == 1, 60,
             lambda: f"the patrol held by one vehicle once healed: {hosts.try_vehicles()}", poll_s=0.25)
    # a few more samples of the healed team before the end
    n = len(hosts.samples)
    wait_for(lambda: len(hosts.samples) >= n + 20, 60, "20 more samples of the ground's view", poll_s=0.25)
    (keeper,) = holders(hosts.vehicles(), patrol)
    assert hosts.tasks()[patrol]["holder"] == keeper
    wait_for(lambda: came_near(hosts, keeper, shape, 2.0, t_back), 60,
             f"vehicle {keeper} on the patrol line once healed (MAVLink)", poll_s=0.5)
    assert hosts.api("DELETE", f"/api/tasks/{patrol}").json() == {"cancelled": [patrol]}

    samples = list(hosts.samples)
    twice = [(t, held_twice(s)) for t, s in samples]
    print(f"{hosts.transport}: {len(samples)} samples of the ground's view; the cut at {t_cut - t0:.1f} s, "
          f"reassigned {t_moved - t_cut:.1f} s later, healed at {t_heal - t0:.1f} s, vehicle {x} heard "
          f"{t_back - t_heal:.1f} s later; held twice: {[(round(t - t0, 2), h) for t, h in twice if h]}")
    # over the whole run a double claim among the vehicles the ground hears (harness.hosts.held_twice) is seen
    # in one sample at most (a conflict declared and resolved, seed 003 Sec. II); once healed, in none but the
    # samples of the first second vehicle x is heard again
    # (its first rows carry the claim it flew alone, unable to know; it yields on its next decision)
    raw = {round(t - t0, 2): {v: (s[v]["raw"], f"heard {s[v]['age_s']} s ago") for v in s}
           for t, s in samples}
    heard = next((t for t, s in samples if t > t_heal and s.get(x, {}).get("team_state") == "available"),
                 t_back)
    for (ta, a), (_, b) in itertools.pairwise(twice):
        if heard <= ta <= heard + 1.0:
            continue
        both = {task: h for task, h in a.items() if set(b.get(task, [])) == set(h)}
        assert not both, (f"held by two vehicles in two samples in a row at {ta - t0:.2f} s: {both} "
                          f"(claims: {raw[round(ta - t0, 2)]})")
    after = [(round(t - t0, 2), h) for t, h in twice if h and t > heard + 1.0]
    assert not after, f"a task held by two vehicles once healed (s since the visit, holders): {after}"
