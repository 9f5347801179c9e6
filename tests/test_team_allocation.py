"""Distributed allocation (seed 003 Sec. III-B; CBBA): each rule on hand-made rows, then rounds of
several members deciding on the same snapshot until steady (no task held twice)."""

from __future__ import annotations

import dataclasses
import random

import pytest

from companion.team.allocation import AllocationPolicy, CbbaPolicy, GreedyPolicy
from companion.team.cost import CostModel, entry_point
from companion.team.geometry import LocalFrame
from companion.team.task_tst import mission_for
from companion.team.tasks import TaskDef, TaskLedger
from companion.team.types import Claim, ClaimState, MemberEntry, MemberStatus, TaskBoard
from companion.tst.delegation import delegate
from companion.tst.platform import load_platform
from harness.team import PLATFORM

FRAME = LocalFrame(-35.363261, 149.165230)
MODEL = CostModel(speed=5.0, accel=2.5, climb_speed=2.5)


def geo(x: float, y: float, z: float = 20.0) -> tuple[float, float, float]:
    return FRAME.to_geo(x, y, z)


def visits(*xy: tuple[float, float]) -> tuple[TaskLedger, list[int]]:
    led = TaskLedger()
    return led, [led.add(TaskDef("visit", (geo(x, y),)))[0] for x, y in xy]


def row(member: int, xy: tuple[float, float], claims: tuple[Claim, ...] = (),
        status: MemberStatus = MemberStatus.IDLE) -> MemberEntry:
    return MemberEntry(member=member, stamp=1.0, seq=1, position=geo(*xy), status=status, claims=claims,
                       voc=5)


def costfn(entry: MemberEntry):
    return lambda t: MODEL.cost(entry.position, t)


def decide(pol: AllocationPolicy, me: int, entries: dict[int, MemberEntry], board: TaskBoard
           ) -> tuple[Claim, ...]:
    return pol.decide(me, entries, board, costfn(entries[me]), entries[me].claims)


def settle(policies: dict[int, AllocationPolicy], entries: dict[int, MemberEntry], board: TaskBoard,
           rounds: int = 30) -> dict[int, MemberEntry]:
    """Synchronous rounds (all decide on one snapshot, then all publish) until nothing changes."""
    for _ in range(rounds):
        new = {m: dataclasses.replace(e, claims=decide(policies[m], m, entries, board))
               for m, e in entries.items()}
        if new == entries:
            return entries
        entries = new
    raise AssertionError("no steady state")


def held(entries: dict[int, MemberEntry]) -> dict[int, list[int]]:
    out: dict[int, list[int]] = {}
    for m, e in entries.items():
        for c in e.claims:
            out.setdefault(c.task, []).append(m)
    return out


def test_greedy_takes_the_lowest_cost_task() -> None:
    led, (_a, b, _c) = visits((100, 0), (40, 0), (-300, 0))
    entries = {1: row(1, (0, 0))}
    (claim,) = decide(GreedyPolicy(), 1, entries, led.board())
    assert claim.task == b and claim.cost == pytest.approx(MODEL.leg_time(40.0))


def test_greedy_conflict_higher_cost_yields_and_takes_its_next_best() -> None:
    led, (a, b) = visits((100, 0), (0, 300))
    board = led.board()
    v = board.get(a).version
    p1, p2 = GreedyPolicy(), GreedyPolicy()
    # both claimed a (neither had heard the other): 2 is nearer
    e = {1: row(1, (0, 0), (Claim(a, v, MODEL.leg_time(100)),)),
         2: row(2, (60, 0), (Claim(a, v, MODEL.leg_time(40)),))}
    assert decide(p2, 2, e, board)[0].task == a and p2.conflicts == 0
    (c1,) = decide(p1, 1, e, board)
    assert c1.task == b and p1.conflicts == 1


def test_greedy_conflict_tie_is_broken_by_the_lower_id() -> None:
    led, (a, _b) = visits((100, 0), (0, 300))
    board = led.board()
    v = board.get(a).version
    e = {3: row(3, (0, 0), (Claim(a, v, 10.0),)), 5: row(5, (200, 0), (Claim(a, v, 10.0),))}
    assert decide(GreedyPolicy(), 3, e, board)[0].task == a
    assert decide(GreedyPolicy(), 5, e, board)[0].task != a


