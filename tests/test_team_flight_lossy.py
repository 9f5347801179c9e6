"""Seed 003's flight demonstration with 30 % of the team packets dropped (seed 003 Sec. V).

The same nine tasks as :mod:`test_team_flight`, every member (companions and station) dropping 30 % of what
it receives on the team link: the flooding of the group state carries each vehicle's row and the board
through the loss, the allocation still converges (no task held twice), every task ends done or cancelled.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from harness.team import TeamRig, fly_nine_tasks

pytestmark = pytest.mark.integration

SPEEDUP = 3.0


@pytest.fixture(scope="module")
def rig(tmp_path_factory: pytest.TempPathFactory) -> Iterator[TeamRig]:
    r = TeamRig(tmp_path_factory.mktemp("team_lossy"), n=3, speedup=SPEEDUP, loss=0.3)
    try:
        yield r
    finally:
        r.close()


def test_nine_tasks_with_30_percent_of_team_packets_dropped(rig: TeamRig) -> None:
    fly_nine_tasks(rig)
    for i in range(rig.n):
        link = rig.team(i)["link"]
        total = link["packets_received"] + link["dropped_by_test_loss"]
        assert 0.2 < link["dropped_by_test_loss"] / total < 0.4, link  # the loss really happened
    assert rig.discontinuities() == []
