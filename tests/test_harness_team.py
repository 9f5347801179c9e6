"""The team rig's claim sampler can fail: a task held by two vehicles for a whole sampling period is
reported with the samples that show it; a double claim seen once (a conflict declared and resolved,
seed 003 Sec. II) is not."""

from __future__ import annotations

from typing import Any

import pytest

from harness.hosts import held_twice
from harness.team import ClaimSampler


class Script:
    """A stand-in for :class:`harness.team.TeamRig`: ``team(i)`` answers from a list of board states."""

    def __init__(self, boards: list[list[list[int]]]) -> None:
        self.n = len(boards[0])
        self.boards, self.k = boards, 0

    def team(self, i: int) -> dict[str, Any]:
        return {"claims": [{"task": t, "state": "flying"} for t in self.boards[self.k][i]]}


def sampled(boards: list[list[list[int]]]) -> ClaimSampler:
    rig = Script(boards)
    sampler = ClaimSampler(rig)  # type: ignore[arg-type]
    for k in range(len(boards)):
        rig.k = k
        sampler.samples.append((float(k), sampler.sample()))
    return sampler


def test_a_task_held_twice_in_two_samples_fails_naming_them() -> None:
    s = sampled([[[1], [2], []], [[1], [1], []], [[1], [1], []], [[1], [], []]])
    with pytest.raises(AssertionError, match=r"at 1\.00 s and 2\.00 s: \{1: \(\[0, 1\], \[0, 1\]\)\}"):
        s.assert_no_task_held_twice()


def test_a_double_claim_seen_once_passes() -> None:
    sampled([[[1], [2], []], [[1], [1], []], [[], [1], []], [[], [1], [3]]]).assert_no_task_held_twice()


def test_no_sample_fails() -> None:
    with pytest.raises(AssertionError, match="no claims sampled"):
        ClaimSampler(Script([[[]]])).assert_no_task_held_twice()  # type: ignore[arg-type]


def test_the_ground_view_counts_only_vehicles_it_hears() -> None:
    def v(state: str, age: float | None, *claims: int) -> dict[str, Any]:
        return {"team_state": state, "age_s": age, "claims": list(claims)}
    assert held_twice({1: v("available", 0.3, 7), 2: v("taken", 1.9, 7, 8), 3: v("available", 0.1, 8)}) \
        == {7: [1, 2], 8: [2, 3]}
    # gone, never heard, or not heard for longer than the operator's page calls live: its claims are history
    assert held_twice({1: v("available", 0.3, 7), 2: v("gone", 0.2, 7), 3: v("available", None, 7),
                       4: v("taken", 2.5, 7)}) == {}
