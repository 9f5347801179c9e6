"""Seed 003's flight demonstration with 30 % of the team packets dropped (seed 003 Sec. V).

The same nine tasks as :mod:`test_team_flight`, every member (companions and station) dropping 30 % of what
it receives on the team link: the flooding of the group state carries each vehicle's row and the board
through the loss, the allocation still converges (no task held twice), every task ends done or cancelled.
"""

from __future__ import annotations

import pytest

from harness.team import TeamRig, fly_nine_tasks

pytestmark = pytest.mark.integration

SPEEDUP = 3.0


TEAM_LOSS = 0.3  # of the team packets, dropped by every member (the team_rig fixture)


def test_nine_tasks_with_30_percent_of_team_packets_dropped(team_rig: TeamRig) -> None:
    fly_nine_tasks(team_rig)
    for i in range(team_rig.n):
        link = team_rig.team(i)["link"]
        total = link["packets_received"] + link["dropped_by_test_loss"]
        assert 0.2 < link["dropped_by_test_loss"] / total < 0.4, link  # the loss really happened
    assert team_rig.discontinuities() == []
