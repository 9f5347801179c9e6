"""Distributed task allocation (seed 003 Sec. III-B; CBBA, Choi, Brunet and How 2009).

Every member runs a policy on its own copy of the group state and writes the result only into its own
row (seed 003 Sec. III-B: "each variable has only one process with write permission"); there is no
central allocator. :meth:`AllocationPolicy.decide` is pure: from the rows, the board, this member's cost
function and its current claims it returns its new claims, which the caller publishes.

Only live tasks (on the board, not done or cancelled, claims of the board's version) and only members
whose status is available count. A DONE claim cannot be outbid. An ACTIVE claim (being flown) yields
only to a clearly cheaper one (seed 003 Sec. III-B: "when one UAV sees that the other could complete the
task at a lower cost, it gives up the task"): a claim cheaper by the *active* hysteresis margin
(:data:`ACTIVE_MARGIN_REL` of the holder's cost, at least :data:`ACTIVE_MARGIN_ABS`), wider than the margin
between merely claimed tasks, so that a task being flown does not flap between two vehicles whose costs
differ a little. Of two ACTIVE claims (flown by both: after a partition, or two vehicles that started
flying at once) the one clearly dearer (by :data:`ACTIVE_TIE`) yields, and within that band the higher id
yields: each member compares the cost it *published* with the rival's published one (never its fresh
cost with the rival's a period older: both approach the task, so each would read itself cheaper and both
would fly it to the end). The holder's cost of an ACTIVE task is refreshed every decision (it falls as it
approaches) and is 0 once it has reached the task (:data:`REACHED`): a vehicle working on its task is
never out-bid by one that would first have to fly there.

:class:`GreedyPolicy` is seed 003's rule: "each UAV selects the task that it could complete at the lowest
cost to itself (a greedy algorithm), and then broadcasts its selection. In the event that two UAVs select
the same task, a conflict is declared and the UAVs must compare reported costs. When one UAV sees that
the other could complete the task at a lower cost, it gives up the task and selects its next lowest-cost
option. When a task is canceled, the UAVs assigned to it will claim new tasks if any remain unclaimed,
and otherwise will loiter at their current positions."

:class:`CbbaPolicy` is the consensus-based bundle algorithm (several tasks per vehicle).
"""

from __future__ import annotations

import logging
import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace

from companion.team.cost import CostModel, endless, exit_point
from companion.team.types import Claim, ClaimState, GeoPoint, MemberEntry, TaskBoard, TeamTask

log = logging.getLogger(__name__)

CostFn = Callable[[TeamTask], float]

#: rank of a rival claim: ACTIVE and DONE hold a task firmly, CLAIMED can be outbid
_FIRM = 0
_SOFT = 1

#: an ACTIVE claim yields to a claim cheaper by this fraction of its cost ...
ACTIVE_MARGIN_REL = 0.25
#: ... and by at least this much (cost units: s of flight, m for the Euclidean cost)
ACTIVE_MARGIN_ABS = 5.0
#: an ACTIVE claim whose cost fell below this has reached its task: its cost is 0 from then on
REACHED = 2.0
#: of two ACTIVE claims on one task, costs closer than this are a tie (the lower id keeps the task): wider
#: than the drift of two approaching vehicles' costs between their rows (a period each)
ACTIVE_TIE = 5.0
#: a challenger judges an ACTIVE holder's cost as this much lower than the row says: the holder's cost falls
#: as it approaches (up to 1 s a second) and the challenger reads a row up to a period or two old, so without
#: it the challenger would claim a task the holder (checking its fresher cost) keeps: both would hold it
ACTIVE_DRIFT = 2.0


@dataclass(frozen=True)
class Rival:
    """Another member's claim on a task as its row reports it."""

    member: int
    cost: float
    firm: bool  #: ACTIVE or DONE
    done: bool = False  #: DONE (never outbid); firm and not done: ACTIVE

    @property
    def active(self) -> bool:
        return self.firm and not self.done

    def key(self) -> tuple[int, float, int]:
        return (_FIRM if self.firm else _SOFT, self.cost, self.member)


def clearly_cheaper(bid: float, holder_cost: float) -> bool:
    """Does ``bid`` take a task flown (ACTIVE) at ``holder_cost``? Only when cheaper by the active margin."""
    return bid < holder_cost - _margin(holder_cost, ACTIVE_MARGIN_REL, ACTIVE_MARGIN_ABS)


def active_cost(previous: float, now: float) -> float:
    """The holder's cost of its ACTIVE task: ``now``, and 0 once it reached the task (latched)."""
    return 0.0 if previous <= 0.0 or now < REACHED else now


