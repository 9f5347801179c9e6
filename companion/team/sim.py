"""The team simulator: distributed allocation with kinematic vehicles in one process on simulated time.

``taskflight team sim``: N point-mass vehicles (speed, acceleration and climb limits)
and a team-control station, each with its own :class:`~companion.team.groupstate.GroupState` and
:class:`~companion.team.link.TeamLink` over one :class:`~companion.team.transport.MemoryBus` behind a
:class:`~companion.team.transport.LossyTransport` (the real flooding, voc and wire format of seed 003
Sec. III-A). Every period each vehicle runs the flying member's decision step (Sec. III-B,
:class:`~companion.team.decision.DecisionStep`) on its own view and flies what it holds (the route its
kind gives, :mod:`companion.team.kinds`): a visit is done on arrival, a patrol (line or border piece)
is flown back and forth until cancelled, an area part is done after flying its scan length at scan
speed, a TST task visits its points in order. Positions are local metres north, east and up of the
script's home (``starts``). Every step samples the true claims for tasks held by two vehicles at once
(a conflict, Sec. III-B, until one lets go): :attr:`SimResult.held_twice_s` is over the whole run, not
only its end. The station adds and cancels the scripted tasks at their times, follows the rows
(:func:`~companion.team.tasks.derive_states`) and publishes the board. Nothing sleeps: time is a number.
"""

from __future__ import annotations

import logging
import math
import random
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from companion.flight.simulate import PointMass, Vec3
from companion.team import kinds
from companion.team.allocation import make_policy
from companion.team.cost import CostModel, endless
from companion.team.decision import DecisionStep
from companion.team.geometry import LocalFrame
from companion.team.groupstate import GroupState
from companion.team.kinds.base import with_altitude
from companion.team.link import TeamLink
from companion.team.station import TeamControlStation
from companion.team.taskfile import TaskScript
from companion.team.transport import LossyTransport, MemoryBus
from companion.team.types import (
    Claim,
    ClaimState,
    GeoPoint,
    MemberEntry,
    MemberStatus,
    TaskBoard,
    TaskState,
    TeamTask,
)

log = logging.getLogger(__name__)

#: a vehicle is at a point when nearer than this (m)
ARRIVE_M = 2.0


@dataclass
class Work:
    """What a vehicle does on the task it flies: the waypoints left (local NED m) and the metres to fly."""

    task: TeamTask
    waypoints: list[Vec3]
    loop: list[Vec3] | None = None   #: a patrol's points, flown back and forth (an area's ring)
    scan_left: float = 0.0           #: an area part: metres still to scan


