"""Helpers the flight maneuvers share: the situation "flying", the reference's position, channel builders."""

from __future__ import annotations

from companion.flight import (
    EndCondition,
    FlightCommand,
    HeadingChannel,
    HeadingMode,
    HorizontalChannel,
    HorizontalMode,
    VerticalChannel,
    VerticalMode,
)

from ..controller import BehaviorExecutionController

Vec3 = tuple[float, float, float]


def need_flying(c: BehaviorExecutionController, or_taking_off: bool = False) -> str | None:
    """The situation of every maneuver but TAKE_OFF: the vehicle flies (``or_taking_off``: or takes off,
    for LAND and RTL, which may cut a take-off short) and the companion has it."""
    state = c.flight_state()
    if state != "flying" and not (or_taking_off and state == "taking_off"):
        return f"needs flight_state(self, flying); the vehicle is {state or 'in an unknown state'}"
    if c.ctx.queue.status().queue_system_status.name == "OVERRIDDEN":
        return "the vehicle is controlled elsewhere (a pilot or ground station took it)"
    return None


def reference_neu(c: BehaviorExecutionController) -> Vec3:
    """Where the reference is now ((north, east, up)); the vehicle's position before the first tick."""
    ref = c.ctx.queue.reference
    if ref is not None:
        return (float(ref.p[0]), float(ref.p[1]), float(ref.altitude))
    v = c.ctx.vehicle()
    if v is None:
        return (0.0, 0.0, 0.0)
    return (v.p[0], v.p[1], -v.p[2])


def go_to(point: Vec3, speed: float | None = None, straight_line: bool = True,
          follow_ground: float | None = None, end_speed: float | None = None) -> FlightCommand:
    """Seed 000 Fig. 12b: H_Pos to ``point`` ((north, east, up), absolute), V_WithHor (the straight 3-D
    line) or V_Pos (altitude on its own, ``straight_line`` false), Hd_DNU (heading kept), E_H and E_V.
    ``follow_ground`` (m; Fig. 12a's follow_ground_altitude): V_GROUND at that height above the ground the
    range finder measures instead (``point``'s altitude is then not flown). ``end_speed`` (m/s, default 0:
    come to rest) is the speed the command ends with at ``point``: the next command goes on from there
    without stopping (H_Pos's end speed, Fig. 7a)."""
    if follow_ground is not None:
        vertical = VerticalChannel(VerticalMode.GROUND, altitude=float(follow_ground))
    elif straight_line:
        vertical = VerticalChannel(VerticalMode.WITH_HOR, altitude=point[2])
    else:
        vertical = VerticalChannel(VerticalMode.POS, altitude=point[2])
    return FlightCommand(HorizontalChannel(HorizontalMode.POS, north=point[0], east=point[1], speed=speed,
                                           end_speed=end_speed),
                         vertical, HeadingChannel(HeadingMode.DNU), EndCondition(e_h=True, e_v=True))


def hold(end: EndCondition) -> FlightCommand:
    return FlightCommand(HorizontalChannel(HorizontalMode.DNU), VerticalChannel(VerticalMode.DNU),
                         HeadingChannel(HeadingMode.DNU), end)
