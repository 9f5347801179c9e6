"""Seed 003's flight demonstration over loopback (seed 003 Sec. V): three bundled models (one
fleet process), three companions (processes) on one team link, a team-control station.

Nine tasks of every type (visits, a patrol line, a border patrol divided among two, an area scan divided
among two) are added and cancelled by the station while the vehicles fly; conflicts are declared and
resolved; every task ends done or cancelled and idle vehicles loiter; a vehicle whose companion is killed
mid-task has its task re-allocated once its vote of confidence runs out; a vehicle taken over by a ground
station's mode change leaves the team and its task moves, and rejoins when given back; every streamed
setpoint stays within the continuity bound. Positions are read from the models over MAVLink.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from companion.team.tasks import TaskDef
from companion.team.transport import open_transport
from harness.observer import GUIDED, LOITER
from harness.team import TeamRig, distance_m, fly_nine_tasks, geo
from harness.timing import wait_for

pytestmark = pytest.mark.integration

SPEEDUP = 3.0


def test_nine_tasks_of_every_type_added_flown_and_cancelled(team_rig: TeamRig) -> None:
    team_rig.ensure_companions()
    start = len(team_rig.station.log.entries)
    fly_nine_tasks(team_rig)
    events = team_rig.station.log.entries[start:]
    conflicts = [e for e in events if e["event"] == "conflict"]  # two claims on one task seen by the station
    yielded = sum(team_rig.team(i)["conflicts"] for i in range(team_rig.n))  # claims given up to a lower cost
    assert conflicts or yielded, "no conflict declared (two vehicles claiming one task)"
    assert all(any(e["event"] == "resolved" and e["task"] == c["task"] for e in events) for c in conflicts)
    assert team_rig.discontinuities() == []


def test_killed_vehicle_task_reallocated_after_its_voc_runs_out(team_rig: TeamRig) -> None:
    team_rig.ensure_companions()
    st = team_rig.station
    task = team_rig.add(TaskDef("patrol_line", (geo(-15, -20, 8), geo(-15, 20, 8)), name="patrol-k"))[0]
    wait_for(lambda: team_rig.state(task) == "active", team_rig.wall(90), "the patrol flown")
    holder = team_rig.holder(task)
    assert holder is not None
    team_rig.kill_companion(holder - 1)
    wait_for(lambda: holder not in st.state.alive(), 30, f"member {holder} gone (voc ran out)")
    wait_for(lambda: team_rig.state(task) == "active" and team_rig.holder(task) not in (None, holder),
             team_rig.wall(90),
             "the patrol re-allocated and flown by another vehicle")
    new = team_rig.holder(task)
    st.cancel(task)
    team_rig.ensure_companions()  # the killed companion restarted: its vehicle rejoins the team
    wait_for(lambda: team_rig.team(holder - 1)["status"] in ("idle", "landed", "busy"), 30, "rejoined")
    assert new != holder
    assert team_rig.discontinuities() == []


def test_ground_station_mode_change_takes_the_vehicle_out_of_the_team(team_rig: TeamRig) -> None:
    team_rig.ensure_companions()
    task = team_rig.add(TaskDef("patrol_line", (geo(10, -25, 8), geo(10, 25, 8)), name="patrol-o"))[0]
    wait_for(lambda: team_rig.state(task) == "active", team_rig.wall(90), "the patrol flown")
    holder = team_rig.holder(task)
    assert holder is not None
    gcs = team_rig.gcs[holder - 1]
    gcs.set_mode(LOITER)  # the autopilot's own ground station: the lowest tier overrides the others
    wait_for(lambda: team_rig.team(holder - 1)["status"] == "overridden", team_rig.wall(30),
             "seen as overridden")
    wait_for(lambda: team_rig.station.state.get(holder).status.name == "OVERRIDDEN", 10, "the team sees it")
    wait_for(lambda: team_rig.state(task) == "active" and team_rig.holder(task) not in (None, holder),
             team_rig.wall(90),
             "the patrol moved to another vehicle")
    assert team_rig.team(holder - 1)["claims"] == []
    gcs.set_mode(GUIDED)  # given back: it rejoins
    wait_for(lambda: team_rig.team(holder - 1)["status"] in ("idle", "busy"), team_rig.wall(30), "rejoined")
    team_rig.station.cancel(task)
    wait_for(lambda: team_rig.state(task) == "cancelled", 5, "cancelled")
    assert team_rig.discontinuities() == []


def test_directed_commands_take_and_release(team_rig: TeamRig) -> None:
    team_rig.ensure_companions()
    with team_rig.http(0) as c:
        r = c.post("/team/take", json={"reason": "operator inspection"})
        assert r.status_code == 200 and r.json()["team"]["status"] == "taken"
        wait_for(lambda: team_rig.station.state.get(1).status.name == "TAKEN", 10,
                 "the team sees member 1 taken")
        task = team_rig.add(TaskDef("visit", (geo(-5, -5, 6),), name="visit-t"))[0]  # next to vehicle 1
        wait_for(lambda: team_rig.state(task) == "done", team_rig.wall(90),
                 "the visit flown by another vehicle")
        assert team_rig.holder(task) != 1
        r = c.post("/team/task", json={"kind": "visit", "points": [list(geo(5, -5, 6))]})
        assert r.status_code == 200 and r.json()["team"]["controller"] == "directed"
        wait_for(lambda: (p := team_rig.position(0)) is not None and distance_m(p, geo(5, -5)) < 1.0,
                 team_rig.wall(60), "vehicle 1 at its directed visit")
        assert c.post("/team/release").status_code == 200
        wait_for(lambda: team_rig.team(0)["status"] in ("idle", "busy"), 10, "back in the team")
        bad = c.post("/team/task", json={"kind": "visit", "points": [[95.0, 0.0]]})
        assert bad.status_code == 400 and "latitude" in bad.json()["error"]
    assert team_rig.discontinuities() == []


def test_bad_team_input_changes_nothing(team_rig: TeamRig, tmp_path: Path) -> None:
    st = team_rig.station
    before = [(v.id, v.state) for v in st.tasks()]
    with pytest.raises(ValueError, match="n: the number of vehicles"):
        st.add(TaskDef("border_patrol", (geo(0, 0), geo(0, 50)), n=0))
    with pytest.raises(ValueError, match="points"):
        st.add(TaskDef("patrol_line", (geo(0, 0),)))
    far = TaskDef("visit", (geo(5000, 0, 10),), name="far")  # outside every vehicle's platform fence
    ids = st.add(far).ids
    wait_for(lambda: all(team_rig.team(i)["board"]["seq"] >= st.ledger.board().seq
                         for i in range(team_rig.n)), 10, "the board reached every vehicle")
    wait_for(lambda: all(str(ids[0]) in team_rig.team(i)["cannot"] for i in range(team_rig.n)), 10,
             "every vehicle's delegation rejected it")
    assert team_rig.state(ids[0]) == "unassigned"  # no vehicle bids for what its delegation rejects
    st.cancel(ids[0])
    assert [(v.id, v.state) for v in st.tasks() if v.id != ids[0]] == before


def test_a_tst_with_a_c_root_is_delegated_across_the_team(team_rig: TeamRig) -> None:
    """Seed 000 Sec. III across the team: the children of a C node go to different vehicles through the
    allocation; each vehicle bids only for what its own delegation (check, constraints) accepts."""
    team_rig.ensure_companions()
    tree = {"type": "C", "id": "both", "children": [
        {"type": "fly-to", "id": "north", "params": {"position": list(geo(20, 0, 7)), "speed": "standard"}},
        {"type": "fly-to", "id": "south", "params": {"position": list(geo(-20, 10, 7)), "speed": "standard"}},
        {"type": "fly-to", "id": "high", "params": {"position": list(geo(0, 0, 90)), "speed": "standard"}},
    ]}
    ids = team_rig.add(TaskDef("tst", tree=tree, name="c-node"))
    assert len(ids) == 3  # one team task per child of the C node
    north, south, high = ids
    wait_for(lambda: team_rig.state(north) == "done" and team_rig.state(south) == "done", team_rig.wall(120),
             "both reachable children flown")
    # 90 m is above every vehicle's ceiling (the outdoor platform's 60 m): no vehicle bids for it
    wait_for(lambda: all(str(high) in team_rig.team(i)["cannot"] for i in range(team_rig.n)), 10,
             "judged by all")
    assert team_rig.state(high) == "unassigned"
    team_rig.station.cancel(
        team_rig.station.tasks()[[v.id for v in team_rig.station.tasks()].index(north)].group)
    assert team_rig.state(high) == "cancelled"
    assert team_rig.discontinuities() == []


def test_malformed_team_packets_are_counted_and_ignored(team_rig: TeamRig) -> None:
    team_rig.ensure_companions()
    before = [team_rig.team(i)["link"] for i in range(team_rig.n)]
    sender = open_transport(team_rig.team_url)
    try:
        sender.send(b"\x00garbage that is no team packet")
        sender.send(b"TF\x63" + bytes(40))  # the magic of the team link, a version from the future
        wait_for(lambda: all(team_rig.team(i)["link"]["garbage"] + team_rig.team(i)["link"]["foreign_version"]
                             >= before[i]["garbage"] + before[i]["foreign_version"] + 1
                             for i in range(team_rig.n)), 10, "the bad packets counted by every member")
    finally:
        sender.close()
    # nothing else changed: every member still in the team
    assert len(team_rig.station.vehicle_rows()) == team_rig.n