def active_loses(me: int, c: Claim, rs: Sequence[Rival]) -> bool:
    """My ACTIVE claim ``c`` (its cost as I published it) yields: to a DONE report, to an ACTIVE rival that
    beats it (:func:`_active_beats`), or to a claim clearly cheaper (the active margin)."""
    for r in rs:
        if r.done:
            return True
        if r.firm and _active_beats(r.cost, r.member, c.cost, me):
            return True
        if not r.firm and clearly_cheaper(r.cost, c.cost):
            return True
    return False


def _active_beats(cost: float, member: int, mine: float, me: int) -> bool:
    """Does an ACTIVE claim at ``cost`` by ``member`` beat mine? One that reached the task (0) beats one that
    did not; else cheaper by :data:`ACTIVE_TIE`, or within it with the lower id."""
    if (cost <= 0.0) != (mine <= 0.0):
        return cost <= 0.0
    return cost < mine - ACTIVE_TIE or (abs(cost - mine) <= ACTIVE_TIE and member < me)


def rivals(me: int, entries: Mapping[int, MemberEntry], board: TaskBoard) -> dict[int, list[Rival]]:
    """Claims of the other available members on live tasks of the board's version, by task id."""
    live = {t.id: t.version for t in board.live()}
    out: dict[int, list[Rival]] = {}
    for m, e in entries.items():
        if m == me or not e.status.available:
            continue
        for c in e.claims:
            if live.get(c.task) != c.version or c.state is ClaimState.FAILED:
                continue
            firm = c.state in (ClaimState.ACTIVE, ClaimState.DONE)
            out.setdefault(c.task, []).append(Rival(m, c.cost, firm, c.state is ClaimState.DONE))
    return out


def _kept(board: TaskBoard, current: Sequence[Claim]) -> tuple[list[Claim], list[Claim]]:
    """Split my claims on live tasks into (held: CLAIMED/ACTIVE, parked: DONE/FAILED kept until the board
    says so); claims on tasks gone, cancelled, done or of an old version are dropped."""
    live = {t.id: t.version for t in board.live()}
    held: list[Claim] = []
    parked: list[Claim] = []
    for c in current:
        if live.get(c.task) != c.version:
            continue
        (parked if c.state in (ClaimState.DONE, ClaimState.FAILED) else held).append(c)
    return held, parked


def _position(me: int, entries: Mapping[int, MemberEntry]) -> GeoPoint | None:
    """My position from my own row, if the caller passed it (else None: see :func:`_first_point`)."""
    e = entries.get(me)
    return e.position if e is not None else None


def _first_point(task: TeamTask) -> GeoPoint:
    """Where a path's first task is entered when my own row was not passed: its first point."""
    return task.points[0] if task.points else (0.0, 0.0, 0.0)


class AllocationPolicy(ABC):
    """One member's allocation rule: its new claims from the group state (pure, see module doc)."""

    def __init__(self) -> None:
        #: conflicts declared: a claim given up because another member claims the task at a lower cost
        self.conflicts = 0

    @abstractmethod
    def decide(self, me: int, entries: Mapping[int, MemberEntry], board: TaskBoard, cost: CostFn,
               current: tuple[Claim, ...]) -> tuple[Claim, ...]:
        """My claims in order (the caller publishes them in its own row)."""

    def order(self, me: int, entries: Mapping[int, MemberEntry], board: TaskBoard, cost: CostFn,
              claims: tuple[Claim, ...]) -> tuple[int, ...]:
        """The order in which to fly my claimed tasks (the claims' order by default)."""
        return tuple(c.task for c in claims if c.state in (ClaimState.CLAIMED, ClaimState.ACTIVE))


def _margin(cost: float, rel: float, absolute: float) -> float:
    return max(absolute, rel * abs(cost)) if math.isfinite(cost) else absolute


