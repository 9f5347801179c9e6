"""MAVProxy edits a mission in part: ``wp param`` and ``wp changealt`` send one item with
MISSION_WRITE_PARTIAL_LIST.

MAVProxy (pip package) runs as a user types at it: ``wp load FILE`` uploads a plan (MISSION_COUNT), then
``wp param 2 1 7`` (item 2's hold time) and ``wp changealt 3 25`` each write one item with
MISSION_WRITE_PARTIAL_LIST. A second ground station (pymavlink over UDP) downloads the plan after each
step: the edited item changed, every other item as uploaded, the count unchanged.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from harness.mavproxy import MavProxy
from harness.observer import Gcs, M
from harness.timing import wait_for

pytestmark = pytest.mark.integration

SPEEDUP = 10.0
HOME = (-35.363261, 149.165230, 584.0)


def _plan_file(path: Path) -> list[tuple[int, float, float, float]]:
    """A QGC WPL 110 file: home, take-off, two waypoints, RTL. Returns (command, lat, lon, alt) per item."""
    lat, lon, alt = HOME
    items = [(16, lat, lon, alt), (22, 0.0, 0.0, 10.0), (16, lat + 0.0003, lon, 10.0),
             (16, lat + 0.0003, lon + 0.0003, 15.0), (20, 0.0, 0.0, 0.0)]
    lines = ["QGC WPL 110"]
    for i, (cmd, la, lo, al) in enumerate(items):
        frame = 0 if i == 0 else 3
        lines.append(f"{i}\t{int(i == 0)}\t{frame}\t{cmd}\t0\t0\t0\t0\t{la:.7f}\t{lo:.7f}\t{al:.2f}\t1")
    path.write_text("\n".join(lines) + "\n")
    return items


def _download(gcs: Gcs) -> list[Any]:
    """The stored plan, item by item, as the observer downloads it."""
    gcs.mission.clear()
    gcs.conn.mav.mission_request_list_send(1, 1, 0)
    count = gcs.next_mission(("MISSION_COUNT",)).count
    items = []
    for seq in range(count):
        gcs.conn.mav.mission_request_int_send(1, 1, seq, 0)
        items.append(gcs.next_mission(("MISSION_ITEM_INT",)))
    gcs.conn.mav.mission_ack_send(1, 1, M.MAV_MISSION_ACCEPTED, 0)
    return items


def _typed_until(mp: MavProxy, command: str, done: Any, what: str, tries: int = 3) -> None:
    """Type ``command`` into MAVProxy until ``done()``: the observer's downloads are paced (1 s) so they
    do not hold the mission protocol while MAVProxy writes; a write lost on a loaded machine is typed
    again (MAVProxy does not retry a partial write itself)."""
    for attempt in range(tries):
        mp.type(command)
        try:
            wait_for(done, 15, what, poll_s=1.0)
            return
        except AssertionError:
            if attempt == tries - 1:
                raise


def test_mavproxy_wp_partial_edit(mavproxy: tuple[MavProxy, Gcs], tmp_path: Path) -> None:
    (mp, gcs), d = mavproxy, tmp_path
    mp.out.wait("Detected vehicle 1:1", 30)
    wait_for(lambda: gcs.last.get("HEARTBEAT") is not None, 20, "the observer's first heartbeat")
    plan = _plan_file(d / "plan.txt")
    mp.type(f"wp load {d / 'plan.txt'}")
    mp.out.wait("Sent all 5", 30)
    before: list[Any] = []
    # MAVProxy prints "Sent all" as it sends the last item: the vehicle may not have stored it yet
    wait_for(lambda: len(before.__setitem__(slice(None), _download(gcs)) or before) == 5, 30,
             "the uploaded plan")
    assert [m.command for m in before] == [c for c, *_ in plan]
    assert before[2].param1 == 0.0 and before[3].z == pytest.approx(15.0)

    after: list[Any] = []

    def edited() -> bool:
        after[:] = _download(gcs)
        return after[2].param1 == 7.0

    _typed_until(mp, "wp param 2 1 7", edited, "item 2's hold time edited")  # MISSION_WRITE_PARTIAL_LIST 2..2
    assert len(after) == 5
    for seq in (1, 3, 4):
        a, b = after[seq], before[seq]
        assert (a.command, a.x, a.y, a.z, a.param1) == (b.command, b.x, b.y, b.z, b.param1), seq

    _typed_until(mp, "wp changealt 3 25",  # one item's altitude: MISSION_WRITE_PARTIAL_LIST 3..3
                 lambda: (after.__setitem__(slice(None), _download(gcs)), after[3].z == 25.0)[1],
                 "item 3's altitude edited")
    assert len(after) == 5 and after[2].param1 == 7.0
    assert (after[3].x, after[3].y) == (before[3].x, before[3].y)
    assert not any("Mission" in t and "denied" in t.lower() for t in gcs.texts)
