"""The fleet bus on Zenoh (docs/team.md, "Which transport"): seed 003's group state (Sec. III-A) carried as
Zenoh publications, and the ground service's view of each vehicle published on the bus.

* ``udp://`` without ``?iface=`` uses the interface of the default route, not loopback;
* ``zenoh:`` URLs are parsed, bad ones refused naming the part; udp-only options refused on zenoh:;
* two team links exchange group state (the same wire packets) over ``zenoh:`` in peer mode (multicast
  scouting, no configuration) and through a router started by ``taskflight router`` (a subprocess), the
  members connecting with ``zenoh:tcp/127.0.0.1:PORT``;
* a team of companions (processes) on a zenoh: team flies a visit given through the station: claimed by
  one vehicle at every sample, flown to (the model's GLOBAL_POSITION_INT comes within 2 m), done;
* the ground service on a zenoh: team sees each vehicle's status without any companion URL given to it and
  without polling (its HTTP poll counter stays 0), even a companion that serves no control surface at all;
  a vehicle's control URL, found on the bus, is where the service's commands go.
"""

from __future__ import annotations

import fcntl
import json
import os
import random
import socket
import struct
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from companion.team.groupstate import GroupState
from companion.team.link import TeamLink
from companion.team.tasks import TaskDef
from companion.team.transport import UdpTransport, default_iface, open_transport
from companion.team.types import MemberEntry, MemberStatus
from companion.team.zenoh_transport import parse_zenoh_url
from harness import ROOT
from harness.fleet import ports, start_fleet
from harness.team import PLATFORM, ClaimSampler, TeamRig, distance_m, geo
from harness.timing import wait_for
from taskflight.sitlproc import stop_child
from taskflight_common.ports import free_ports


def _team_name() -> str:
    """A team of its own on the shared network (parallel test runs keep apart by name)."""
    return f"t{os.getpid()}x{random.randrange(1 << 30)}"


# --- udp:// default interface --------------------------------------------------------------------------

def _default_route_iface() -> tuple[str, str] | None:
    """(interface name, its IPv4 address) of the default route, read from the kernel; None without one."""
    try:
        lines = Path("/proc/net/route").read_text().splitlines()[1:]
    except OSError:
        return None
    for line in lines:
        f = line.split()
        if len(f) > 7 and f[1] == "00000000" and f[7] == "00000000":
            name = f[0]
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            try:
                raw = fcntl.ioctl(s.fileno(), 0x8915, struct.pack("256s", name.encode()[:15]))  # SIOCGIFADDR
            except OSError:
                return None
            finally:
                s.close()
            return name, socket.inet_ntoa(raw[20:24])
    return None


def test_udp_without_iface_uses_the_default_routes_interface() -> None:
    route = _default_route_iface()
    if route is None:
        pytest.skip("this machine has no default route (the udp:// default is then loopback)")
    name, addr = route
    assert default_iface() == addr
    port = free_ports(1, socket.SOCK_DGRAM, host="")[0]
    t = open_transport(f"udp://239.255.70.1:{port}")
    try:
        assert isinstance(t, UdpTransport)
        assert t.iface == addr != "127.0.0.1", \
            f"default interface {t.iface}, the default route's is {name} {addr}"
        assert f"iface={addr}" in t.url
    finally:
        t.close()
    explicit = open_transport(f"udp://239.255.70.1:{port}?iface=127.0.0.1")
    try:
        assert isinstance(explicit, UdpTransport) and explicit.iface == "127.0.0.1"
    finally:
        explicit.close()


