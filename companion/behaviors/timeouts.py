"""Time-outs derived from the plan, and the parameters the flight envelope cannot honour.

Seed 001 Sec. 5.2.1 ends a behavior with ``time_out`` when it is "not achieved within the time
limit" of its descriptor (Fig. 5's ``time out``). A fixed number contradicts the parameters' ranges
(a LAND 1000 m away, a 300 x 300 m scan): here a goal-based behavior with a plan gets its limit from
that plan, the catalog giving only the slack::

    timeout: {factor: 1.5, margin_s: 20}     # limit = factor x planned duration + margin_s
    timeout: 600                             # a behavior without a plan: a fixed limit (s)

The planned duration is the motion at the speed *actually allowed*: the request's ``speed`` clamped
to the queue's limits (seed 000 Sec. IV-D: v_env, a_env), each leg a trapezoid of speed (accelerate,
cruise, brake), horizontal and vertical flown together (the longer counts), heading turns at the
yaw-rate limit, a WAIT its duration. :func:`time_limit` is public so that delegation can tell in
advance how long a behavior may run (``companion.tst``).

:func:`envelope_refusal` is the other half of "never say yes and then do something else": a speed
or velocity beyond the limits is refused at the coordinator's format check with the reason, never
clamped silently (``docs/behaviors.md``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from companion.flight.limits import Limits

from .catalog import BehaviorDescriptor

Vec3 = tuple[float, float, float]
#: (params, limits, start (north, east, up), start heading in degrees or None) -> planned seconds
Planner = Callable[[Mapping[str, Any], Limits, Vec3, "float | None"], float]

_PLANS: dict[str, Planner] = {}


def plan(behavior: str) -> Callable[[Planner], Planner]:
    """Decorator: the planned duration of ``behavior`` (a new behavior with a plan registers one)."""
    def deco(fn: Planner) -> Planner:
        _PLANS[behavior] = fn
        return fn
    return deco


def allowed_speed(params: Mapping[str, Any], limits: Limits) -> float:
    """The horizontal speed the queue will fly: the request's ``speed`` within the limit, else the limit."""
    speed = params.get("speed")
    if speed is None:
        return limits.horizontal_speed
    return min(float(speed), limits.horizontal_speed)


def travel_time(distance_m: float, speed: float, acceleration: float) -> float:
    """Seconds to move ``distance_m`` from rest to rest at most ``speed`` with ``acceleration``."""
    d = abs(distance_m)
    if d <= 0.0:
        return 0.0
    if d >= speed * speed / acceleration:  # reaches cruise speed
        return d / speed + speed / acceleration
    return 2.0 * math.sqrt(d / acceleration)


def legs_time(start: Vec3, points: Sequence[Sequence[float]], limits: Limits, speed: float) -> float:
    """The legs start -> points[0] -> ... flown straight, stopping at each point."""
    total, prev = 0.0, start
    for p in points:
        here = (float(p[0]), float(p[1]), float(p[2]) if len(p) > 2 else prev[2])
        horizontal = travel_time(math.dist(prev[:2], here[:2]), speed, limits.horizontal_acceleration)
        vertical = travel_time(here[2] - prev[2], limits.vertical_speed, limits.vertical_acceleration)
        total += max(horizontal, vertical)
        prev = here
    return total


def planned_duration(behavior: str, params: Mapping[str, Any], limits: Limits,
                     start_neu: Vec3 = (0.0, 0.0, 0.0), start_heading_deg: float | None = None
                     ) -> float | None:
    """The plan's duration in seconds, or None when ``behavior`` has no plan."""
    fn = _PLANS.get(behavior)
    if fn is None:
        return None
    return fn(params, limits, start_neu, start_heading_deg)


