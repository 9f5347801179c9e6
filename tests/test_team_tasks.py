"""Team tasks (seed 003 Sec. II): division of border and area, offer of a smaller N, the ledger's state
machine, derived states, the cost model and bad input."""

from __future__ import annotations

import itertools
import math

import pytest
from shapely.geometry import Polygon
from shapely.ops import unary_union

from companion.team.cost import CostModel, entry_point, euclidean
from companion.team.geometry import LocalFrame, split_polygon_equal_area
from companion.team.tasks import (
    Fence,
    TaskDef,
    TaskLedger,
    TransitionError,
    derive_states,
    divide,
    offer_smaller_n,
)
from companion.team.types import (
    Claim,
    ClaimState,
    MemberEntry,
    MemberStatus,
    TaskKind,
    TaskState,
    TeamTask,
)

HOME = (-35.363261, 149.165230)
FRAME = LocalFrame(*HOME)


def geo(x: float, y: float, z: float = 20.0) -> tuple[float, float, float]:
    return FRAME.to_geo(x, y, z)


BORDER = (geo(0, 0), geo(300, 400), geo(300, 900), geo(-200, 1100))
AREA = (geo(0, 0), geo(400, 0), geo(500, 250), geo(100, 300))


@pytest.mark.parametrize("n", [1, 2, 3, 5])
def test_border_divided_into_equal_lengths_end_to_end(n: int) -> None:
    tasks = divide(TaskDef("border_patrol", BORDER, n=n), iter(range(1, 100)), group=50)
    assert len(tasks) == n
    lengths = [FRAME.line(t.points).length for t in tasks]
    total = FRAME.line(BORDER).length
    assert sum(lengths) == pytest.approx(total, rel=1e-6)
    assert max(lengths) - min(lengths) < 1e-3 * total
    for t in tasks:
        assert t.kind is TaskKind.BORDER_PIECE and t.group == 50 and t.group_size == n
    # the pieces join end to end and cover the border's ends
    ends = [(FRAME.to_local(t.points[0])[:2], FRAME.to_local(t.points[-1])[:2]) for t in tasks]
    assert math.dist(ends[0][0], (0, 0)) < 0.01 and math.dist(ends[-1][1], (-200, 1100)) < 0.01
    for (_, b), (a, _) in itertools.pairwise(ends):
        assert math.dist(a, b) < 0.01


@pytest.mark.parametrize("n", [2, 3, 4])
def test_area_divided_into_equal_areas_covering_it(n: int) -> None:
    tasks = divide(TaskDef("area_scan", AREA, n=n, altitude=30), iter(range(1, 100)), group=7)
    polys = [FRAME.polygon(t.points) for t in tasks]
    whole = FRAME.polygon(AREA)
    for p in polys:
        assert p.is_valid and p.exterior.is_simple
        assert abs(p.area - whole.area / n) < 0.01 * whole.area / n
    union = unary_union(polys)
    assert union.symmetric_difference(whole).area < 1e-3 * whole.area
    assert sum(p.area for p in polys) == pytest.approx(whole.area, rel=1e-3)  # no overlap
    assert all(t.kind is TaskKind.AREA_PART and t.altitude == 30 and t.points[0][2] == 30 for t in tasks)


def test_concave_area_that_falls_apart_is_rejected() -> None:
    u_shape = Polygon([(0, 0), (300, 0), (300, 300), (200, 300), (200, 100), (100, 100), (100, 300),
                       (0, 300)])
    with pytest.raises(ValueError, match="not one simple polygon"):
        split_polygon_equal_area(u_shape, 2)


def test_offer_smaller_n() -> None:
    assert offer_smaller_n(3, 3) is None
    assert offer_smaller_n(2, 5) is None
    assert offer_smaller_n(4, 2) == 2
    assert offer_smaller_n(3, 0) == 1
    assert offer_smaller_n(1, 0) is None  # the offer of 1 with no vehicle free is accepted (it waits)
    with pytest.raises(ValueError, match="requested"):
        offer_smaller_n(0, 2)