def test_greedy_cancel_makes_the_holder_claim_another_then_loiter() -> None:
    led, (a, b) = visits((50, 0), (0, 400))
    pol = GreedyPolicy()
    e = {1: row(1, (0, 0))}
    (c,) = decide(pol, 1, e, led.board())
    assert c.task == a
    led.cancel(a)
    e = {1: row(1, (0, 0), (dataclasses.replace(c, state=ClaimState.ACTIVE),))}
    (c2,) = decide(pol, 1, e, led.board())
    assert c2.task == b
    led.cancel(b)
    assert decide(pol, 1, {1: row(1, (0, 0), (c2,))}, led.board()) == ()  # nothing left: loiter


def test_greedy_nothing_left_loiters_and_claimed_tasks_are_respected() -> None:
    led, (a,) = visits((500, 0))
    board = led.board()
    v = board.get(a).version
    e = {1: row(1, (450, 0), (Claim(a, v, MODEL.leg_time(50)),)), 2: row(2, (0, 0))}
    assert decide(GreedyPolicy(), 2, e, board) == ()


def test_greedy_hysteresis_no_flapping_on_small_differences() -> None:
    led, (a, b) = visits((100, 0), (0, 104))
    board = led.board()
    v = board.get(a).version
    pol = GreedyPolicy(margin_rel=0.1)
    # I hold a; b became slightly cheaper: I keep a
    e = {1: row(1, (0, 0), (Claim(a, v, MODEL.leg_time(100)),)), 2: row(2, (0, 103))}
    e[1] = dataclasses.replace(e[1], position=geo(0, 2))
    assert decide(pol, 1, e, board)[0].task == a
    # someone a little nearer does not outbid my claim; someone much nearer does
    e2 = {1: row(1, (0, 0), (Claim(a, v, MODEL.leg_time(100)),)), 2: row(2, (5, 0))}
    assert decide(GreedyPolicy(), 2, e2, board)[0].task == b
    e3 = {1: row(1, (0, 0), (Claim(a, v, MODEL.leg_time(100)),)), 2: row(2, (90, 0))}
    assert decide(GreedyPolicy(), 2, e3, board)[0].task == a
    # an ACTIVE claim is not outbid by a claim a little cheaper (the wider active margin)
    e4 = {1: row(1, (0, 0), (Claim(a, v, MODEL.leg_time(100), ClaimState.ACTIVE),)), 2: row(2, (25, 0))}
    assert decide(GreedyPolicy(), 2, e4, board)[0].task == b


def test_greedy_two_active_claims_settle_on_one_holder_from_each_ones_view() -> None:
    """Both flew a task (apart during a partition), each sees the other's cost a moment old: within the
    margin the lower id keeps it, from both views (each finding itself cheaper kept both on it for ever)."""
    led, (a,) = visits((100, 0))
    board = led.board()
    v = board.get(a).version

    def active(cost: float) -> tuple[Claim, ...]:
        return (Claim(a, v, cost, ClaimState.ACTIVE),)
    view1 = {1: row(1, (100, 0), active(0.30)), 2: row(2, (100, 1), active(0.40))}
    view2 = {1: row(1, (100, 0), active(0.50)), 2: row(2, (100, 1), active(0.35))}
    assert [c.task for c in decide(GreedyPolicy(), 1, view1, board)] == [a]
    assert [c.task for c in decide(GreedyPolicy(), 2, view2, board)] == []
    # the clearly cheaper keeps it, whatever the ids
    far = {1: row(1, (0, 0), active(30.0)), 2: row(2, (100, 1), active(0.4))}
    assert [c.task for c in decide(GreedyPolicy(), 1, far, board)] == []
    assert [c.task for c in decide(GreedyPolicy(), 2, far, board)] == [a]


def test_greedy_active_claim_yields_to_a_clearly_cheaper_one() -> None:
    """Seed 003 Sec. III-B: "when one UAV sees that the other could complete the task at a lower cost, it
    gives up the task", also once it flies it (ACTIVE): vehicle 1 flies to a, 400 m away; vehicle 2 is
    released next to a. 2 claims a, 1 yields and takes its next best; neither flaps back."""
    led, (a, b) = visits((400, 0), (-300, 0))
    board = led.board()
    v = board.get(a).version
    p1, p2 = GreedyPolicy(), GreedyPolicy()
    e = {1: row(1, (0, 0), (Claim(a, v, MODEL.leg_time(400), ClaimState.ACTIVE),)), 2: row(2, (390, 0))}
    (c2,) = decide(p2, 2, e, board)
    assert c2.task == a and c2.state is ClaimState.CLAIMED
    e[2] = dataclasses.replace(e[2], claims=(c2,))
    (c1,) = decide(p1, 1, e, board)
    assert c1.task == b and p1.conflicts == 1  # 1 gave a up for its next best
    e[1] = dataclasses.replace(e[1], claims=(c1,))
    assert decide(p2, 2, e, board)[0].task == a  # 2 keeps it
    final = settle({1: p1, 2: p2}, e, board)
    assert {m: [c.task for c in x.claims] for m, x in final.items()} == {1: [b], 2: [a]}


