"""One team member's decision step (seed 003 Sec. III-B), shared by the flying member and the simulator.

"Each UAV calculates the cost ... selects the task ... and then broadcasts its selection." Every decision
period a member:

1. forgets the tasks it failed :data:`RETRY_FAILED_S` ago (what made it fail may have passed);
2. takes the board without what is over (tasks reported done by anyone, done or failed by itself, and
   those its platform cannot fly: ``acceptable``);
3. asks its allocation policy (greedy or CBBA, :mod:`companion.team.allocation`) which tasks it claims
   given everyone's rows, and in which order it flies them;
4. publishes its claims: ACTIVE for the task it flies, CLAIMED for the others, DONE for the tasks it
   finished until the board says they are over, FAILED for the live tasks it could not fly;
5. flies the first live claim in the policy's order once it has been held ``settle_s`` without being
   out-bid (so that most conflicts are resolved before the vehicle turns, seed 003 Sec. V).

:class:`DecisionStep` is that step and the bookkeeping it needs; what flies the task (a TST on a real
vehicle, :class:`~companion.team.member.TeamMember`; a kinematic point mass, :mod:`companion.team.sim`)
is the caller's.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

from .types import Claim, ClaimState, GeoPoint, MemberEntry, TaskBoard, TeamTask

if TYPE_CHECKING:
    from .allocation import AllocationPolicy

#: seconds after which a task this vehicle failed may be bid for again
RETRY_FAILED_S = 30.0


@dataclass(frozen=True)
class Choice:
    """What to fly after a decision: ``task`` (None: nothing claimed, loiter); ``settled``: it has been held
    long enough to switch to it."""

    task: TeamTask | None
    settled: bool


class DecisionStep:
    """Claims, done and failed tasks of one member, and the step that revises them (module docstring)."""

    def __init__(self, member_id: int, policy: AllocationPolicy, cost: Callable[[GeoPoint, TeamTask], float],
                 *, clock: Callable[[], float], settle_s: float = 0.0,
                 acceptable: Callable[[TeamTask], bool] = lambda t: True,
                 on_event: Callable[..., None] | None = None, retry_failed_s: float = RETRY_FAILED_S) -> None:
        self.member_id = member_id
        self.policy = policy
        self.cost = cost
        self.clock = clock
        self.settle_s = settle_s
        self.acceptable = acceptable
        self.on_event = on_event
        self.retry_failed_s = retry_failed_s
        self.claims: tuple[Claim, ...] = ()
        self.done: dict[int, int] = {}      # task id -> version this vehicle finished
        self.failed: dict[int, str] = {}    # task id -> why this vehicle could not fly it
        self._failed_at: dict[int, float] = {}
        self._claimed_at: dict[int, float] = {}

    # --- what the flight reports ----------------------------------------------------------------------
    def finished(self, task: TeamTask) -> None:
        """``task`` was flown to its end: reported DONE until the board says it is over."""
        self.done[task.id] = task.version
        self.claims = tuple(replace(c, state=ClaimState.DONE) if c.task == task.id else c
                            for c in self.claims)

    def fail(self, task_id: int, reason: str) -> None:
        """This vehicle could not fly ``task_id``: reported FAILED, not bid for during the retry time."""
        self.failed[task_id] = reason
        self._failed_at[task_id] = self.clock()

    def clear(self) -> None:
        """No claims (a vehicle out of the team, or not yet localized)."""
        self.claims = ()

    # --- the step ---------------------------------------------------------------------------------------
    def step(self, now: float, position: GeoPoint, board: TaskBoard, rows: Mapping[int, MemberEntry],
             own: Callable[[], MemberEntry | None], flying: int | None) -> Choice:
        """One decision at ``now`` from ``position``: ``rows`` are the others' rows, ``own()`` this member's
        row, ``flying`` the task it flies now. Returns what to fly."""
        self._forget_failures(now)
        for tid in list(self.done):
            t = board.get(tid)
            if t is None or t.state.final:
                del self.done[tid]
        candidates = self._candidates(board, rows)
        current = tuple(c for c in self.claims if c.state in (ClaimState.CLAIMED, ClaimState.ACTIVE))

        def cost(t: TeamTask) -> float:
            return self.cost(position, t)

        row = own()
        entries = {**rows, self.member_id: row} if row is not None else dict(rows)
        decided = self.policy.decide(self.member_id, entries, candidates, cost, current)
        self._publish(decided, board, now, flying)
        order = self.policy.order(self.member_id, entries, candidates, cost, self.claims)
        live = {c.task for c in self.claims if c.state in (ClaimState.CLAIMED, ClaimState.ACTIVE)}
        first = next((t for t in order if t in live), None)
        if first is None:
            return Choice(None, True)
        task = board.get(first)
        settled = flying == first or now - self._claimed_at.get(first, now) >= self.settle_s
        return Choice(task, settled)

    def _forget_failures(self, now: float) -> None:
        for tid in [t for t, at in self._failed_at.items() if now - at >= self.retry_failed_s]:
            self.failed.pop(tid, None)
            del self._failed_at[tid]

    def _candidates(self, board: TaskBoard, rows: Mapping[int, MemberEntry]) -> TaskBoard:
        """The board without what is over: tasks reported done by anyone, and those this vehicle failed."""
        reported_done = {c.task for e in rows.values() for c in e.claims if c.state is ClaimState.DONE}
        live = tuple(t for t in board.tasks if t.live and t.id not in reported_done and t.id not in self.done
                     and t.id not in self.failed and self.acceptable(t))
        return replace(board, tasks=live)

    def _publish(self, decided: tuple[Claim, ...], board: TaskBoard, now: float, flying: int | None) -> None:
        claims = []
        for c in decided:
            self._claimed_at.setdefault(c.task, now)
            cost = c.cost if math.isfinite(c.cost) else 1e9
            state = ClaimState.ACTIVE if c.task == flying else ClaimState.CLAIMED
            claims.append(Claim(c.task, c.version, cost, state))
        held = {c.task for c in claims}
        for tid in list(self._claimed_at):
            if tid not in held:
                del self._claimed_at[tid]
        for tid, version in self.done.items():
            claims.append(Claim(tid, version, 0.0, ClaimState.DONE))
        for tid in self.failed:
            t = board.get(tid)
            if t is not None and t.live:
                claims.append(Claim(tid, t.version, 1e9, ClaimState.FAILED))
        if [(c.task, c.state) for c in claims] != [(c.task, c.state) for c in self.claims]:
            self._event("claims", claims=[(c.task, c.state.name) for c in claims])
        self.claims = tuple(claims)

    def _event(self, kind: str, **fields: Any) -> None:
        if self.on_event is not None:
            self.on_event(kind, **fields)