def time_limit(descriptor: BehaviorDescriptor, params: Mapping[str, Any], limits: Limits,
               start_neu: Vec3 = (0.0, 0.0, 0.0), start_heading_deg: float | None = None) -> float | None:
    """Seconds a behavior may run (not counting pauses) before it ends with ``time_out``; None: no limit.

    ``descriptor``'s ``timeout: {factor, margin_s}``: factor x :func:`planned_duration` + margin
    (a behavior without a registered plan gets the margin alone); a plain ``timeout``: that number;
    none, or a recurrent behavior: no limit. ``params`` are the checked parameters (defaults filled
    in), ``limits`` the queue's, ``start_neu`` where the vehicle starts ((north, east, up) from home)
    and ``start_heading_deg`` its heading (None: the worst case, a half turn)."""
    if descriptor.category != "goal_based":
        return None
    if descriptor.timeout_plan:
        planned = planned_duration(descriptor.behavior, params, limits, start_neu, start_heading_deg) or 0.0
        slack = descriptor.timeout_plan
        return slack.get("factor", 1.0) * planned + slack.get("margin_s", 0.0)
    return descriptor.timeout_s


def envelope_refusal(params: Mapping[str, Any], limits: Limits) -> tuple[str, str] | None:
    """(parameter, reason) for a parameter beyond the flight envelope's limits, or None.

    ``speed`` (m/s, horizontal) against ``horizontal_speed``; ``velocity`` ((north, east, up) m/s)
    against ``horizontal_speed`` (its horizontal norm) and ``vertical_speed``."""
    speed = params.get("speed")
    if isinstance(speed, int | float) and speed > limits.horizontal_speed + 1e-9:
        return "speed", (f"{speed:g} m/s is beyond the flight envelope's horizontal speed limit "
                         f"{limits.horizontal_speed:g} m/s (ask for at most that)")
    velocity = params.get("velocity")
    if isinstance(velocity, tuple | list) and len(velocity) == 3:
        h = math.hypot(float(velocity[0]), float(velocity[1]))
        if h > limits.horizontal_speed + 1e-9:
            return "velocity", (f"horizontal {h:g} m/s is beyond the flight envelope's horizontal speed "
                                f"limit {limits.horizontal_speed:g} m/s")
        if abs(float(velocity[2])) > limits.vertical_speed + 1e-9:
            return "velocity", (f"vertical {abs(float(velocity[2])):g} m/s is beyond the flight envelope's "
                                f"vertical speed limit {limits.vertical_speed:g} m/s")
    return None


# --- the bundled behaviors' plans ---------------------------------------------------------------------------
@plan("GO_TO_POINT")
def _go_to_point(params: Mapping[str, Any], limits: Limits, start: Vec3, heading: float | None) -> float:
    return legs_time(start, [params["coordinate"]], limits, allowed_speed(params, limits))


@plan("FOLLOW_PATH")
def _follow_path(params: Mapping[str, Any], limits: Limits, start: Vec3, heading: float | None) -> float:
    return legs_time(start, params["path"], limits, allowed_speed(params, limits))


@plan("TAKE_OFF")
def _take_off(params: Mapping[str, Any], limits: Limits, start: Vec3, heading: float | None) -> float:
    climb = float(params["altitude"]) - start[2]
    return travel_time(climb, limits.vertical_speed, limits.vertical_acceleration)


@plan("LAND")
def _land(params: Mapping[str, Any], limits: Limits, start: Vec3, heading: float | None) -> float:
    fly = 0.0
    if params.get("coordinate") is not None:
        fly = legs_time(start, [params["coordinate"]], limits, limits.horizontal_speed)
    return fly + travel_time(max(start[2], 0.0), limits.vertical_speed, limits.vertical_acceleration)


@plan("ROTATE")
def _rotate(params: Mapping[str, Any], limits: Limits, start: Vec3, heading: float | None) -> float:
    if params.get("relative_angle") is not None:
        turn = abs(float(params["relative_angle"]))
    elif heading is None:
        turn = 180.0
    else:
        turn = abs(math.remainder(float(params.get("angle", 0.0)) - heading, 360.0))
    return travel_time(turn, limits.yaw_rate, limits.yaw_acceleration)


@plan("WAIT")
def _wait(params: Mapping[str, Any], limits: Limits, start: Vec3, heading: float | None) -> float:
    return float(params.get("duration", 0.0))
