"""Missions over loopback UDP: pymavlink as the ground station, the model in a SITL subprocess (lockstep,
paced at SPEEDUP). Upload, download (equal to what was sent), a refused upload that changes nothing,
and an AUTO flight that visits the waypoints. Deadlines are wall time derived from simulated time.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path
from typing import Any

import pytest

from harness.model import sitl_and_gcs
from harness.observer import AUTO, GUIDED, Gcs, M
from harness.timing import SPEEDUP, wall
from taskflight_common.geo import ned_to_geodetic

pytestmark = pytest.mark.integration

REL = M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT


# --- the mission protocol as a ground station uses it ---------------------------------------------
def upload(gcs: Gcs, items: list[Any], mission_type: int = 0) -> int:
    """Upload by the protocol (answer each MISSION_REQUEST_INT); returns the MISSION_ACK type."""
    gcs.mission.clear()
    gcs.conn.mav.mission_count_send(1, 1, len(items), mission_type)
    while True:
        m = gcs.next_mission(("MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"))
        if m.get_type() == "MISSION_ACK":
            return m.type
        it = items[m.seq]
        gcs.conn.mav.mission_item_int_send(1, 1, m.seq, it.frame, it.command, 0, it.autocontinue, it.param1,
                                           it.param2, it.param3, it.param4, it.x, it.y, it.z, mission_type)


def download(gcs: Gcs, mission_type: int = 0) -> list[Any]:
    gcs.mission.clear()
    gcs.conn.mav.mission_request_list_send(1, 1, mission_type)
    n = gcs.next_mission(("MISSION_COUNT",)).count
    out = []
    for seq in range(n):
        gcs.conn.mav.mission_request_int_send(1, 1, seq, mission_type)
        out.append(gcs.next_mission(("MISSION_ITEM_INT",)))
    gcs.conn.mav.mission_ack_send(1, 1, M.MAV_MISSION_ACCEPTED, mission_type)
    return out


class Item:
    """A mission item as the GCS composes it."""

    def __init__(self, command: int, frame: int = REL, p1: float = 0, p2: float = 0, p4: float = 0,
                 x: int = 0, y: int = 0, z: float = 0) -> None:
        self.command, self.frame, self.autocontinue = command, frame, 1
        self.param1, self.param2, self.param3, self.param4 = p1, p2, 0.0, p4
        self.x, self.y, self.z = x, y, z


def at(home: tuple[float, float, float], n: float, e: float) -> tuple[int, int]:
    lat, lon, _ = ned_to_geodetic(home, n, e, 0.0)
    return round(lat * 1e7), round(lon * 1e7)


WAYPOINTS = [(25.0, 0.0, 10.0), (25.0, 25.0, 15.0), (0.0, 20.0, 12.0)]


def wp(command: int, home: tuple[float, float, float], n: float, e: float, alt: float, **kw: Any) -> Item:
    x, y = at(home, n, e)
    return Item(command, x=x, y=y, z=alt, **kw)


def plan(home: tuple[float, float, float]) -> list[Item]:
    """Home, take-off, waypoint (radius 1 m), speed 8 m/s, waypoint (hold 2 s, yaw NaN), loiter 1 s, land."""
    hx, hy = round(home[0] * 1e7), round(home[1] * 1e7)
    (n1, e1, a1), (n2, e2, a2), (n3, e3, a3) = WAYPOINTS
    return [Item(M.MAV_CMD_NAV_WAYPOINT, M.MAV_FRAME_GLOBAL, x=hx, y=hy, z=home[2]),
            Item(M.MAV_CMD_NAV_TAKEOFF, z=10.0),
            wp(M.MAV_CMD_NAV_WAYPOINT, home, n1, e1, a1, p2=1.0),
            Item(M.MAV_CMD_DO_CHANGE_SPEED, M.MAV_FRAME_MISSION, p1=1, p2=8.0),
            wp(M.MAV_CMD_NAV_WAYPOINT, home, n2, e2, a2, p1=2.0, p4=math.nan),
            wp(M.MAV_CMD_NAV_LOITER_TIME, home, n3, e3, a3, p1=1.0),
            Item(M.MAV_CMD_NAV_LAND)]


FIELDS = ("seq", "frame", "command", "autocontinue", "param1", "param2", "param3", "param4", "x", "y", "z")


def same(a: float, b: float) -> bool:
    return a == b or (math.isnan(a) and math.isnan(b))


def test_upload_download_equal_and_bad_upload_changes_nothing(gcs: Gcs) -> None:
    home = gcs.home()
    items = plan(home)
    assert upload(gcs, items) == M.MAV_MISSION_ACCEPTED
    got = download(gcs)
    assert len(got) == len(items)
    for seq, (sent, back) in enumerate(zip(items, got, strict=True)):
        assert back.seq == seq
        for f in FIELDS[1:]:
            assert same(float(getattr(sent, f)), float(getattr(back, f))), (seq, f, getattr(sent, f),
                                                                             getattr(back, f))
    # an unsupported command in item 3: refused with MAV_MISSION_UNSUPPORTED, stored plan unchanged
    bad = plan(home)
    bad[3] = Item(M.MAV_CMD_DO_SET_SERVO, M.MAV_FRAME_MISSION, p1=5, p2=1500)
    assert upload(gcs, bad) == M.MAV_MISSION_UNSUPPORTED
    # NaN altitude in a waypoint: invalid param7
    bad = plan(home)
    bad[2].z = math.nan
    assert upload(gcs, bad) == M.MAV_MISSION_INVALID_PARAM7
    # an item sent out of sequence: MAV_MISSION_INVALID_SEQUENCE
    gcs.mission.clear()
    gcs.conn.mav.mission_count_send(1, 1, 3, 0)
    gcs.next_mission(("MISSION_REQUEST_INT",))
    gcs.conn.mav.mission_item_int_send(1, 1, 2, REL, 16, 0, 1, 0, 0, 0, 0, 1, 1, 5, 0)
    assert gcs.next_mission(("MISSION_ACK",)).type == M.MAV_MISSION_INVALID_SEQUENCE
    # a mission type the vehicle does not have
    gcs.conn.mav.mission_count_send(1, 1, 3, 7)
    assert gcs.next_mission(("MISSION_ACK",)).type == M.MAV_MISSION_UNSUPPORTED
    again = download(gcs)
    assert [(m.command, m.x, m.y) for m in again] == [(m.command, m.x, m.y) for m in got]


def test_upload_abandoned_is_cancelled_after_retries(gcs: Gcs) -> None:
    """The requests are repeated 1 s apart and the upload given up in *simulated* time,
    as ArduCopter SITL does (its ``AP_HAL::millis()`` is the simulation's clock). Each MISSION_* message is
    stamped with the vehicle's time_boot_ms of the latest ATTITUDE (4 Hz by default) heard before it: the
    repeats are 1 s apart in that time, where repeats timed on the wall would be about SPEEDUP s apart. (How
    long the exchange takes on the wall is no test: a loaded machine runs the simulation slower.)"""
    before = download(gcs)
    gcs.mission.clear()
    stamped: list[tuple[str, int, float]] = []  # (type, seq or result, simulated seconds)

    def stamp_until_ack() -> bool:
        with gcs._lock:
            new, gcs.mission[:] = list(gcs.mission), []
        t = gcs.last["ATTITUDE"].time_boot_ms / 1000.0
        for m in new:
            stamped.append((m.get_type(), m.type if m.get_type() == "MISSION_ACK" else m.seq, t))
        return any(k == "MISSION_ACK" for k, _, _ in stamped)

    gcs.msg("ATTITUDE")
    gcs.conn.mav.mission_count_send(1, 1, 4, 0)
    assert SPEEDUP >= 2, "at 1x simulated and wall time agree: the repeats' clock could not be told"
    gcs.wait(stamp_until_ack, gcs.wall(10), "MISSION_ACK after the repeated requests")
    requests = [(v, t) for k, v, t in stamped if k == "MISSION_REQUEST_INT"]
    acks = [(v, t) for k, v, t in stamped if k == "MISSION_ACK"]
    assert [v for v, _ in acks] == [M.MAV_MISSION_OPERATION_CANCELLED]
    assert [v for v, _ in requests] == [0] * 6  # the request and 5 repeats
    gaps = [b[1] - a[1] for a, b in itertools.pairwise(requests)]
    assert all(0.6 <= g <= 1.5 for g in gaps), gaps  # 1 s apart in simulated time (4 Hz stamps)
    assert 5.5 <= acks[0][1] - requests[0][1] <= 7.0
    assert len(download(gcs)) == len(before)


def test_mission_persists_across_restart(tmp_path: Path) -> None:
    with sitl_and_gcs(tmp_path) as g:
        items = plan(g.home())
        assert upload(g, items) == M.MAV_MISSION_ACCEPTED
    with sitl_and_gcs(tmp_path) as g:
        got = download(g)
        assert [(m.command, m.x, m.y, m.z) for m in got[1:]] == \
            [(i.command, i.x, i.y, i.z) for i in items[1:]]


def test_auto_flight_visits_waypoints(gcs: Gcs) -> None:
    home = gcs.home()
    assert upload(gcs, plan(home)) == M.MAV_MISSION_ACCEPTED
    assert gcs.set_mode(GUIDED) == M.MAV_RESULT_ACCEPTED
    gcs.wait(lambda: gcs.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_ACCEPTED, wall(20),
             "arming")
    gcs.reached.clear()
    gcs.positions.clear()
    assert gcs.command(M.MAV_CMD_MISSION_START, 0, 0) == M.MAV_RESULT_ACCEPTED
    gcs.wait_mode(AUTO, 5)
    gcs.wait(lambda: 6 in gcs.reached, wall(150), "the landing (item 6) reached")
    gcs.wait_disarmed(10)
    assert gcs.reached == [1, 3, 4, 5, 6]  # as ArduCopter: 2 overtaken by the DO_CHANGE_SPEED (3), same cycle
    for n, e, alt in WAYPOINTS:
        closest = min(math.dist(p, (n, e, -alt)) for p in gcs.positions)
        assert closest < 2.5, (n, e, alt, closest)
    assert any("Reached command #2" in t for t in gcs.texts)
    n, e, _ = gcs.positions[-1]  # landed where the last waypoint was (LAND with lat = lon = 0)
    assert math.hypot(n - WAYPOINTS[2][0], e - WAYPOINTS[2][1]) < 2.5
    assert gcs.fresh("EXTENDED_SYS_STATE").landed_state == M.MAV_LANDED_STATE_ON_GROUND
    cur = gcs.fresh("MISSION_CURRENT")
    assert cur.seq == 6 and cur.total == 6


def test_mission_start_while_disarmed_switches_to_auto(gcs: Gcs) -> None:
    """ArduCopter accepts MISSION_START on the ground while disarmed and switches to AUTO; with the default
    AUTO_OPTIONS it then refuses to arm in AUTO (ModeAuto::allows_arming), so the usual order stays: arm
    in GUIDED, switch to AUTO, MISSION_START."""
    assert gcs.set_mode(GUIDED) == M.MAV_RESULT_ACCEPTED
    gcs.wait_disarmed(10)
    assert upload(gcs, plan(gcs.home())) == M.MAV_MISSION_ACCEPTED
    assert gcs.command(M.MAV_CMD_MISSION_START, 0, 0) == M.MAV_RESULT_ACCEPTED, gcs.texts[-3:]
    gcs.wait_mode(AUTO, 5)
    assert not (gcs.fresh("HEARTBEAT").base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
    assert gcs.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_FAILED
    assert any("not armable" in t for t in gcs.texts[-3:]), gcs.texts[-3:]
    assert gcs.set_mode(GUIDED) == M.MAV_RESULT_ACCEPTED