class SimVehicle:
    """One kinematic vehicle (:class:`~companion.flight.simulate.PointMass`) with its own group state, link
    and the flying member's decision step (:class:`~companion.team.decision.DecisionStep`)."""

    def __init__(self, member: int, pos: Vec3, sim: TeamSim) -> None:
        self.member = member
        m = sim.model
        self.body = PointMass(pos, speed=m.speed, accel=m.accel, climb_speed=m.climb_speed)
        self.sim = sim
        self.state = GroupState(member, voc_max=sim.voc_max)
        inner = sim.bus.attach()
        self.transport = LossyTransport(inner, sim.loss, seed=sim.rng.randrange(1 << 30))
        self.link = TeamLink(self.state, self.transport, period_s=sim.period_s, clock=lambda: sim.now,
                             own=self._own)
        self.policy = make_policy(sim.policy_name, sim.model, sim.max_tasks)
        self.decision = DecisionStep(member, self.policy, sim.model.cost, clock=lambda: sim.now)
        self.work: Work | None = None
        self.alive = True
        self.flown_m = 0.0      #: horizontal metres flown (toward tasks later lost too)
        self.moving_s = 0.0     #: simulated seconds spent moving

    @property
    def claims(self) -> tuple[Claim, ...]:
        return self.decision.claims

    def geo(self) -> GeoPoint:
        n, e, d = self.body.p
        return self.sim.frame.to_geo(n, e, -d)

    def _own(self) -> MemberEntry:
        busy = any(c.state in (ClaimState.CLAIMED, ClaimState.ACTIVE) for c in self.claims)
        v = self.body.v
        return MemberEntry(member=self.member, stamp=0.0, seq=0, position=self.geo(),
                           velocity=(float(v[0]), float(v[1]), float(v[2])),
                           status=MemberStatus.BUSY if busy else MemberStatus.IDLE,
                           task=self.work.task.id if self.work else 0, claims=self.claims,
                           name=f"v{self.member}")

    # --- decision -------------------------------------------------------------------------------
    def decide(self) -> None:
        board = self.state.board
        rows = {m: e for m, e in self.state.alive().items() if m != self.member}
        flying = self.work.task.id if self.work is not None else None
        choice = self.decision.step(self.sim.now, self.geo(), board, rows, self._own, flying)
        nxt = choice.task
        if self.work is not None and (nxt is None or self.work.task.id != nxt.id):
            self.work = None  # dropped, lost or cancelled: the next one (or loiter)
        if nxt is not None and self.work is None and choice.settled:
            self.work = self._plan(nxt)

    def _local(self, p: GeoPoint) -> Vec3:
        n, e, up = self.sim.frame.to_local(p)
        return (n, e, -up)

    def _plan(self, t: TeamTask) -> Work:
        self.body.speed = t.speed if t.speed > 0 else self.sim.model.speed  # the task's speed, as bid
        route = kinds.for_task(t.kind).route(t, self.geo())
        loop = [self._local(p) for p in route.loop] if route.loop is not None else None
        return Work(t, [self._local(p) for p in route.waypoints], loop=loop, scan_left=route.scan_m)

    def _finish(self, w: Work) -> None:
        self.decision.finished(w.task)
        self.sim.finish(w.task.id, self.member)
        self.work = None

    # --- flight ---------------------------------------------------------------------------------
    def fly(self, dt: float) -> None:
        if not self.alive:
            return
        w = self.work
        if w is None:
            self._count(self.body.fly_toward(self.body.p, dt), dt)  # loiter where it is (braking first)
            return
        target = w.waypoints[0] if w.waypoints else None
        if target is None and w.loop:
            target = w.loop[0]
        if target is None:
            return
        moved = self.body.fly_toward(target, dt)
        self._count(moved, dt)
        if w.scan_left > 0 and not w.waypoints:
            w.scan_left -= moved
            if w.scan_left <= 0:
                self._finish(w)
                return
        if math.dist(target, self.body.p) > ARRIVE_M:
            return
        if w.waypoints:
            w.waypoints.pop(0)
            if not w.waypoints:
                if w.loop is None:  # a visit or a TST's last point: done
                    self._finish(w)
                else:
                    self.sim.active_by.setdefault(w.task.id, self.member)
        elif w.loop:
            pt = w.loop.pop(0)
            if w.scan_left > 0:
                w.loop.append(pt)       # the scan goes round its part
            elif not w.loop:
                w.loop = self._reverse(w.task, pt)  # a patrol turns back at its end

    def _count(self, moved: float, dt: float) -> None:
        self.flown_m += moved
        if moved > 1e-6:
            self.moving_s += dt

    def _reverse(self, t: TeamTask, last: Vec3) -> list[Vec3]:
        pts = [self._local(with_altitude(t, p)) for p in t.points]
        if math.dist(pts[0], last) < math.dist(pts[-1], last):
            return pts[1:]
        return list(reversed(pts))[1:]


@dataclass
class SimResult:
    """What a run gave: the station's final view, the conflicts, and the timings."""

    tasks: dict[int, tuple[TeamTask, TaskState, int | None]]
    conflicts: int
    changes: list[tuple[float, int, str, int | None]]
    conflict_free_at: float | None
    duration: float
    done_by: dict[int, int] = field(default_factory=dict)
    held_twice_s: dict[int, float] = field(default_factory=dict)
    """Per task ever held by two or more vehicles at once (claimed or active, whatever the task's state on
    the board): the simulated seconds it was, summed over the whole run (every step sampled,
    :meth:`TeamSim.step`); its keys are the tasks held twice at some step."""
    held_twice_longest_s: float = 0.0
    """The longest stretch of simulated seconds any one task was held by two or more vehicles at once:
    how long a conflict (seed 003 Sec. III-B) lasted before one of them let the task go."""
    claims: dict[int, tuple[Claim, ...]] = field(default_factory=dict)