def test_zenoh_urls_parsed_and_bad_ones_refused() -> None:
    assert parse_zenoh_url("zenoh:").mode == "peer" and parse_zenoh_url("zenoh:").connect == ()
    spec = parse_zenoh_url("zenoh:tcp/10.0.0.5:7447?team=red")
    assert (spec.mode, spec.connect, spec.team) == ("client", ("tcp/10.0.0.5:7447",), "red")
    assert parse_zenoh_url(spec.url) == spec
    assert parse_zenoh_url("zenoh:tcp/a:1,tcp/b:2?mode=peer").connect == ("tcp/a:1", "tcp/b:2")
    for bad, part in [("zenoh:tcp/host", "endpoint"), ("zenoh:?team=a/b", "team"),
                      ("zenoh:?mode=router", "mode"), ("zenoh:?mode=client", "mode=client"),
                      ("zenoh:?colour=red", "colour")]:
        with pytest.raises(ValueError, match=part):
            parse_zenoh_url(bad)
    with pytest.raises(ValueError, match="iface and ttl"):
        open_transport("zenoh:?iface=127.0.0.1")
    with pytest.raises(ValueError, match="options of zenoh"):
        open_transport("udp://239.255.70.1:14650?team=red")


# --- group state over the bus ----------------------------------------------------------------------------