class GreedyPolicy(AllocationPolicy):
    """Seed 003 Sec. III-B greedy selection with conflict resolution (one task per member).

    Rules (in order): keep the task I hold unless another member holds it firmly or claims it at a lower
    reported cost (ties: the lower member id wins) -> a conflict is declared and I yield; I may switch from
    a merely claimed task to another only if it is cheaper by the hysteresis margin; otherwise I take the
    task I can do at the lowest cost among those I can win; a task another member claims can be won only
    by a cost lower than its reported cost by the margin (hysteresis: costs change as vehicles fly, tasks
    must not flap); nothing left -> no claim (loiter). An ACTIVE claim is never given up for a cheaper
    task, and a task flown by another member is won only by a clearly cheaper claim (module docstring).
    My reported cost of a claimed task is refreshed every decision (it falls as I approach).

    ``margin_rel`` and ``margin_abs`` (cost units) set the hysteresis.
    """

    def __init__(self, margin_rel: float = 0.1, margin_abs: float = 1.0) -> None:
        super().__init__()
        if margin_rel < 0 or margin_abs < 0:
            raise ValueError("margin: must be >= 0")
        self.margin_rel = margin_rel
        self.margin_abs = margin_abs

    def _margin(self, cost: float) -> float:
        return _margin(cost, self.margin_rel, self.margin_abs)

    def decide(self, me: int, entries: Mapping[int, MemberEntry], board: TaskBoard, cost: CostFn,
               current: tuple[Claim, ...]) -> tuple[Claim, ...]:
        held, parked = _kept(board, current)
        riv = rivals(me, entries, board)
        live = {t.id: t for t in board.live()}
        excluded = {c.task for c in parked}
        mine: Claim | None = None
        for c in held[:1]:
            mine = c if not self._loses(me, c, riv.get(c.task, [])) else None
            if mine is None:
                self.conflicts += 1
                excluded.add(c.task)
                log.debug("member %d: conflict on task %d, yields", me, c.task)
        if mine is not None and mine.state is ClaimState.ACTIVE:
            return (replace(mine, cost=active_cost(mine.cost, cost(live[mine.task]))), *parked)
        costs = {tid: cost(t) for tid, t in live.items() if tid not in excluded}
        if mine is not None:
            now = costs.get(mine.task, mine.cost)
            mine = replace(mine, cost=now)
        best: tuple[float, int] | None = None
        for tid, bid in costs.items():
            if mine is not None and tid == mine.task:
                continue
            if not self._winnable(me, bid, riv.get(tid, [])):
                continue
            if best is None or (bid, tid) < best:
                best = (bid, tid)
        if mine is not None and (best is None or best[0] >= mine.cost - self._margin(mine.cost)):
            return (mine, *parked)
        if best is None:
            return tuple(parked)
        return (Claim(best[1], live[best[1]].version, best[0]), *parked)

    def _loses(self, me: int, c: Claim, rs: list[Rival]) -> bool:
        if c.state is ClaimState.ACTIVE:
            return active_loses(me, c, rs)
        return any(_claimed_loses(me, c, r) for r in rs)

    def _winnable(self, me: int, c: float, rs: list[Rival]) -> bool:
        return all(_beats(c, r, self._margin(r.cost)) for r in rs)


def _claimed_loses(me: int, c: Claim, r: Rival) -> bool:
    """My merely CLAIMED ``c`` against rival ``r``: a DONE report wins; an ACTIVE holder wins unless my
    claim is clearly cheaper than its cost; another claim wins with a lower (cost, id)."""
    if r.done:
        return True
    if r.active:
        return not clearly_cheaper(c.cost, r.cost)
    return (r.cost, r.member) < (c.cost, me)


def _beats(bid: float, r: Rival, margin: float) -> bool:
    """Can a new claim at ``bid`` take a task ``r`` holds? Never a DONE one; an ACTIVE one when clearly
    cheaper than its cost less :data:`ACTIVE_DRIFT` (the holder judges with a fresher cost); a CLAIMED one
    when lower by ``margin`` (hysteresis)."""
    if r.done:
        return False
    if r.active:
        return clearly_cheaper(bid, r.cost - ACTIVE_DRIFT)
    return bid < r.cost - margin


