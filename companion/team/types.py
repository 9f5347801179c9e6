"""The team layer's shared vocabulary (seed 003 Sec. II-III): the group-state entry, claims, team tasks.

Seed 003 Sec. III-A: "group-state information can be visualized as a two-dimensional vector where one
dimension denotes the particular vehicle and the other dimension denotes the specific field of interest
such as time stamp or ID number". One :class:`MemberEntry` is one row of that vector; its fields are the
columns. Each row has exactly one writer, its owner (seed 003 Sec. III-B "each variable has only one
process with write permission"): a member refreshes its own row and only carries the others' rows along
(controlled flooding). The task list (:class:`TaskBoard`) has one writer too, the team-control station;
a task's progress is written by its holder in its own row (:class:`Claim` with a :class:`ClaimState`).

Positions are WGS84 latitude and longitude in degrees and an altitude in metres above the team's
datum (the vehicles' home altitude, as GLOBAL_RELATIVE_ALT), the frame the operator gives tasks in.
Times are seconds of GPS time (or the station's clock in simulation: any clock shared by the team).
These types are immutable: a new refresh is a new object.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum, StrEnum

#: a position: (latitude deg, longitude deg, altitude m above the team datum)
GeoPoint = tuple[float, float, float]

#: member id of the team-control station (vehicles use their MAVLink system id by default; ids are 32-bit)
STATION_ID = 0
#: the largest member id the wire format carries
MEMBER_ID_MAX = 0xFFFFFFFF


class MemberStatus(IntEnum):
    """What a member's own row says of it (seed 003 Fig. 1: the tier that controls it)."""

    IDLE = 0        #: in the team, holding no task: loitering where it is (or on the ground)
    BUSY = 1        #: in the team, flying a team task
    TAKEN = 2       #: taken out of the team by a directed command (process monitor tier)
    OVERRIDDEN = 3  #: a ground station changed the autopilot's mode (the lowest tier)
    STATION = 4     #: the team-control station (not a vehicle)
    LANDED = 5      #: in the team, on the ground after a landing it was told to make

    @property
    def available(self) -> bool:
        """May the team give this member tasks?"""
        return self in (MemberStatus.IDLE, MemberStatus.BUSY, MemberStatus.LANDED)


class ClaimState(IntEnum):
    """A holder's progress on a claimed task, written in its own row."""

    CLAIMED = 0     #: claimed, not yet flown (cost is the holder's bid)
    ACTIVE = 1      #: being flown
    DONE = 2        #: finished (kept in the row until the board says done)
    FAILED = 3      #: the holder could not do it (its TST failed or was rejected)


@dataclass(frozen=True)
class Claim:
    """One task a member claims, with its cost (s of flight, or m for the Euclidean policy)."""

    task: int
    version: int
    cost: float
    state: ClaimState = ClaimState.CLAIMED


@dataclass(frozen=True)
class MemberEntry:
    """One row of the group state (seed 003 Sec. III-A).

    ``epoch`` (the owner's boot epoch) and ``seq`` order refreshes: within one epoch a received row
    replaces the local one only if its ``seq`` is higher; a row of another epoch (a reboot, or another
    vehicle with the same id) replaces it only under the identity rule of
    :class:`~companion.team.groupstate.GroupState`. ``stamp`` is the owner's clock at the refresh, shown
    and checked against a future window, never used to order rows (a companion's clock may be far behind
    after a reboot). ``voc`` is the vote of confidence, a small integer that ages every sample interval
    the owner has not refreshed the row, raised only by the owner or by a member reporting a higher voc
    for it; zero means gone. ``task`` is the task being flown (0: none). ``claims`` is the member's
    bundle in order (one claim under the greedy policy, several under CBBA).
    """

    member: int
    stamp: float
    seq: int
    position: GeoPoint = (0.0, 0.0, 0.0)
    velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)  #: north, east, down m/s
    status: MemberStatus = MemberStatus.IDLE
    task: int = 0
    claims: tuple[Claim, ...] = ()
    voc: int = 0
    name: str = ""
    epoch: int = 0

    def newer_than(self, other: MemberEntry) -> bool:
        """Seed 003 Sec. III-A orders rows by time stamp and sequence number; here the boot epoch gives the
        origin (no host clock) and the sequence number the resolution: newer only within one epoch."""
        return self.epoch == other.epoch and self.seq > other.seq


class TaskKind(StrEnum):
    """Team task types (seed 003 Sec. II-III; area scan and TST added)."""

    VISIT = "visit"                  #: visit location: one point, visited once
    PATROL_LINE = "patrol_line"      #: a polyline flown back and forth until cancelled
    BORDER_PIECE = "border_piece"    #: one of N equal-length pieces of a border patrol (patrolled)
    AREA_PART = "area_part"          #: one of N equal-area parts of an area scan (a scan-ground)
    TST = "tst"                      #: a Task Specification Tree (or a C node's child) given to the team


class TaskState(StrEnum):
    """A team task's state as the operator sees it."""

    UNASSIGNED = "unassigned"
    ASSIGNED = "assigned"
    ACTIVE = "active"
    DONE = "done"
    CANCELLED = "cancelled"

    @property
    def final(self) -> bool:
        return self in (TaskState.DONE, TaskState.CANCELLED)


@dataclass(frozen=True)
class TeamTask:
    """One allocatable task on the board. ``group`` is the id of the operator's task it is a piece of
    (a border patrol or area scan divided among ``group_size`` vehicles; 0 for a task given whole).
    ``state`` as published by the station: UNASSIGNED for a live task, DONE or CANCELLED when over
    (assigned and active are derived from the members' claims). ``tst`` is the tree's JSON for TST
    tasks. ``altitude`` (m above the datum) and ``speed`` (m/s, 0: the platform's standard) apply to
    the legs flown to and along the task."""

    id: int
    version: int
    kind: TaskKind
    points: tuple[GeoPoint, ...]
    state: TaskState = TaskState.UNASSIGNED
    group: int = 0
    group_size: int = 1
    altitude: float = 0.0
    speed: float = 0.0
    tst: str | None = None
    name: str = ""

    @property
    def live(self) -> bool:
        return not self.state.final


@dataclass(frozen=True)
class TaskBoard:
    """The task list, written only by the team-control station and flooded like a row: it carries the
    station's boot ``epoch`` and its version ``seq``; within one epoch a higher ``seq`` replaces a lower
    one, a board of another epoch replaces it once the group state has taken that epoch's station row
    (:meth:`~companion.team.groupstate.GroupState.merge_board`). ``stamp`` is shown, never ordered on."""

    stamp: float = 0.0
    seq: int = 0
    tasks: tuple[TeamTask, ...] = field(default_factory=tuple)
    epoch: int = 0

    def newer_than(self, other: TaskBoard) -> bool:
        """Within one epoch: a higher version. The empty initial board (epoch 0, version 0) is older than
        any board of an epoch."""
        if self.epoch == other.epoch:
            return self.seq > other.seq
        return other.epoch == 0 and other.seq == 0 and not other.tasks

    def get(self, task_id: int) -> TeamTask | None:
        for t in self.tasks:
            if t.id == task_id:
                return t
        return None

    def live(self) -> tuple[TeamTask, ...]:
        return tuple(t for t in self.tasks if t.live)