def test_ledger_redivides_on_a_smaller_n() -> None:
    led = TaskLedger()
    ids = led.add(TaskDef("border_patrol", BORDER, n=4))
    group = led.task(ids[0]).group
    new = led.redivide(group, offer_smaller_n(4, 2))
    assert len(new) == 2 and all(led.state(i) is TaskState.CANCELLED for i in ids)
    assert all(led.task(i).group == group and led.task(i).group_size == 2 for i in new)
    assert {t.id for t in led.board().live()} == set(new)


def test_state_machine_and_illegal_transitions() -> None:
    led = TaskLedger()
    (tid,) = led.add(TaskDef("visit", (geo(10, 10),)))
    assert led.state(tid) is TaskState.UNASSIGNED
    with pytest.raises(TransitionError, match="unassigned -> active"):
        led.transition(tid, TaskState.ACTIVE, 1)
    with pytest.raises(TransitionError, match="unassigned -> done"):
        led.transition(tid, TaskState.DONE, 1)
    led.assign(tid, 1)
    led.assign(tid, 2)  # a new holder
    assert led.holder(tid) == 2
    led.transition(tid, TaskState.ACTIVE, 2)
    led.transition(tid, TaskState.UNASSIGNED)  # the holder is gone
    assert led.holder(tid) is None
    led.assign(tid, 3)
    led.transition(tid, TaskState.ACTIVE, 3)
    v = led.task(tid).version
    led.transition(tid, TaskState.DONE, 3)
    assert led.task(tid).state is TaskState.DONE and led.task(tid).version == v + 1
    for to in TaskState:
        with pytest.raises(TransitionError, match="illegal transition done"):
            led.transition(tid, to, 1)
    (other,) = led.add(TaskDef("visit", (geo(20, 10),)))
    led.cancel(other)
    with pytest.raises(TransitionError, match="cancelled -> cancelled"):
        led.cancel(other)


def test_board_seq_advances_and_cancel_of_a_group() -> None:
    led = TaskLedger()
    s0 = led.board(1.0).seq
    ids = led.add(TaskDef("area_scan", AREA, n=2), now=2.0)
    b1 = led.board()
    assert b1.seq > s0 and b1.stamp == 2.0 and len(b1.live()) == 2
    assert led.cancel(ids[0] - 1, now=3.0) == ids  # the group id cancels its pieces
    b2 = led.board()
    assert b2.newer_than(b1) and not b2.live()


def _entry(member: int, claims: tuple[Claim, ...], status: MemberStatus = MemberStatus.BUSY) -> MemberEntry:
    return MemberEntry(member=member, stamp=1.0, seq=1, status=status, claims=claims, voc=5)


def test_derive_states_and_apply() -> None:
    led = TaskLedger()
    a, b, c, d = (led.add(TaskDef("visit", (geo(10 * i, 0),)))[0] for i in range(4))
    board = led.board()
    v = board.get(a).version
    entries = {
        1: _entry(1, (Claim(a, v, 30.0),)),
        2: _entry(2, (Claim(a, v, 20.0), Claim(b, v, 5.0, ClaimState.ACTIVE))),
        3: _entry(3, (Claim(c, v, 1.0, ClaimState.DONE),)),
        4: _entry(4, (Claim(d, v, 1.0),), MemberStatus.TAKEN),  # taken out of the team: not counted
        5: _entry(5, (Claim(b, v + 7, 1.0),)),  # another version: ignored
    }
    st = derive_states(board, entries)
    assert st[a][:2] == (TaskState.ASSIGNED, 2) and st[a][2] == 20.0
    assert st[b][:2] == (TaskState.ACTIVE, 2)
    assert st[c][:2] == (TaskState.DONE, 3)
    assert st[d][:2] == (TaskState.UNASSIGNED, None)
    changes = led.apply(st, now=5.0)
    assert {(i, s) for i, s, _ in changes} == {(a, TaskState.ASSIGNED), (b, TaskState.ACTIVE),
                                               (c, TaskState.DONE)}
    assert led.board().get(c).state is TaskState.DONE and led.holder(b) == 2