class CbbaPolicy(AllocationPolicy):
    """Consensus-based bundle algorithm (Choi, Brunet, How 2009), consensus through the flooded rows.

    Each member's row carries its bundle (claims in the order they were added) with its bids; the
    winner of a task is the best bid among the rows (lowest, ties by the lower id). Per decision:

    1. release: the first task of my bundle on which another row bids better (or holds it firmly) is
       lost, and with it every task added after it (their bids assumed the lost one);
    2. bundle building: while the bundle has fewer than ``max_tasks`` tasks, add the task of lowest bid
       that I can win, inserted at its best place in my path. The bid is the marginal path time
       (:meth:`~companion.team.cost.CostModel.path_time`: legs and each task's own flight), warped to be
       no lower than the previous bid in my bundle (Johnson, Ponda, Choi, How 2010: with non-diminishing
       marginal scores CBBA still converges when each bid is at least the bundle's last).

    An ACTIVE task stays first in the path; an endless task (a patrol) can only be last. A task another
    member bids on is won only by a bid lower than that by the hysteresis margin (near-ties do not
    ping-pong). :meth:`order` gives the path (the order to fly).
    """

    def __init__(self, model: CostModel, max_tasks: int = 3, margin_rel: float = 0.02,
                 margin_abs: float = 0.5) -> None:
        super().__init__()
        if max_tasks < 1:
            raise ValueError(f"max_tasks: must be >= 1, got {max_tasks}")
        self.model = model
        self.max_tasks = max_tasks
        self.margin_rel = margin_rel
        self.margin_abs = margin_abs

    # --- path ----------------------------------------------------------------------------------------
    def _path_time(self, at: GeoPoint | None, path: Sequence[TeamTask], cost: CostFn) -> float:
        if not path:
            return 0.0
        total = cost(path[0]) + self.model.work_time(path[0])
        here = exit_point(path[0], at if at is not None else _first_point(path[0]))
        for t in path[1:]:
            total += self.model.cost(here, t) + self.model.work_time(t)
            here = exit_point(t, here)
        return total

    def _insert(self, at: GeoPoint | None, path: list[TeamTask], task: TeamTask, cost: CostFn,
                first_fixed: bool) -> tuple[float, int]:
        """(marginal time, index) of the best insertion of ``task`` into ``path`` (inf when none fits)."""
        base = self._path_time(at, path, cost)
        lo = 1 if first_fixed and path else 0
        hi = len(path) - 1 if path and endless(path[-1]) else len(path)
        if endless(task):
            if path and endless(path[-1]):
                return math.inf, -1
            lo = max(lo, len(path))
        best = (math.inf, -1)
        for i in range(lo, hi + 1):
            d = self._path_time(at, [*path[:i], task, *path[i:]], cost) - base
            if d < best[0]:
                best = (d, i)
        return best

    def _path(self, at: GeoPoint | None, bundle: Sequence[Claim], live: Mapping[int, TeamTask], cost: CostFn
              ) -> list[TeamTask]:
        """The path: the ACTIVE task first, then the bundle's tasks inserted in bundle order."""
        path: list[TeamTask] = []
        active = [c for c in bundle if c.state is ClaimState.ACTIVE]
        for c in active[:1]:
            path.append(live[c.task])
        for c in bundle:
            if active and c is active[0]:
                continue
            _, i = self._insert(at, path, live[c.task], cost, bool(active))
            path.insert(i if i >= 0 else len(path), live[c.task])
        return path

    def order(self, me: int, entries: Mapping[int, MemberEntry], board: TaskBoard, cost: CostFn,
              claims: tuple[Claim, ...]) -> tuple[int, ...]:
        live = {t.id: t for t in board.live()}
        held, _ = _kept(board, claims)
        at = _position(me, entries)
        return tuple(t.id for t in self._path(at, held, live, cost))

    # --- decision ---------------------------------------------------------------------------------------
    def decide(self, me: int, entries: Mapping[int, MemberEntry], board: TaskBoard, cost: CostFn,
               current: tuple[Claim, ...]) -> tuple[Claim, ...]:
        held, parked = _kept(board, current)
        riv = rivals(me, entries, board)
        live = {t.id: t for t in board.live()}
        at = _position(me, entries)
        # 1. release: outbid on a task -> drop it and everything added after it (ACTIVE ones stay)
        bundle: list[Claim] = []
        lost = False
        outbid: set[int] = set()  # not bid for again in this decision (a drop and re-bid would hold it on)
        for c in held:
            if c.state is ClaimState.ACTIVE:
                if active_loses(me, c, riv.get(c.task, [])):  # the cost I published against theirs
                    self.conflicts += 1
                    lost = True
                    outbid.add(c.task)
                    continue
                bundle.append(replace(c, cost=active_cost(c.cost, cost(live[c.task]))))
                continue
            if lost:
                continue
            if any(_claimed_loses(me, c, r) for r in riv.get(c.task, [])):
                self.conflicts += 1
                lost = True
                outbid.add(c.task)
                continue
            bundle.append(c)
        excluded = {c.task for c in parked} | {c.task for c in bundle} | outbid
        # 2. bundle building
        path = self._path(at, bundle, live, cost)
        first_fixed = any(c.state is ClaimState.ACTIVE for c in bundle)
        while len(bundle) < self.max_tasks:
            last = max((c.cost for c in bundle), default=0.0)
            best: tuple[float, int, int] | None = None
            for tid, t in live.items():
                if tid in excluded:
                    continue
                marginal, idx = self._insert(at, path, t, cost, first_fixed)
                if not math.isfinite(marginal):
                    continue
                bid = max(marginal, last)
                rs = riv.get(tid, [])
                if not all(_beats(bid, r, _margin(r.cost, self.margin_rel, self.margin_abs)) for r in rs):
                    continue
                if best is None or (bid, tid) < best[:2]:
                    best = (bid, tid, idx)
            if best is None:
                break
            bid, tid, idx = best
            bundle.append(Claim(tid, live[tid].version, bid))
            path.insert(idx, live[tid])
            excluded.add(tid)
        return (*bundle, *parked)


#: the allocation policies by name
POLICIES = ("greedy", "cbba")


def make_policy(name: str, model: CostModel, max_tasks: int = 3) -> AllocationPolicy:
    """The policy called ``name`` (greedy: seed 003 Sec. III-B; cbba: at most ``max_tasks`` in a path)."""
    if name == "greedy":
        return GreedyPolicy()
    if name == "cbba":
        return CbbaPolicy(model, max_tasks=max_tasks)
    raise ValueError(f"policy: unknown allocation policy {name!r} (known: {', '.join(POLICIES)})")