def policy_named(name: str) -> AllocationPolicy:
    """A fresh policy of one vehicle: seed 003's greedy rule, or CBBA with 3 tasks per vehicle."""
    return GreedyPolicy() if name == "greedy" else CbbaPolicy(MODEL, 3)


@pytest.mark.parametrize("policy", ["greedy", "cbba"])
def test_active_claim_does_not_flap_within_the_hysteresis(policy: str) -> None:
    """Two vehicles whose costs to a task differ by less than the active margin, in turn a little nearer
    than the other: the one flying it keeps it through every decision, the other never claims it."""
    led, (a,) = visits((200, 0))
    board = led.board()
    v = board.get(a).version

    p1, p2 = policy_named(policy), policy_named(policy)
    holder = (Claim(a, v, MODEL.leg_time(100), ClaimState.ACTIVE),)
    for k in range(20):
        d1 = 100.0 - 2 * k  # vehicle 1 approaches; vehicle 2 is alternately a little nearer and farther
        d2 = d1 - 12.0 if k % 2 else d1 + 12.0
        e = {1: row(1, (200 - d1, 0), holder), 2: row(2, (200 - d2, 10))}
        claims2 = decide(p2, 2, e, board)
        assert a not in [c.task for c in claims2], (k, claims2)
        holder = decide(p1, 1, e, board)
        assert [c.task for c in holder] == [a] and holder[0].state is ClaimState.ACTIVE, (k, holder)
    assert p1.conflicts == p2.conflicts == 0


def test_cbba_active_claim_yields_to_a_clearly_cheaper_one() -> None:
    led, (a, _b) = visits((400, 0), (-300, 0))
    board = led.board()
    v = board.get(a).version
    p1, p2 = CbbaPolicy(MODEL, 3), CbbaPolicy(MODEL, 3)
    e = {1: row(1, (0, 0), (Claim(a, v, MODEL.leg_time(400), ClaimState.ACTIVE),)), 2: row(2, (390, 0))}
    c2 = decide(p2, 2, e, board)
    assert a in [c.task for c in c2]
    e[2] = dataclasses.replace(e[2], claims=c2)
    c1 = decide(p1, 1, e, board)
    assert a not in [c.task for c in c1] and p1.conflicts == 1


@pytest.mark.parametrize("policy", ["greedy", "cbba"])
def test_two_vehicles_flying_one_task_side_by_side_one_lets_go(policy: str) -> None:
    """Two vehicles that started flying one visit at once, side by side (costs 0.6 s apart), each deciding
    on the other's row of a period before: both approach, so each one's fresh cost is below the other's
    published one. Exactly one lets go at the first decision (the published costs are compared; within the
    tie band the lower id keeps it), not both flying it to the end (the bench's 33 s held twice)."""
    led, (a,) = visits((200, 0))
    board = led.board()
    v = board.get(a).version

    p1, p2 = policy_named(policy), policy_named(policy)
    c1 = (Claim(a, v, MODEL.leg_time(100.0) + 0.6, ClaimState.ACTIVE),)  # published a period ago
    c2 = (Claim(a, v, MODEL.leg_time(100.0), ClaimState.ACTIVE),)
    e = {1: row(1, (200 - 97.0, 3), c1), 2: row(2, (200 - 97.0, -3), c2)}  # both 3 m nearer now
    k1, k2 = decide(p1, 1, e, board), decide(p2, 2, e, board)
    holders = [m for m, k in ((1, k1), (2, k2)) if a in [c.task for c in k]]
    assert holders == [1], (k1, k2)
    # vehicle 2, clearly nearer, takes it from vehicle 1 (and 1 lets go)
    e = {1: row(1, (0, 0), (Claim(a, v, MODEL.leg_time(200.0), ClaimState.ACTIVE),)),
         2: row(2, (150, 0), (Claim(a, v, MODEL.leg_time(50.0), ClaimState.ACTIVE),))}
    k1, k2 = decide(policy_named(policy), 1, e, board), decide(policy_named(policy), 2, e, board)
    assert a not in [c.task for c in k1] and a in [c.task for c in k2]


