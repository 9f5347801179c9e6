"""The consensus-based bundle algorithm flying (CBBA as a selectable allocation policy).

Three companions run ``--team-policy cbba``: each builds a bundle of several tasks by marginal flight time
and flies it in its path's order; consensus comes from the flooded rows. Five visits for three vehicles:
some vehicle holds two, every visit is flown, a task held twice (a conflict) is let go within a few
team-link periods all through the flight (every sample checked), the setpoints stay continuous. A patrol
given a speed of its own is flown at that speed (measured on the autopilot).
"""

from __future__ import annotations

import statistics

import pytest

from companion.team.tasks import TaskDef
from harness.team import ClaimSampler, TeamRig, distance_m, geo
from harness.timing import wait_for

pytestmark = pytest.mark.integration

SPEEDUP = 3.0


TEAM_POLICY = "cbba"  # the team_rig fixture's allocation policy


def test_five_visits_bundled_among_three_vehicles(team_rig: TeamRig) -> None:
    """Sampled over the whole flight (:class:`ClaimSampler`, every sample checked), not at its end (when every
    visit is done none can be held): two vehicles may claim one visit before they hear each other (seed 003
    Sec. III-B), and one of them lets it go within a few team-link periods. A conflict's length is counted
    in the packets the vehicles broadcast meanwhile (two a period each, plus announcements), so a loaded
    machine that runs the team link late does not lengthen it."""
    points = [geo(25, 0, 8), geo(30, 10, 8), geo(-20, 5, 8), geo(-25, -10, 8), geo(5, 30, 8)]
    most = 0
    with ClaimSampler(team_rig) as claims:
        ids = [team_rig.add(TaskDef("visit", (p,), name=f"v{k}"))[0] for k, p in enumerate(points)]

        def all_done() -> bool:
            nonlocal most
            if claims.samples:
                most = max(most, max((sum(1 for who in claims.samples[-1][1].values() if i in who)
                                      for i in range(team_rig.n)), default=0))
            return all(team_rig.state(t) == "done" for t in ids)

        wait_for(all_done, team_rig.wall(240), "every visit flown", poll_s=0.2)
    assert most >= 2  # a bundle: one vehicle held several tasks at once
    holders = {team_rig.holder(t) for t in ids}
    assert len(holders) >= 2  # divided among the team
    claims.assert_no_task_held_twice(max_packets=20)
    claims.assert_visited(points, within_m=3.0)
    assert team_rig.discontinuities() == []


def test_a_patrol_is_flown_at_its_own_speed(team_rig: TeamRig) -> None:
    """The API's patrol speed is flown (and bid with): 1.5 times the standard speed, a speed no name says,
    measured from the holder's GLOBAL_POSITION_INT along the line's middle."""
    speed = 6.0  # the outdoor platform: standard 4 m/s, fast 8 m/s
    a, b = geo(-40, -30, 8), geo(-40, 50, 8)
    with ClaimSampler(team_rig) as claims:
        task = team_rig.add(TaskDef("patrol_line", (a, b), speed=speed, name="fast-patrol"))[0]
        wait_for(lambda: team_rig.state(task) == "active", team_rig.wall(90), "the patrol flown")
        holder = team_rig.holder(task)
        assert holder is not None
        speeds: list[float] = []

        def measured() -> bool:
            m = team_rig.gcs[holder - 1].last.get("GLOBAL_POSITION_INT")
            p = team_rig.position(holder - 1)
            # on the line's middle 20 m, 30 m from either turn (it brakes for a turn over up to ~18 m: a wider
            # window, or samples spread by a loaded machine, caught the braking); several passes if need be
            if m is not None and p is not None and distance_m(p, geo(-40, 10)) < 10 and abs(
                    distance_m(p, a) + distance_m(p, b) - distance_m(a, b)) < 3:
                speeds.append(((m.vx / 100) ** 2 + (m.vy / 100) ** 2) ** 0.5)
            return len(speeds) >= 15

        wait_for(measured, team_rig.wall(240), "the patrol's speed measured", poll_s=0.1)
        team_rig.station.cancel(task)
        wait_for(lambda: team_rig.state(task) == "cancelled", 10, "cancelled")
    assert statistics.median(speeds) == pytest.approx(speed, abs=0.6), speeds
    claims.assert_no_task_held_twice(max_packets=20)
    assert team_rig.discontinuities() == []
