"""What several leaf task types share: solver variable names, fence and altitude checks, the parameter
constraints, the time model of a plan, the follow-ground parameters (seed 000 Sec. III-A, VI).

Time model (``expected_s``; the endurance check uses the same, linear in the speed): a horizontal path of
``length`` flown at ``v`` in ``legs`` rest-to-rest legs (every waypoint is reached with E_H, Fig. 14b)
takes ``length / v + legs * v / a`` (a trapezoidal profile, an upper bound for short legs), plus the
vertical moves at the platform's climb / descent speed, plus any wait.
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING, Any

from companion.tst.constraints import ConstraintProblem
from companion.tst.param_spec import ParamSpec
from companion.tst.params import Interval, LinearRelation, ParamError, Qualitative, plan_point
from companion.tst.plan import NodePlan, Vec3
from companion.tst.platform import Platform

if TYPE_CHECKING:
    from companion.tst.tree import TstNode

#: Parameter name -> the variable suffix the constraints use for it.
_VAR_OF_PARAM = {"commanded_speed": "speed", "speed": "speed"}


def var(node: TstNode | str, what: str) -> str:
    """The solver variable of ``what`` (a parameter or ``duration``) of a node: ``<id>.<what>``."""
    nid = node if isinstance(node, str) else str(node.id)
    safe = re.sub(r"\W", "_", nid)
    if not safe[:1].isalpha() and safe[:1] != "_":
        safe = "n_" + safe
    return f"{safe}.{_VAR_OF_PARAM.get(what, what)}"


def where(node: TstNode) -> str:
    """How a reason names a node: ``node scan (scan-ground)``."""
    return f"node {node.id} ({node.type})"


def point_reasons(at: str, what: str, point: Any, platform: Platform, altitude: bool) -> list[str]:
    """Why a geopoint cannot be flown to: outside the fence, or (``altitude``) below home, the floor or
    above the ceiling."""
    n, e, up = plan_point(point, platform.home)
    out = []
    why = platform.fence_reason((n, e))
    if why:
        out.append(f"{at}: {what} outside the fence: {n:.1f} m north, {e:.1f} m east of home is {why}")
    if altitude:
        ceiling, c_src = platform.ceiling
        floor, f_src = platform.floor
        if up < 0:
            out.append(f"{at}: bad altitude: {what} altitude {up:g} m is negative (below home)")
        elif up < floor:
            out.append(f"{at}: bad altitude: {what} altitude {up:g} m is below the floor {floor:g} m "
                       f"({f_src})")
        elif up > ceiling:
            out.append(f"{at}: bad altitude: {what} altitude {up:g} m is above the ceiling {ceiling:g} m "
                       f"({c_src})")
    return out


def speed_reasons(node: TstNode, platform: Platform) -> list[str]:
    """Why the node's given speed cannot be flown: a ``commanded_speed`` (a number, or an interval wholly)
    above the envelope's speed limit, the one the queue flies (:meth:`Platform.flight_limits`)."""
    given = node.params.get("commanded_speed")
    top, src = platform.max_speed
    low = given.lo if isinstance(given, Interval) else given
    if isinstance(low, int | float) and not isinstance(low, bool) and low > top + 1e-9:
        shown = f"{given:g}" if isinstance(given, int | float) else str(given)
        return [f"{where(node)}: bad speed: commanded_speed {shown} m/s is above the envelope's speed limit "
                f"{top:g} m/s ({src})"]
    return []


def qualitative_allowed(value: Any, options: dict[str, float]) -> list[str] | None:
    """The options a mission allows: a word, a Qualitative set, or None (free: unspecified / absent)."""
    if isinstance(value, Qualitative):
        return [o for o in value.options if o in options]
    if isinstance(value, str) and value in options:
        return [value]
    return None


def declare_number(problem: ConstraintProblem, name: str, value: Any, label: str, lo: float | None = None,
                   hi: float | None = None, note: str = "given") -> None:
    """Declare a numeric parameter: a given value, an interval, or free in ``[lo, hi]`` (a relation
    constrains it; the solver's default objective puts it in the middle, or at ``lo`` without ``hi``)."""
    if isinstance(value, Interval):
        problem.variable(name, lo=value.lo, hi=value.hi,
                         label=f"{label} in [{value.lo:g}, {value.hi:g}] (given)")
    elif (isinstance(value, LinearRelation) or value is None) and hi is not None and lo is not None:
        problem.variable(name, lo=lo, hi=hi, label=f"{label} in [{lo:g}, {hi:g}] (platform)")
    elif isinstance(value, LinearRelation) or value is None:
        problem.variable(name, lo=lo, label=f"{label} >= {lo:g}" if lo is not None else None)
    else:
        problem.variable(name, value=float(value), label=f"{label} = {float(value):g} ({note})")


def leg_time(length_m: float, speed: float, accel: float) -> float:
    """Time of one rest-to-rest leg with the linear model of the module docstring."""
    return length_m / speed + (speed / accel if length_m > 0 else 0.0)


def vertical_time(dz: float, platform: Platform) -> float:
    """Seconds to climb (dz > 0) or descend (dz < 0) at the platform's vertical speeds."""
    return dz / platform.max_climb if dz >= 0 else -dz / platform.max_descent


def finish_plan(plan: NodePlan, start: Vec3, platform: Platform, legs: int, extra_s: float = 0.0) -> NodePlan:
    """Fill ``expected_s`` from ``length_m``, ``speed_m_s``, the vertical move to ``altitude_m`` and legs."""
    length = plan.length_m or 0.0
    end_alt = plan.altitude_m if plan.altitude_m is not None else start[2]
    vertical = vertical_time(end_alt - start[2], platform)
    horizontal = 0.0
    if length > 0 and plan.speed_m_s:
        horizontal = length / plan.speed_m_s + legs * plan.speed_m_s / platform.max_accel
    plan.extra["legs"] = legs
    plan.extra["vertical_s"] = round(vertical, 6)
    plan.expected_s = horizontal + vertical + extra_s
    return plan


def follow_ground_params() -> tuple[ParamSpec, ...]:
    """Fig. 12a / 14a's ground-relative flight parameters."""
    return (
        ParamSpec("follow_ground_flag", "bool", "Ground relative flight.", default=False),
        ParamSpec("follow_ground_altitude", "float", "Distance to the ground if follow_ground_flag is true.",
                  unit="m", minimum=0.0),
    )


def check_follow_ground(p: dict[str, Any]) -> None:
    if p.get("follow_ground_flag") is True and "follow_ground_altitude" not in p:
        raise ParamError("required when follow_ground_flag is true", "follow_ground_altitude")
    if p.get("follow_ground_flag") is not True and "follow_ground_altitude" in p:
        raise ParamError("only meaningful when follow_ground_flag is true", "follow_ground_altitude")
