"""A team member under faults (seed 003 Sec. III-B): its decision step on a stand-in mission service (no
flight), so each rule is seen on its own: a member that loses its localization while its tree flies a
task keeps its claim (the tree still flies it); one that never had a tree does not bid."""

from __future__ import annotations

from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any

from companion.team.allocation import GreedyPolicy
from companion.team.cost import CostModel
from companion.team.geometry import LocalFrame
from companion.team.member import TeamMember
from companion.team.switchboard import Controller
from companion.team.tasks import TaskDef, TaskLedger
from companion.team.transport import MemoryBus
from companion.team.types import ClaimState
from companion.tst.platform import Platform

FRAME = LocalFrame(-35.363261, 149.165230)
MODEL = CostModel()


@dataclass
class FakeExecution:
    state: str | None = None

    @property
    def running(self) -> bool:
        return self.state in ("running", "paused")

    def root_status(self) -> Any:
        return None if self.state is None else SimpleNamespace(state=self.state, fail_reason="")


@dataclass
class FakeMissions:
    """What :class:`TeamMember` reads of the mission service: the vehicle, the platform, SELF_LOCALIZE,
    the one tree it runs (accepted, started: "running" until the test says otherwise)."""

    localized: bool = True
    execution: FakeExecution = field(default_factory=FakeExecution)
    submitted: list[Any] = field(default_factory=list)

    def __post_init__(self) -> None:
        status = SimpleNamespace(global_position=(*FRAME.to_geo(0.0, 0.0, 10.0)[:2], 600.0, 10.0),
                                 velocity=(0.0, 0.0, 0.0), overridden=False, on_ground=False)
        self.node = SimpleNamespace(vehicle_status=lambda: status)
        self.layer = SimpleNamespace(coordinator=SimpleNamespace(is_active=lambda name: self.localized))

    def platform(self) -> Platform:
        return Platform("test", (FRAME.lat, FRAME.lon))

    def submit(self, mission: Any) -> Any:
        self.submitted.append(mission)
        return SimpleNamespace(accepted=True, reasons=[])

    def start(self) -> None:
        self.execution.state = "running"

    def abort(self, reason: str = "", policy: str | None = None) -> None:
        self.execution.state = "aborted"


def member_with_a_visit() -> tuple[TeamMember, FakeMissions, int]:
    missions = FakeMissions()
    led = TaskLedger()
    (tid,) = led.add(TaskDef("visit", (FRAME.to_geo(40.0, 0.0, 10.0),)))
    m = TeamMember(missions, MemoryBus("faults").attach(), GreedyPolicy(), MODEL.cost,  # type: ignore[arg-type]
                   member_id=1, settle_s=0.0)
    m.state.merge_board(led.board(1.0))
    return m, missions, tid


def test_claim_kept_while_the_tree_flies_with_localization_lost() -> None:
    m, missions, tid = member_with_a_visit()
    m.step(1.0)
    m.step(1.1)
    assert m.switchboard.controller is Controller.TEAM and missions.execution.state == "running"
    assert [(c.task, c.state) for c in m.claims] == [(tid, ClaimState.ACTIVE)]
    missions.localized = False  # the estimate goes bad while the tree flies
    for k in range(10):
        m.step(1.2 + 0.25 * k)
        assert [(c.task, c.state) for c in m.claims] == [(tid, ClaimState.ACTIVE)], k
    missions.execution.state = "failed"  # the tree ends: the claim goes (not localized: no new bids)
    m.step(5.0)
    assert not [c for c in m.claims if c.state in (ClaimState.CLAIMED, ClaimState.ACTIVE)]


def test_no_bid_before_localization() -> None:
    m, missions, _tid = member_with_a_visit()
    missions.localized = False
    m.step(1.0)
    assert m.claims == () and missions.submitted == []