@pytest.fixture(scope="module")
def router() -> Iterator[int]:
    """``taskflight router`` as a subprocess on a free loopback port (yields the port)."""
    port = free_ports(1, socket.SOCK_STREAM)[0]
    proc = subprocess.Popen([sys.executable, "-m", "taskflight.cli", "router", "--listen",
                             f"tcp/127.0.0.1:{port}"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            cwd=ROOT)
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline().decode()
        assert "listening on" in line, f"taskflight router said {line!r} (exit {proc.poll()})"
        yield port
    finally:
        stop_child(proc, 10.0)
    assert proc.returncode == 0, f"taskflight router exited {proc.returncode} on SIGTERM"


def _row(member: int) -> MemberEntry:
    return MemberEntry(member=member, stamp=0.0, seq=0, position=(-35.36, 149.16, 10.0 + member),
                       status=MemberStatus.IDLE, name=f"uav{member}")


def _exchange(url: str) -> None:
    """Three members' links on ``url``: each hears the two others' rows (with their positions)."""
    links = []
    try:
        for m in (1, 2, 3):
            state = GroupState(m)
            state.refresh_own(_row(m))
            links.append(TeamLink(state, open_transport(url, member=m), period_s=0.1))
        for link in links:
            link.start()
        wait_for(lambda: all(set(lk.state.alive()) == {1, 2, 3} for lk in links), 20,
                 lambda: f"every member hears the others: {[sorted(lk.state.alive()) for lk in links]}")
        for lk in links:
            for m in (1, 2, 3):
                assert lk.state.get(m).position == _row(m).position
            assert lk.stats.garbage == 0 and lk.stats.packets_received > 0
    finally:
        for lk in links:
            lk.close()


@pytest.mark.integration
class _Bus:
    """A fleet bus that keeps what is published (a collaborator of the presence under test)."""

    def __init__(self) -> None:
        self.sent: dict[str, list[bytes]] = {}

    def key(self, *parts: object) -> str:
        return "/".join(map(str, parts))

    def publisher(self, key: str) -> object:
        bus = self

        class Pub:
            def put(self, data: bytes) -> None:
                bus.sent.setdefault(key, []).append(data)

        return Pub()


def test_a_detection_is_published_again_until_its_repeats_are_spent() -> None:
    """Publications are not acknowledged (one made before the ground's subscriber matched is lost): each
    object is published DETECTION_REPEATS times, with its first sighting's position, then no more."""
    from companion.team.presence import DETECTION_EVERY, DETECTION_REPEATS, Presence

    seen = [{"x": 7, "kind": "person", "p": [3.0, 4.0, 0.0]},
            {"x": 1, "kind": "aerial_robot", "p": [0, 0, 0]}]
    bus: Any = _Bus()
    presence = Presence(bus, 5, name="uav5", status=lambda: {"queue": {}}, detections=lambda: seen)
    for _ in range(DETECTION_EVERY * (DETECTION_REPEATS + 3)):
        presence.publish_once()
        seen[0] = {**seen[0], "p": [9.0, 9.0, 0.0]}  # it moved: the events keep the first sighting
    events = [json.loads(b) for b in bus.sent["vehicle/5/events"]]
    assert [e["object"] for e in events] == [7] * DETECTION_REPEATS
    assert all(e["ned"] == [3.0, 4.0, 0.0] and e["t"] == events[0]["t"] for e in events)


def test_group_state_over_zenoh_peer_mode() -> None:
    _exchange(f"zenoh:?team={_team_name()}")


@pytest.mark.integration
def test_group_state_over_a_zenoh_router(router: int) -> None:
    _exchange(f"zenoh:tcp/127.0.0.1:{router}?team={_team_name()}")


# --- a team of companions on the bus ---------------------------------------------------------------------

def _fly_a_visit(rig: TeamRig) -> None:
    """A visit given through the station is never held by two vehicles in two samples in a row (the cheaper
    one may take it over from the first claimant, seed 003 Sec. III-B), is flown to (some vehicle's
    GLOBAL_POSITION_INT comes within 2 m of it) and done."""
    point = geo(20, -10, 8)
    closest = [1e9] * rig.n

    def track() -> None:
        for i in range(rig.n):
            pos = rig.position(i)
            if pos is not None:
                closest[i] = min(closest[i], distance_m(pos, point))
    with ClaimSampler(rig) as claims:
        task = rig.add(TaskDef("visit", (point,), name="visit-bus"))[0]
        wait_for(lambda: rig.holder(task) is not None, rig.wall(60), "the visit claimed")
        wait_for(lambda: track() or rig.state(task) == "done", rig.wall(120),
                 lambda: f"the visit done (state {rig.state(task)}, holder {rig.holder(task)})", poll_s=0.05)
    claims.assert_no_task_held_twice()
    assert min(closest) < 2.0, f"no vehicle came within 2 m of the visit: closest {closest} m"
    assert rig.discontinuities() == []


@pytest.mark.integration
def test_team_flies_a_visit_over_zenoh_peer_mode(tmp_path: Path) -> None:
    rig = TeamRig(tmp_path, n=2, speedup=3.0, team_url=f"zenoh:?team={_team_name()}")
    try:
        _fly_a_visit(rig)
    finally:
        rig.close()


@pytest.mark.integration
def test_team_flies_a_visit_through_a_router(tmp_path: Path, router: int) -> None:
    rig = TeamRig(tmp_path, n=2, speedup=3.0, team_url=f"zenoh:tcp/127.0.0.1:{router}?team={_team_name()}")
    try:
        _fly_a_visit(rig)
    finally:
        rig.close()


# --- the ground service on the bus -----------------------------------------------------------------------

@pytest.mark.integration
def test_ground_service_sees_vehicles_over_the_bus_without_polling(tmp_path: Path, router: int) -> None:
    """Vehicle 1's companion serves no control surface at all, vehicle 2's one on a port the service is not
    told: both show up with their autopilot's status; the service never polls; vehicle 2's control URL comes
    from the bus and the service's calls reach it."""
    from groundstation.auth import Tokens
    from groundstation.service import GroundService

    url = f"zenoh:tcp/127.0.0.1:{router}?team={_team_name()}"
    fleet, base = start_fleet(tmp_path / "fleet", 2, 3.0)
    control = free_ports(1, socket.SOCK_STREAM)[0]
    procs: list[subprocess.Popen[bytes]] = []
    service = None
    try:
        for i, port_args in enumerate([["--control-port", "-1"], ["--control-port", str(control)]]):
            out = open(tmp_path / f"companion{i}.out", "ab")  # noqa: SIM115 - the child owns it
            procs.append(subprocess.Popen(
                [sys.executable, "-m", "taskflight.cli", "companion", "--autopilot",
                 f"udpout:127.0.0.1:{ports(base + i)[1]}", "--team", url, *port_args,
                 "--platform", str(PLATFORM)], stdout=out, stderr=subprocess.STDOUT, cwd=ROOT))
            out.close()
        service = GroundService(str(tmp_path / "ground.db"), Tokens.generate(), team_url=url).start()

        def records() -> dict[int, dict]:
            return {r["id"]: r for r in service.fleet.snapshot(max_age_s=0.0)}

        def both_seen() -> bool:
            recs = records()
            return all(recs.get(v, {}).get("mode") and recs[v]["companion"] == "ok" for v in (1, 2))
        wait_for(both_seen, 90, lambda: f"both vehicles' status on the bus: {records()}", poll_s=0.1)
        recs = records()
        assert recs[1]["control_url"] is None
        assert recs[2]["control_url"] == f"http://127.0.0.1:{control}"
        assert recs[1]["armed"] is not None and recs[1]["health"]["level"] in ("green", "yellow")
        code, team = service.call(2, "GET", "/team")  # a command goes to the URL found on the bus
        assert code == 200 and team["member"] == 2
        n = service.fleet.bus.status_messages
        wait_for(lambda: service.fleet.bus.status_messages > n + 4, 10, "status messages keep coming")
        assert service.fleet.http_polls == 0, "the ground service polled a companion over HTTP"
    finally:
        if service is not None:
            service.close()
        for p in procs:
            stop_child(p, 10.0)
        fleet.stop()


# --- polling on a udp:// team ----------------------------------------------------------------------------

class _SlowClient:
    """A companion client whose vehicle 1 never answers until released; the others answer at once."""

    def __init__(self) -> None:
        import threading

        self.release = threading.Event()
        self.calls: dict[int, int] = {}

    def call(self, vid: int, url: str | None, method: str, path: str, body: object = None,
             timeout_s: float | None = None) -> tuple[int, object]:
        self.calls[vid] = self.calls.get(vid, 0) + 1
        if vid == 1:
            self.release.wait(30)
        if path == "/status":
            return 200, {"queue": {}, "vehicle": {"mode": "GUIDED"}}
        return 200, {"state": "idle"}


def test_an_unanswering_companion_never_delays_the_others_polls() -> None:
    """On a udp:// team the ground polls each companion in a worker of its own: while vehicle 1's poll
    hangs, vehicles 2 and 3 are polled again and again (they used to wait in line behind it)."""
    from companion.team.station import TeamControlStation
    from groundstation.fleet import Fleet

    station = TeamControlStation(open_transport(f"mem://{_team_name()}", member=0))
    client = _SlowClient()
    fleet = Fleet(station, client, lambda *a, **k: None, poll_period_s=0.05)  # type: ignore[arg-type]
    for v in (1, 2, 3):
        fleet.register(v, f"uav{v}", f"http://192.0.2.{v}:8765")
    fleet.start()
    try:
        assert fleet.bus is None  # not a Zenoh team: polled
        wait_for(lambda: client.calls.get(2, 0) >= 10 and client.calls.get(3, 0) >= 10, 30,
                 lambda: f"vehicles 2 and 3 polled while vehicle 1 hangs: {client.calls}")
        assert client.calls[1] == 1, "vehicle 1 polled again while its first poll still hangs"
        modes = {r["id"]: r["mode"] for r in fleet.snapshot(max_age_s=0.0)}
        assert modes[2] == modes[3] == "GUIDED" and modes[1] is None
    finally:
        client.release.set()
        fleet.close()
        station.close()


@pytest.mark.integration
def test_presence_reaches_the_fleet_as_status_mission_and_detections() -> None:
    """A companion's presence (its status, its mission left out while unchanged, its camera's detections)
    reaches the ground's fleet over a zenoh: bus: the record shows the mode, the mission's state holds
    between the messages that leave it out, a new object becomes one detection event."""
    from companion.team.presence import MISSION_EVERY, Presence, loopback_id
    from companion.team.station import TeamControlStation
    from companion.team.zenoh_transport import ZenohBus
    from groundstation.fleet import KEEP, Fleet

    url = f"zenoh:?team={_team_name()}"
    events: list[tuple[str, str]] = []
    station = TeamControlStation(open_transport(url, member=0))
    fleet = Fleet(station, None, lambda kind, msg, **k: events.append((kind, msg)))  # type: ignore[arg-type]
    fleet.start()
    seen = [{"x": 7, "kind": "person", "p": [3.0, 4.0, 0.0]},
            {"x": 1, "kind": "aerial_robot", "p": [0, 0, 0]}]  # its own belief: not a detection
    presence = Presence(ZenohBus.open(url), 5, name="uav5", period_s=0.05,
                        status=lambda: {"queue": {"queue_status": "IDLE"}, "vehicle": {"mode": "GUIDED"}},
                        mission=lambda: {"state": "running", "active_node": None, "tree": None},
                        detections=lambda: seen)
    try:
        assert fleet.bus is not None
        presence.start()
        wait_for(lambda: fleet.bus.status_messages > MISSION_EVERY + 2, 20, "status messages on the bus")
        rec = {r["id"]: r for r in fleet.snapshot(max_age_s=0.0)}[5]
        assert (rec["mode"], rec["name"], rec["companion"], rec["control_url"]) == \
            ("GUIDED", "uav5", "ok", None)
        assert rec["mission"]["state"] == "running"
        presence.close()
        presence.published = 1  # not a refresh
        assert "mission" not in presence.message()  # unchanged: left out ...
        fleet.heard_on_bus(5, "", None, {"queue": {}, "vehicle": {"mode": "LOITER"}}, KEEP)
        rec = {r["id"]: r for r in fleet.snapshot(max_age_s=0.0)}[5]
        assert (rec["mode"], rec["mission"]["state"]) == ("LOITER", "running")  # ... and the last one holds
        wait_for(lambda: any(k == "detection" for k, _ in events), 10, lambda: f"a detection event: {events}")
        assert [m for k, m in events if k == "detection"] == ["vehicle 5 sees person 7"]
        assert fleet.http_polls == 0
        # a loopback control URL is taken from this host only (another host's would reach ours), told by
        # the loopback id (a host of the same name, another network namespace) or, without one, the name
        me = socket.gethostname()
        for host, lo, vid in (("another-host", None, 6), (me, None, 7), (me, "other-boot/4026531840", 8),
                              ("another-name", loopback_id(), 9)):
            fleet.bus._on_status(f"taskflight/x/vehicle/{vid}/status", json.dumps(
                {"host": host, "control_url": "http://127.0.0.1:8765", "status": {"queue": {}},
                 **({"loopback": lo} if lo else {})}).encode())
        urls = {r["id"]: r["control_url"] for r in fleet.snapshot(max_age_s=0.0)}
        assert (urls[6], urls[7], urls[8], urls[9]) == (None, "http://127.0.0.1:8765", None,
                                                        "http://127.0.0.1:8765")
    finally:
        presence.close()
        fleet.close()
        station.close()


def test_a_large_fleet_is_polled_at_most_poll_rate_max_times_a_second() -> None:
    """The poll period stays ``poll_period_s`` for a small fleet and grows with a large one: at most
    POLL_RATE_MAX polls a second in all (a vehicle without a control URL is not polled, not counted)."""
    from companion.team.station import TeamControlStation
    from groundstation.fleet import POLL_RATE_MAX, Fleet

    station = TeamControlStation(open_transport(f"mem://{_team_name()}", member=0))
    fleet = Fleet(station, _SlowClient(), lambda *a, **k: None, poll_period_s=0.5)  # type: ignore[arg-type]
    for v in range(1, 4):
        fleet.register(v, f"uav{v}", f"http://192.0.2.{v}:8765")
    assert fleet.period_s() == 0.5
    for v in range(4, 51):
        fleet.register(v, f"uav{v}", f"http://192.0.2.{v}:8765")
    fleet.register(51, "uav51", None)
    assert fleet.period_s() == pytest.approx(50 / POLL_RATE_MAX) == 2.5
    station.close()