def test_tst_with_a_c_root_gives_one_task_per_child() -> None:
    tree = {"type": "C", "children": [
        {"type": "fly-to", "params": {"position": [*geo(50, 50)[:2], 10.0]}},
        {"type": "scan-ground", "params": {"area": [list(geo(0, 0)[:2]), list(geo(60, 0)[:2]),
                                                     list(geo(30, 60)[:2])]}}]}
    led = TaskLedger()
    ids = led.add(TaskDef("tst", tree=tree, name="pair"))
    assert len(ids) == 2
    t = led.task(ids[0])
    assert t.kind is TaskKind.TST and t.group == ids[0] - 1 and t.group_size == 2 and '"fly-to"' in t.tst
    assert t.points[0][:2] == pytest.approx(geo(50, 50)[:2])


@pytest.mark.parametrize(("defn", "field"), [
    (TaskDef("border_patrol", BORDER, n=0), "n:"),
    (TaskDef("border_patrol", BORDER, n=-2), "n:"),
    (TaskDef("border_patrol", (geo(0, 0), geo(30, 0)), n=5), "n:"),
    (TaskDef("area_scan", AREA, n=10_000), "n:"),
    (TaskDef("patrol_line", (geo(0, 0),)), "points:"),
    (TaskDef("visit", ()), "points:"),
    (TaskDef("area_scan", (geo(0, 0), geo(100, 0))), "points:"),
    (TaskDef("area_scan", (geo(0, 0), geo(300, 100), geo(300, 0), geo(0, 200)), n=2), "not simple"),
    (TaskDef("area_scan", (geo(0, 0), geo(100, 0), geo(200, 0))), "zero area"),
    (TaskDef("visit", ((91.0, 0.0),)), "points\\[0\\]"),
    (TaskDef("visit", ((float("nan"), 0.0),)), "points\\[0\\]"),
    (TaskDef("scan", (geo(0, 0),)), "kind:"),
    (TaskDef("visit", (geo(0, 0),), speed=-1), "speed:"),
    (TaskDef("tst", tree={"type": "no-such-task"}), "type"),
])
def test_bad_input_is_rejected_and_changes_nothing(defn: TaskDef, field: str) -> None:
    led = TaskLedger()
    led.add(TaskDef("visit", (geo(1, 1),)))
    before = led.board()
    with pytest.raises(ValueError, match=field):
        led.add(defn)
    assert led.board() == before


def test_a_task_outside_the_fence_is_rejected() -> None:
    fence_local = Fence(Polygon([(-500, -500), (500, -500), (500, 500), (-500, 500)]), FRAME)
    lat = [geo(-500, -500), geo(500, 500)]
    fence_geo = Fence(Polygon([(lat[0][0], lat[0][1]), (lat[0][0], lat[1][1]), (lat[1][0], lat[1][1]),
                               (lat[1][0], lat[0][1])]))
    for fence in (fence_local, fence_geo):
        led = TaskLedger(fence=fence)
        led.add(TaskDef("visit", (geo(400, 400),)))
        before = led.board()
        with pytest.raises(ValueError, match=r"points\[1\]: .* outside the fence"):
            led.add(TaskDef("patrol_line", (geo(0, 0), geo(0, 600))))
        assert led.board() == before


def test_cost_is_flight_time_and_euclidean_its_lower_bound() -> None:
    m = CostModel(speed=5.0, accel=2.0, climb_speed=2.0)
    # trapezoid: 100 m at 5 m/s, 2 m/s^2 -> 100/5 + 5/2; triangle: 4 m -> 2 sqrt(4/2)
    assert m.leg_time(100.0) == pytest.approx(22.5)
    assert m.leg_time(4.0) == pytest.approx(2 * math.sqrt(2.0))
    assert m.leg_time(12.5) == pytest.approx(2 * math.sqrt(12.5 / 2.0))  # continuous at d = v^2/a
    assert m.leg_time(0.0, 10.0) == pytest.approx(5.0)
    import random

    rng = random.Random(3)
    for _ in range(200):
        at = geo(rng.uniform(-800, 800), rng.uniform(-800, 800), rng.uniform(0, 60))
        t = TeamTask(id=1, version=1, kind=TaskKind.VISIT, points=(geo(rng.uniform(-800, 800),
                                                                       rng.uniform(-800, 800),
                                                                       rng.uniform(0, 60)),))
        assert max(m.speed, m.climb_speed) * m.cost(at, t) >= euclidean(at, t) - 1e-6


