"""A companion joins a team (``taskflight companion ... --team URL``): the pieces of seed 003 Sec. III put
together for one vehicle.

The member id is the vehicle's MAVLink system id (unique in a fleet; ``taskflight up`` numbers vehicles
1..N), its name the one given or ``uav<id>``. The cost is the flight time under the platform's standard
speed, horizontal acceleration and vertical speed (:class:`~companion.team.cost.CostModel`; the
Euclidean distance of the paper is its lower bound), and the policy greedy (seed 003 Sec. III-B) or CBBA.
A ``range`` option of the team URL drops packets between members farther apart than that (a radio's
range, for tests), using the positions of the group state.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .allocation import make_policy
from .auth import warn_if_unauthenticated
from .cost import CostModel
from .member import TeamMember
from .transport import open_transport
from .types import MEMBER_ID_MAX

if TYPE_CHECKING:
    from companion.mission_service import MissionService

def cost_model_for(missions: MissionService) -> CostModel:
    """Flight time under the platform's standard speed and its acceleration and climb limits."""
    p = missions.platform()
    return CostModel(speed=float(p.speeds.get("standard", p.limits.horizontal_speed)),
                     accel=float(p.limits.horizontal_acceleration),
                     climb_speed=float(p.limits.vertical_speed))


def join_team(missions: MissionService, url: str, member_id: int, *, policy: str = "greedy", name: str = "",
              period_s: float | None = None, voc_max: int | None = None,
              key: bytes | None = None) -> TeamMember:
    """A started :class:`TeamMember` for ``missions``' vehicle on the team link ``url`` (signed with
    ``key``, the team key of :mod:`.auth`, when given)."""
    if not 1 <= member_id <= MEMBER_ID_MAX:
        raise ValueError(f"member id {member_id}: outside 1..{MEMBER_ID_MAX} (by default a vehicle's "
                         "MAVLink system id)")
    model = cost_model_for(missions)
    chosen = make_policy(policy, model)
    holder: dict[str, TeamMember] = {}

    def position_of(member: int) -> tuple[float, float, float] | None:
        m = holder.get("member")
        row = m.state.get(member) if m is not None else None
        return row.position if row is not None else None

    transport = open_transport(url, member=member_id, position_of=position_of)
    warn_if_unauthenticated(transport.url, key, f"team member {member_id}")
    member = TeamMember(missions, transport, chosen, model.cost, member_id=member_id, name=name,
                        period_s=period_s, voc_max=voc_max, key=key)
    holder["member"] = member
    return member.start()
