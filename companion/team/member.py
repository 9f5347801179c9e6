"""One vehicle's place in the team (seed 003 Sec. III): its row, its claims, its tier, its switchboard.

:class:`TeamMember` joins, on one companion,

* the team link (:mod:`companion.team.link`): the group state flooded over a lossy radio-like link, the
  vehicle's own row refreshed from the node's vehicle status (position, velocity), its status and its claims;
* the allocation policy (:mod:`companion.team.allocation`, greedy as in seed 003 Sec. III-B or CBBA),
  asked every decision period for the claims this vehicle makes given the task board and everyone's rows;
* the interface hierarchy of seed 003 Fig. 1: the team (broadcast tasks) < the process monitor (a directed
  command: :meth:`take`, :meth:`release`, :meth:`assign`) < the autopilot's own ground station (a mode
  change the node reports as ``overridden`` in its vehicle status). "A lower
  interface overrides a higher one": a taken or overridden vehicle publishes no claims and says so in its
  row, so the others re-allocate its task; released (or put back into GUIDED), it rejoins;
* the :class:`~companion.team.switchboard.Switchboard`, the one writer of which tree flies the vehicle.

A claim is flown once it has been held for ``settle_s`` (one broadcast period by default) without being
out-bid, so that most conflicts are declared and resolved before the vehicle turns (seed 003 Sec. V: "On
three occasions, conflicts were declared when two UAVs claimed the same task. These conflicts were
resolved"). A task whose tree succeeded is reported DONE in the row until the board says it is done; a task
whose tree failed (rejected by delegation, or failed in flight) is reported FAILED and not claimed again by
this vehicle for :data:`~companion.team.decision.RETRY_FAILED_S`. A vehicle bids only once it is
localized (seed 001's SELF_LOCALIZE active: ArduCopter's EKF takes tens of seconds after boot); a
vehicle that loses its localization while its tree flies a task keeps its claims (no new bids) until the
tree ends: the tree flies the task whatever the belief says, and a claim dropped would let another
vehicle take the task and both fly it.

Identity: a member whose link refuses to join (another member has used its id longer:
:mod:`companion.team.link`) publishes no claims and flies no team task; its report says
``team: refused: duplicate id N ...`` and its events a "refused" one.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from companion.node import VehicleStatus
from companion.tst.delegation import delegate
from companion.tst.status import ExecutionRequestError

from .decision import Choice, DecisionStep
from .groupstate import GroupState
from .link import DEFAULT_PERIOD_S, TeamLink, link_drops
from .switchboard import Controller, Switchboard
from .task_tst import mission_for
from .types import Claim, GeoPoint, MemberEntry, MemberStatus, TaskState, TeamTask

if TYPE_CHECKING:
    from companion.mission_service import MissionService

    from .allocation import AllocationPolicy
    from .transport import Transport

log = logging.getLogger(__name__)



class TeamMember:
    """See module docstring."""

    def __init__(self, missions: MissionService, transport: Transport, policy: AllocationPolicy,
                 cost: Callable[[GeoPoint, TeamTask], float], *, member_id: int, name: str = "",
                 period_s: float | None = None, decide_period_s: float = 0.25, settle_s: float | None = None,
                 voc_max: int | None = None, clock: Callable[[], float] = time.time,
                 key: bytes | None = None) -> None:
        self.missions = missions
        self.node = missions.node
        self.state = GroupState(member_id, **({} if voc_max is None else {"voc_max": voc_max}))
        self.link = TeamLink(self.state, transport, period_s=period_s or DEFAULT_PERIOD_S, clock=clock,
                             own=self.own_row, key=key)
        link = self.link
        self.policy = policy
        self.cost = cost
        self.id = member_id
        self.name = name or f"uav{member_id}"
        self.decide_period_s = decide_period_s
        self.settle_s = link.period_s if settle_s is None else settle_s
        self.clock = clock
        platform = missions.platform()
        self.switchboard = Switchboard(missions, float(platform.altitudes.get("standard", 10.0)))
        self.status = MemberStatus.IDLE
        self.taken_reason: str | None = None
        self.position: GeoPoint | None = None
        self.velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self.events: list[dict[str, Any]] = []
        self.decision = DecisionStep(member_id, policy, cost, clock=clock, settle_s=self.settle_s,
                                     acceptable=self._acceptable, on_event=self._event)
        self._verdicts: dict[tuple[int, int], str] = {}  # (task, version) -> "" (can) or why not
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self._wake = threading.Event()
        self._thread: threading.Thread | None = None
        self.link.listeners.append(self._on_link)

    # --- lifecycle ------------------------------------------------------------------------------------
    def start(self) -> TeamMember:
        self.link.start()
        self._thread = threading.Thread(target=self._loop, name=f"team-member-{self.id}", daemon=True)
        self._thread.start()
        return self

    def close(self) -> None:
        self._stop.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        self.link.close()

    def _loop(self) -> None:
        while not self._stop.is_set():
            self._wake.wait(self.decide_period_s)
            self._wake.clear()
            if self._stop.is_set():
                return
            try:
                before = self.claims
                self.step(self.clock())
                if [(c.task, c.state) for c in self.claims] != [(c.task, c.state) for c in before]:
                    self.link.announce()  # seed 003: "selects the task ... and then broadcasts its selection"
            except Exception:
                log.exception("team member %d: decision step failed", self.id)

    def _on_link(self, event: Any) -> None:
        """A new board or a member gone: decide now, not at the next decision period. A refusal to join
        (a duplicate id) or a duplicate heard is an event."""
        if event.kind == "refused":
            self._event("refused", reason=f"refused to join the team: {event.reason}")
        elif event.kind == "duplicate":
            self._event("duplicate", reason=f"duplicate id {event.member} heard from another member")
        if event.kind in ("board", "gone", "refused"):
            self._wake.set()

    # --- the interface hierarchy (process monitor tier) ----------------------------------------------------
    def take(self, reason: str = "process monitor") -> None:
        """Out of the team (a directed command): the team's tree is aborted, no claims are published."""
        with self._lock:
            self.taken_reason = reason
            self.switchboard.hand_to(Controller.DIRECTED)
            self._set_status(MemberStatus.TAKEN, reason)

    def safety_stop(self, reason: str) -> None:
        """The companion's safety monitor takes the vehicle (RTL or LAND as emergency): out of the team, its
        task given back (no claims published, so the others re-allocate it)."""
        self.take(f"safety monitor: {reason}")

    def release(self) -> None:
        """Back into the team: a directed tree still running is aborted, the team allocates again."""
        with self._lock:
            if self.taken_reason is None:
                return
            self.taken_reason = None
            if self.switchboard.controller is Controller.DIRECTED and self.missions.execution.running:
                self.missions.abort("released to the team", policy="hover")
            self.switchboard.hand_to(Controller.LOITER)
            self._set_status(MemberStatus.IDLE, "released")

    def assign(self, task: TeamTask) -> bool:
        """A directed task: the vehicle leaves the team and flies ``task`` (False if its tree is refused)."""
        with self._lock:
            self.take(f"directed task {task.id}")
            return self.switchboard.fly(task, self.node.vehicle_status().on_ground, Controller.DIRECTED)

    @property
    def claims(self) -> tuple[Claim, ...]:
        return self.decision.claims

    @property
    def done(self) -> dict[int, int]:
        return self.decision.done

    @property
    def failed(self) -> dict[int, str]:
        return self.decision.failed

    @property
    def taken(self) -> bool:
        return self.taken_reason is not None

    # --- the row -----------------------------------------------------------------------------------------
    def own_row(self) -> MemberEntry | None:
        """This vehicle's row as it is now (the link stamps and numbers it); None before a position."""
        with self._lock:
            if self.position is None:
                return None
            task = self.switchboard.task.id if self.switchboard.task is not None else 0
            return MemberEntry(member=self.id, stamp=0.0, seq=0, position=self.position,
                               velocity=self.velocity, status=self.status, task=task, claims=self.claims,
                               name=self.name)

    # --- one decision (seed 003 Sec. III-B) -----------------------------------------------------------------
    def step(self, now: float) -> None:
        if self._refused():
            return
        s = self.node.vehicle_status()
        with self._lock:
            self._observe(s)
            if self.position is None:
                return
            if not self._tier(s):
                return
            if self.switchboard.controller is Controller.TEAM and self._paused():
                return  # a break-in by the operator: the claims stand until it is resumed
            if not self._ready():
                if not self._flying_team_tree():
                    self.decision.clear()  # no bids before the vehicle knows where it is
                return  # a tree still flies its task: the claims stand (the tree, not the belief, flies it)
            board = self.state.board
            rows = {m: e for m, e in self.state.alive().items() if m != self.id}
            self._progress()
            held = self.switchboard.task
            flying = held.id if held is not None and self.switchboard.controller is Controller.TEAM else None
            choice = self.decision.step(now, self.position, board, rows, self.own_row, flying)
            self._switch(choice, s.on_ground)

    def _refused(self) -> bool:
        """Refused to join (a duplicate id): no claims, no team task flown."""
        if self.link.refused is None:
            return False
        with self._lock:
            self.decision.clear()
            if self.switchboard.controller is Controller.TEAM:
                self.switchboard.loiter()
        return True

    def _observe(self, s: VehicleStatus) -> None:
        if s.global_position is not None:
            lat, lon, _alt, rel = s.global_position
            self.position = (lat, lon, rel)
        self.velocity = s.velocity

    def _ready(self) -> bool:
        """The executive layer localizes the vehicle (SELF_LOCALIZE active: a healthy estimate), so the
        motion behaviors a task needs may start."""
        return self.missions.layer.coordinator.is_active("SELF_LOCALIZE")

    def _flying_team_tree(self) -> bool:
        """The team's tree of a held task is still running (loaded, running or paused): while it flies, the
        task is this vehicle's whatever the localization belief says, so its claims are kept (dropping them
        would let another vehicle claim the "free" task and two vehicles fly it)."""
        if self.switchboard.controller is not Controller.TEAM or self.switchboard.task is None:
            return False
        out = self.switchboard.outcome()
        return out is not None and out.state not in ("succeeded", "failed", "aborted")

    def _paused(self) -> bool:
        status = self.missions.execution.root_status()
        return status is not None and status.state == "paused"

    def _tier(self, s: VehicleStatus) -> bool:
        """Set the status from the hierarchy; True if the team may give this vehicle tasks."""
        if s.overridden:
            if self.status is not MemberStatus.OVERRIDDEN:
                self.switchboard.hand_to(Controller.NONE)
                self._set_status(MemberStatus.OVERRIDDEN, "a ground station changed the mode")
            self.decision.clear()
            return False
        if self.taken:
            self.decision.clear()
            return False
        if self.status is MemberStatus.OVERRIDDEN:
            self.switchboard.hand_to(Controller.LOITER)
            self._set_status(MemberStatus.IDLE, "given back (GUIDED)")
        return True

    def _progress(self) -> None:
        """The current tree's outcome becomes DONE or FAILED."""
        out = self.switchboard.outcome()
        task = self.switchboard.task
        if out is not None and task is not None and self.switchboard.controller is Controller.TEAM:
            if out.state == "succeeded":
                self.decision.finished(task)
                self._event("done", task=task.id)
                self.switchboard.loiter()
            elif out.state in ("failed", "aborted"):
                self.decision.fail(task.id, out.reason or out.state)
                self._event("failed", task=task.id, reason=out.reason)
                self.switchboard.loiter()

    def _acceptable(self, task: TeamTask) -> bool:
        """Seed 000 Sec. III across the team: bid only for what this platform's delegation accepts (its
        check() and constraints on the task's tree); cached per task version."""
        key = (task.id, task.version)
        verdict = self._verdicts.get(key)
        if verdict is None:
            try:
                mission = mission_for(task, True, self.switchboard.standard_altitude)
                result = delegate(mission, self.missions.platform())
                verdict = "" if result.accepted else "; ".join(result.reasons) or "rejected"
            except (ValueError, ExecutionRequestError) as exc:
                verdict = str(exc) or "rejected"
            self._verdicts[key] = verdict
            if verdict:
                self._event("cannot", task=task.id, reason=verdict)
        return not verdict

    def _switch(self, choice: Choice, on_ground: bool) -> None:
        """Fly the decision's task once it has settled; loiter with none."""
        task = choice.task
        if task is None:
            if self.switchboard.controller is Controller.TEAM:
                self.switchboard.loiter()
            self._set_status(MemberStatus.LANDED if on_ground else MemberStatus.IDLE)
            return
        current = self.switchboard.task
        if current is not None and current.id == task.id and self.switchboard.controller is Controller.TEAM:
            self._set_status(MemberStatus.BUSY)
            return
        if not choice.settled:
            return
        if self.switchboard.fly(task, on_ground):
            self._event("fly", task=task.id, version=task.version)
            self._set_status(MemberStatus.BUSY)
        else:
            self.decision.fail(task.id, self.switchboard.errors[-1] if self.switchboard.errors else "refused")

    # --- bookkeeping -------------------------------------------------------------------------------------
    def _set_status(self, status: MemberStatus, why: str = "") -> None:
        if status is not self.status:
            self._event("status", status=status.name, why=why)
            self.status = status

    def _event(self, kind: str, **fields: Any) -> None:
        self.events.append({"t": self.clock(), "member": self.id, "event": kind, **fields})
        del self.events[:-200]
        log.info("team member %d: %s %s", self.id, kind, fields)

    def report(self) -> dict[str, Any]:
        """For the control surface: status, claims, switchboard, what the link knows."""
        with self._lock:
            rows = self.state.entries()
            refused = self.link.refused
            return {"member": self.id, "name": self.name, "status": self.status.name.lower(),
                    "team": f"refused: {refused}" if refused is not None else "joined",
                    "epoch": f"{self.link.epoch:016x}", "authenticated": self.link.key is not None,
                    "taken_reason": self.taken_reason,
                    "controller": self.switchboard.controller.value,
                    "task": self.switchboard.task.id if self.switchboard.task is not None else None,
                    "claims": [{"task": c.task, "version": c.version, "cost": round(c.cost, 2),
                                "state": c.state.name.lower()} for c in self.claims],
                    "done": sorted(self.done), "failed": dict(self.failed),
                    "cannot": {t: why for (t, _v), why in self._verdicts.items() if why},
                    "members": sorted(rows), "alive": sorted(self.state.alive()),
                    "epochs": {str(m): f"{r.epoch:016x}" for m, r in sorted(rows.items())},
                    "events": self.events[-20:],
                    "board": {"seq": self.state.board.seq,
                              "tasks": [{"id": t.id, "version": t.version, "kind": t.kind.value,
                                         "state": t.state.value} for t in self.state.board.tasks]},
                    "handovers": self.switchboard.handovers, "errors": list(self.switchboard.errors),
                    "conflicts": self.policy.conflicts,
                    "link": {"packets_sent": self.link.stats.packets_sent,
                             "packets_received": self.link.stats.packets_received,
                             "garbage": self.link.stats.garbage,
                             "foreign_version": self.link.stats.foreign_version,
                             "dropped_by_test_loss": getattr(self.link.transport, "dropped_loss", 0),
                             **link_drops(self.link)}}


__all__ = ["TaskState", "TeamMember"]