def test_characteristic_points() -> None:
    line = TeamTask(1, 1, TaskKind.PATROL_LINE, (geo(0, 0), geo(0, 500)))
    assert entry_point(line, geo(10, 480))[:2] == pytest.approx(geo(0, 500)[:2])
    assert entry_point(line, geo(10, 20))[:2] == pytest.approx(geo(0, 0)[:2])
    part = TeamTask(2, 1, TaskKind.AREA_PART, (geo(0, 0), geo(100, 0), geo(100, 100), geo(0, 100)))
    x, y, _ = FRAME.to_local(entry_point(part, geo(50, -70)))
    assert (x, y) == pytest.approx((50, 0), abs=0.05)
    x, y, _ = FRAME.to_local(entry_point(part, geo(50, 50)))  # inside: here
    assert (x, y) == pytest.approx((50, 50), abs=0.05)


@pytest.mark.parametrize(("kind", "points", "n"), [
    ("patrol_line", ((0, 0), (20, 10)), 1),
    ("patrol_line", ((0, 0), (20, 10), (40, 0)), 1),          # a three-point line drawn on the map
    ("patrol_line", ((0, 0), (20, 10), (40, 0), (40, 30)), 1),
    ("border_patrol", ((0, 0), (20, 10), (40, 0)), 1),         # the offer of one vehicle: the whole border
    ("border_patrol", ((0, 0), (20, 10), (40, 0)), 2),
    ("border_patrol", ((0, 0), (20, 10), (40, 0), (40, 30), (10, 30)), 3),
])
def test_every_patrol_line_and_border_piece_is_a_tree_the_platform_accepts(kind: str, points: tuple,
                                                                           n: int) -> None:
    """Whatever its number of points, a line's tree flies its waypoints in the order drawn: all of them
    (CI once saw a one-vehicle border of three points refused by every vehicle's delegation: the tree
    asked for scan segments, which need pairs)."""
    from companion.team.task_tst import mission_for
    from companion.tst.delegation import delegate
    from companion.tst.platform import bundled_platform

    platform = bundled_platform("outdoor")
    pts = tuple(geo(x, y, 6.0) for x, y in points)
    defn = TaskDef(kind, pts, n=n) if kind == "border_patrol" else TaskDef(kind, pts)
    tasks = divide(defn, iter(range(1, 100)), group=50 if kind == "border_patrol" else 0)
    assert len(tasks) == n
    for task in tasks:
        result = delegate(mission_for(task, False, 6.0), platform)
        assert result.accepted, result.reasons
        (plan,) = [p for p in result.plans.values() if p.task == "scan-ground"]
        flown = [(p[0], p[1]) for p in plan.waypoints_neu]  # (north, east, up): the frame's (x, y)
        drawn = [FRAME.to_local(p)[:2] for p in task.points]
        assert len(flown) == len(drawn)
        assert all(math.dist(a, b) < 0.05 for a, b in zip(flown, drawn, strict=True)), (flown, drawn)


def test_the_kind_registry_names_each_kind_once_and_checks_directed_tasks() -> None:
    from companion.team import kinds
    from companion.team.kinds.visit import Visit
    from companion.team.types import TaskKind

    assert kinds.names() == ("visit", "patrol_line", "border_patrol", "area_scan", "tst")
    assert kinds.for_task(TaskKind.BORDER_PIECE) is kinds.by_name("border_patrol")
    assert kinds.divided_by_n("area_scan") and not kinds.divided_by_n("visit")
    assert not kinds.divided_by_n("nonsense")
    assert sorted(kinds.wire_codes().values()) == [0, 1, 2, 3, 4]
    with pytest.raises(ValueError, match="registered already"):
        kinds.register(Visit())
    with pytest.raises(ValueError, match="kind: must be one of visit, patrol_line"):
        kinds.by_name("orbit")
    kinds.check_directed(TaskKind.VISIT, 1)
    with pytest.raises(ValueError, match="points: a area_part task needs at least 3 points"):
        kinds.check_directed(TaskKind.AREA_PART, 2)
    with pytest.raises(ValueError, match="kind: give a tree through POST /mission"):
        kinds.check_directed(TaskKind.TST, 1)