@pytest.mark.parametrize("policy", ["greedy", "cbba"])
def test_a_challenger_reading_an_older_row_of_the_holder_does_not_claim_what_the_holder_keeps(
        policy: str) -> None:
    """The holder flies its task (its cost falls half a second a period); a challenger reads the holder's
    row a period old (42.3) and bids 31.7, just clearly cheaper than that, not than the holder's own 41.8.
    Without the drift allowance the challenger claimed it while the holder kept it (and dropped and
    re-claimed it every decision: bench_allocation's seed 20 held one visit twice for 4.5 s)."""
    led, (a,) = visits((200, 0))
    board = led.board()
    v = board.get(a).version

    seen = {2: row(2, (0, 0), (Claim(a, v, 42.3, ClaimState.ACTIVE),)), 3: row(3, (50, 0))}
    challenger = policy_named(policy).decide(3, seen, board, lambda t: 31.7, ())
    now = {2: row(2, (0, 0), (Claim(a, v, 41.8, ClaimState.ACTIVE),)), 3: row(3, (50, 0), challenger)}
    holder = policy_named(policy).decide(2, now, board, lambda t: 41.3, now[2].claims)
    holders = [m for m, k in ((2, holder), (3, challenger)) if a in [c.task for c in k]]
    assert holders == [2], (holder, challenger)
    # clearly cheaper than the holder's cost less the allowance: taken, and the holder lets go
    challenger = policy_named(policy).decide(3, seen, board, lambda t: 25.0, ())
    now[3] = dataclasses.replace(now[3], claims=challenger)
    holder = policy_named(policy).decide(2, now, board, lambda t: 41.3, now[2].claims)
    assert a in [c.task for c in challenger] and a not in [c.task for c in holder]


def test_an_active_holder_that_reached_its_task_is_not_outbid() -> None:
    """A patrol being flown: its holder is on it (its cost fell below REACHED, then 0 for good), so a
    vehicle loitering at the line's end does not take it over even though its way to the end is shorter."""
    led = TaskLedger()
    p = led.add(TaskDef("patrol_line", (geo(0, 0), geo(0, 300))))[0]
    board = led.board()
    v = board.get(p).version
    pol = GreedyPolicy()
    e = {1: row(1, (0, 1), (Claim(p, v, 3.0, ClaimState.ACTIVE),))}
    (c,) = decide(pol, 1, e, board)
    assert c.cost == 0.0  # reached: from now on 0
    e = {1: row(1, (0, 150), (c,)), 2: row(2, (0, 305))}  # mid-line now, 150 m from either end
    (c,) = decide(pol, 1, e, board)
    assert c.cost == 0.0
    e[1] = dataclasses.replace(e[1], claims=(c,))
    assert decide(GreedyPolicy(), 2, e, board) == ()


def test_unavailable_members_do_not_compete() -> None:
    led, (a,) = visits((100, 0))
    board = led.board()
    v = board.get(a).version
    e = {1: row(1, (0, 0)), 2: row(2, (99, 0), (Claim(a, v, 0.5, ClaimState.ACTIVE),), MemberStatus.TAKEN)}
    assert decide(GreedyPolicy(), 1, e, board)[0].task == a


def random_case(seed: int, n: int, m: int) -> tuple[TaskLedger, dict[int, MemberEntry]]:
    rng = random.Random(seed)
    led = TaskLedger()
    for _ in range(m):
        led.add(TaskDef("visit", (geo(rng.uniform(-1000, 1000), rng.uniform(-1000, 1000)),)))
    entries = {i: row(i, (rng.uniform(-1000, 1000), rng.uniform(-1000, 1000))) for i in range(1, n + 1)}
    return led, entries


@pytest.mark.parametrize("seed", range(10))
def test_greedy_steady_state_holds_no_task_twice(seed: int) -> None:
    led, entries = random_case(seed, 5, 7)
    pols = {m: GreedyPolicy() for m in entries}
    final = settle(pols, entries, led.board())
    h = held(final)
    assert all(len(ms) == 1 for ms in h.values())
    assert all(len(e.claims) == 1 for e in final.values())  # 7 tasks, 5 vehicles: every one busy