class TeamSim:
    """N vehicles and a station over a lossy in-memory bus (module doc)."""

    def __init__(self, script: TaskScript, vehicles: int, *, loss: float = 0.0, policy: str = "greedy",
                 seed: int = 0, period_s: float = 0.5, dt: float = 0.25, model: CostModel | None = None,
                 max_tasks: int = 3, voc_max: int = 10,
                 starts: list[tuple[float, float, float]] | None = None,
                 on_change: Callable[[float, int, TaskState, int | None], None] | None = None) -> None:
        if vehicles < 1:
            raise ValueError(f"vehicles: must be >= 1, got {vehicles}")
        if not 0.0 <= loss <= 1.0:
            raise ValueError(f"loss: must be in 0..1, got {loss}")
        self.script = script
        self.loss, self.policy_name, self.period_s, self.dt = loss, policy, period_s, dt
        self.model = model or CostModel()
        self.max_tasks, self.voc_max = max_tasks, voc_max
        make_policy(policy, self.model)  # a bad name fails here
        self.rng = random.Random(seed)
        self.now = 0.0
        home = script.home or (-35.363261, 149.165230)
        self.frame = LocalFrame(home[0], home[1])
        self.bus = MemoryBus(f"sim-{seed}-{id(self)}")
        st = LossyTransport(self.bus.attach(), loss, seed=self.rng.randrange(1 << 30))
        self.station = TeamControlStation(st, fence=script.fence, period_s=period_s, clock=lambda: self.now,
                                          voc_max=voc_max, position=(home[0], home[1], 0.0))
        self.station.listeners.append(self._on_station)
        self.ledger = self.station.ledger
        self.station_state = self.station.state
        self.station_link = self.station.link
        self.done_by: dict[int, int] = {}
        self.done_at: dict[int, float] = {}
        self.active_by: dict[int, int] = {}
        self.vehicles: list[SimVehicle] = []
        for i in range(vehicles):
            if starts is not None:
                n, e, up = starts[i]
            else:
                a = 2 * math.pi * i / vehicles
                n, e, up = 15.0 * math.sin(a), 15.0 * math.cos(a), 20.0
            pos = (float(n), float(e), -float(up))
            self.vehicles.append(SimVehicle(i + 1, pos, self))
        self._pending = sorted(script.tasks, key=lambda s: s.at)
        self._cancels: list[tuple[float, tuple[int, ...]]] = []
        self.changes: list[tuple[float, int, str, int | None]] = []
        self.on_change = on_change
        self._last_bad = 0.0
        self.held_twice_s: dict[int, float] = {}
        self.held_twice_longest_s = 0.0
        self._held_twice_since: dict[int, float] = {}
        self._next_decide = {v.member: self.rng.uniform(0, period_s) for v in self.vehicles}

    # --- the station ------------------------------------------------------------------------------
    def _station(self) -> None:
        while self._pending and self._pending[0].at <= self.now:
            item = self._pending.pop(0)
            ids = self.station.add(item.defn, force=True).ids
            if item.cancel_at is not None:
                self._cancels.append((item.cancel_at, ids))
        for entry in [c for c in self._cancels if c[0] <= self.now]:
            self._cancels.remove(entry)
            for i in entry[1]:
                if not self.ledger.state(i).final:
                    self.station.cancel(i)
        self.station.step()

    def finish(self, task: int, member: int) -> None:
        """A vehicle reports ``task`` done (the first report counts)."""
        if task not in self.done_by:
            self.done_by[task] = member
            self.done_at[task] = self.now

    def _on_station(self, entry: dict[str, Any]) -> None:
        if entry["event"] == "task":
            self._change(entry["task"], TaskState(entry["state"]), entry["holder"])
        elif entry["event"] == "cancelled":
            for i in entry["ids"]:
                self._change(i, TaskState.CANCELLED, None)

    def _change(self, tid: int, state: TaskState, holder: int | None) -> None:
        self.changes.append((self.now, tid, state.value, holder))
        if self.on_change is not None:
            self.on_change(self.now, tid, state, holder)

    # --- running ------------------------------------------------------------------------------------
    def conflict_free(self) -> bool:
        """No live task held by two vehicles, and no vehicle idle while a live task is unclaimed and it
        has room for it (the true claims, not a view)."""
        board = self.ledger.board()
        live_tasks = {t.id: t for t in board.live()}
        live = set(live_tasks)
        holders: dict[int, int] = {}
        for v in self.vehicles:
            for c in v.claims:
                if c.task in live and c.state is not ClaimState.FAILED:
                    holders[c.task] = holders.get(c.task, 0) + 1
        if any(n > 1 for n in holders.values()):
            return False
        free = live - set(holders)
        room = [v for v in self.vehicles if v.alive and len(
            [c for c in v.claims if c.task in live]) < (1 if self.policy_name == "greedy" else self.max_tasks)
            and not any(c.task in live and endless(live_tasks[c.task]) for c in v.claims)]
        return not (free and room)

    def held_twice(self) -> dict[int, int]:
        """Tasks held (claimed or active) by two or more living vehicles now (their true claims, done or
        cancelled tasks included: a vehicle still flying a task the board says is over holds it): how many."""
        count: dict[int, int] = {}
        for v in self.vehicles:
            if not v.alive:
                continue
            for c in v.claims:
                if c.state in (ClaimState.CLAIMED, ClaimState.ACTIVE):
                    count[c.task] = count.get(c.task, 0) + 1
        return {t: n for t, n in count.items() if n > 1}

    def _sample_held_twice(self) -> None:
        """Every step: add the step to each task held twice, and time each stretch of it."""
        twice = self.held_twice()
        for tid in twice:
            self.held_twice_s[tid] = self.held_twice_s.get(tid, 0.0) + self.dt
            since = self._held_twice_since.setdefault(tid, self.now - self.dt)
            self.held_twice_longest_s = max(self.held_twice_longest_s, self.now - since)
        for tid in [t for t in self._held_twice_since if t not in twice]:
            del self._held_twice_since[tid]

    def step(self) -> None:
        self.now += self.dt
        self._station()
        self.station_link.step(self.now)
        for v in self.vehicles:
            if not v.alive:
                continue
            v.fly(self.dt)
            if self.now >= self._next_decide[v.member]:
                self._next_decide[v.member] += self.period_s
                v.link.step(self.now)  # receive (and broadcast when a period has passed)
                v.decide()
        if not self.conflict_free():
            self._last_bad = self.now
        self._sample_held_twice()

    def run(self, duration: float, stop_when_done: bool = False) -> SimResult:
        while self.now < duration:
            self.step()
            if stop_when_done and self.finished():
                break
        return self.result()

    def finished(self) -> bool:
        """Every scripted task added, and every task done or cancelled."""
        return (not self._pending and not self._cancels and self.now > 1.0
                and all(self.ledger.state(i).final for i in self.ledger.ids()))

    def result(self) -> SimResult:
        led = self.ledger
        tasks = {i: (led.task(i), led.state(i), led.holder(i)) for i in led.ids()}
        return SimResult(tasks=tasks, conflicts=sum(v.policy.conflicts for v in self.vehicles),
                         changes=list(self.changes),
                         conflict_free_at=self._last_bad if self.conflict_free() else None,
                         duration=self.now, done_by=dict(self.done_by),
                         held_twice_s=dict(self.held_twice_s), held_twice_longest_s=self.held_twice_longest_s,
                         claims={v.member: v.claims for v in self.vehicles})

    def board(self) -> TaskBoard:
        return self.ledger.board()