@pytest.mark.parametrize("seed", range(10))
def test_cbba_steady_state_holds_no_task_twice_and_covers_all(seed: int) -> None:
    led, entries = random_case(seed, 3, 7)
    pols = {m: CbbaPolicy(MODEL, max_tasks=3) for m in entries}
    final = settle(pols, entries, led.board())
    h = held(final)
    assert all(len(ms) == 1 for ms in h.values())
    assert len(h) == 7  # 3 x 3 slots for 7 tasks: all taken


def test_cbba_release_drops_the_outbid_task_and_those_added_after_it() -> None:
    led, (a, b, c) = visits((100, 0), (200, 0), (300, 0))
    board = led.board()
    v = board.get(a).version
    pol = CbbaPolicy(MODEL, max_tasks=3)
    e = {1: row(1, (0, 0))}
    bundle = decide(pol, 1, e, board)
    assert [x.task for x in bundle] == [a, b, c]
    bids = [x.cost for x in bundle]
    assert bids == sorted(bids)  # warped: each bid at least the previous one
    # member 2 sits on b and bids lower: I lose b and c (added after it), keep a
    e = {1: row(1, (0, 0), bundle), 2: row(2, (200, 0), (Claim(b, v, 0.1),))}
    mine = decide(pol, 1, e, board)
    assert mine[0].task == a and b not in [x.task for x in mine] and pol.conflicts == 1
    # c is free again and I may re-add it with a new bid
    assert [x.task for x in mine] == [a, c]
    # the path I fly goes a then c
    assert pol.order(1, e, board, costfn(e[1]), mine) == (a, c)


def test_cbba_consensus_two_members_split_a_line() -> None:
    led, ids = visits((-300, 0), (-200, 0), (-100, 0), (100, 0), (200, 0), (300, 0))
    e = {1: row(1, (-50, 0)), 2: row(2, (50, 0))}
    final = settle({1: CbbaPolicy(MODEL, 3), 2: CbbaPolicy(MODEL, 3)}, e, led.board())
    assert {c.task for c in final[1].claims} == set(ids[:3])
    assert {c.task for c in final[2].claims} == set(ids[3:])


def test_cbba_patrol_only_last_and_active_first() -> None:
    led = TaskLedger()
    p = led.add(TaskDef("patrol_line", (geo(50, 0), geo(50, 300))))[0]
    a = led.add(TaskDef("visit", (geo(400, 0),)))[0]
    q = led.add(TaskDef("patrol_line", (geo(-50, 0), geo(-50, 300))))[0]
    board = led.board()
    pol = CbbaPolicy(MODEL, max_tasks=3)
    e = {1: row(1, (0, 0))}
    bundle = decide(pol, 1, e, board)
    tasks = [x.task for x in bundle]
    assert a in tasks and not (p in tasks and q in tasks)  # one endless patrol at most
    order = pol.order(1, e, board, costfn(e[1]), bundle)
    assert order[-1] in (p, q)
    v = board.get(a).version
    active = (Claim(a, v, 50.0, ClaimState.ACTIVE),)
    assert pol.order(1, e, board, costfn(e[1]), (*active, Claim(p, v, 60.0)))[0] == a


@pytest.mark.parametrize("kind", ["patrol_line", "border_patrol", "area_scan"])
def test_a_task_speed_and_altitude_are_flown_and_bid_with(kind: str) -> None:
    """What the API accepts is flown: the tree a vehicle flies for the task has the task's speed (and an
    area's altitude), and its bid is the flight time at that speed (faster than the standard one too)."""
    platform = load_platform(PLATFORM)
    speed = platform.speeds["standard"] * 1.5  # between standard and fast: no speed name says it
    pts = ((geo(0, 0, 12), geo(0, 40, 12), geo(30, 40, 12)) if kind != "area_scan"
           else (geo(0, 0), geo(0, 40), geo(40, 40), geo(40, 0)))
    led = TaskLedger()
    led.add(TaskDef(kind, pts, n=1, speed=speed, altitude=14.0 if kind == "area_scan" else 0.0))
    (task,) = led.board().tasks
    result = delegate(mission_for(task, False, 10.0), platform)
    assert result.accepted, result.reasons
    plans = list(result.plans.values())
    assert plans and all(p.speed_m_s == pytest.approx(speed) for p in plans)
    if kind == "area_scan":
        assert all(p.altitude_m == pytest.approx(14.0) for p in plans)
    model = CostModel(speed=platform.speeds["standard"])
    at = geo(-200, 0)
    assert model.cost(at, task) < model.cost(at, dataclasses.replace(task, speed=0.0))  # faster: cheaper
    assert model.cost(at, task) == pytest.approx(model.travel_time(at, entry_point(task, at), speed))
