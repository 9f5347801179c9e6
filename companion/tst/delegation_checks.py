"""``check()`` and ``get_constraints()`` of the delegation, per task type (seed 000 Sec. III-A, Fig. 3).

Seed 000 Sec. III-A: ``check()`` verifies "whether the execution can be performed with the provided
input parameters as well as checking whether other platform-specific requirements are met. For example, a
check whether a camera or a laser range finder sensors are present"; ``get_constraints()`` "returns any
constraints [...] which are platform-specific and should be checked for consistency with a constraint
solver", e.g. "a maximum duration of a task which is limited by the current fuel level".

:func:`check` returns the reasons a node cannot be run by a platform, each starting with the node and a
tag the user can look for: ``unknown task``, ``outside the fence``, ``bad altitude``, ``missing sensor``,
``no range sensor``, ``bad parameters``. :func:`get_constraints` adds a node's constraints to a
:class:`~companion.tst.constraints.ConstraintProblem` as labelled constraints that name the node
(``scan.altitude <= ceiling 10 m (altitude_max)``); with a :class:`NodePlan` (after the expansion) it
adds the node's duration too (``duration_at_speed`` with the planned path length).
"""

from __future__ import annotations

import re
from typing import Any

from companion.tst.constraints import ConstraintProblem, Linear
from companion.tst.delegation_plan import NodePlan
from companion.tst.params import Interval, LinearRelation, Qualitative, geopoint_to_local, is_free
from companion.tst.platform import Platform
from companion.tst.tree import CONTROL_TYPES, TstNode

__all__ = ["check", "get_constraints", "get_relations", "var"]

#: The platform quantities a relation may name (``duration <= endurance_left``).
PLATFORM_QUANTITIES = ("endurance_left", "max_speed", "ceiling", "floor", "takeoff_altitude")
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
    return f"node {node.id} ({node.type})"


# --- check() -----------------------------------------------------------------------------------------
def check(node: TstNode, platform: Platform) -> list[str]:
    """Seed 000 Sec. III-A ``check()``: why ``platform`` cannot run ``node`` itself (empty: it can).

    Control nodes (S, C, IF, WHILE) are always runnable here; their children are checked on their own.
    """
    if node.type in CONTROL_TYPES:
        return []
    at = where(node)
    if node.type not in platform.tasks:
        return [f"{at}: unknown task: platform {platform.name} has no executor for '{node.type}' "
                f"(it runs: {', '.join(platform.tasks)})"]
    p = node.params
    out: list[str] = []
    if p.get("follow_ground_flag") and not platform.range_sensor:
        out.append(f"{at}: no range sensor: follow_ground_flag needs a ground range sensor and platform "
                   f"{platform.name} has none")
    if node.type in ("fly-to", "hover") and "position" in p:
        out += _point(at, "position", p["position"], platform, altitude=True)
    if node.type == "land" and "position" in p and not p.get("land_at_current_position_flag"):
        out += _point(at, "position", p["position"], platform, altitude=False)
    if node.type == "scan-ground":
        sensor = p.get("sensor_type", "camera")
        if sensor not in platform.sensors:
            out.append(f"{at}: missing sensor: sensor_type {sensor}, but platform {platform.name} has no "
                       f"{sensor} (sensors: {', '.join(sorted(platform.sensors)) or 'none'})")
        if "area" in p:
            outside = [i for i, v in enumerate(p["area"])
                       if platform.fence_reason(geopoint_to_local(v, platform.home)[:2])]
            if outside:
                n, e, _ = geopoint_to_local(p["area"][outside[0]], platform.home)
                out.append(f"{at}: area outside the fence: vertex {outside[0]} of the area "
                           f"({n:.1f} m north, {e:.1f} m east of home) and {len(outside) - 1} more: "
                           f"{platform.fence_reason((n, e))}")
        for i, wp in enumerate(p.get("waypoints") or ()):
            out += _point(at, f"waypoint {i}", wp, platform, altitude=len(wp) == 3)
        if p.get("segment_flag") and len(p.get("waypoints") or ()) % 2:
            out.append(f"{at}: bad parameters: segment_flag needs an even number of waypoints (pairs)")
    return out


def _point(at: str, what: str, point: Any, platform: Platform, altitude: bool) -> list[str]:
    n, e, up = geopoint_to_local(point, platform.home)
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


# --- get_constraints() ------------------------------------------------------------------------------
def _qualitative_allowed(value: Any, options: dict[str, float]) -> list[str] | None:
    """The options a mission allows: a word, a Qualitative set, or None (free: unspecified / absent)."""
    if isinstance(value, Qualitative):
        return [o for o in value.options if o in options]
    if isinstance(value, str) and value in options:
        return [value]
    return None


def _number(problem: ConstraintProblem, name: str, value: Any, label: str, lo: float | None = None,
            hi: float | None = None) -> None:
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
        problem.variable(name, value=float(value), label=f"{label} = {float(value):g} (given)")


def get_constraints(node: TstNode, platform: Platform, problem: ConstraintProblem,
                    plan: NodePlan | None = None, fixed: dict[str, Any] | None = None) -> None:
    """Seed 000 Sec. III-A ``get_constraints()``: add the platform's constraints on ``node`` to ``problem``.

    Without ``plan`` (before the expansion): the parameters' constraints, the speed limit, altitude floor
    and ceiling. With ``plan`` (after it): the speeds again (qualitative ones still free, the others as
    ``fixed``: parameter -> value) and the node's duration ``<id>.duration`` from the planned path
    (``duration_at_speed``), which the endurance constraint sums. Control nodes add their duration from
    their children's (S: the sum; C, IF: at least each child's; WHILE: one pass of the body).
    """
    nid = str(node.id)
    fixed = fixed or {}
    if node.type in CONTROL_TYPES:
        if plan is None and not node.children:
            return
        if plan is not None:
            _control_duration(node, problem)
        return
    p = node.params
    has_speed = node.type in ("fly-to", "scan-ground")
    if has_speed:
        speed = var(node, "speed")
        if "commanded_speed" in p:
            given = p["commanded_speed"]
            if plan is not None:
                given = fixed.get("commanded_speed", given)
            _number(problem, speed, given, f"{nid}.commanded_speed", lo=min(platform.speeds.values()),
                    hi=platform.max_speed[0])
        else:
            allowed = _qualitative_allowed(p.get("speed"), dict(platform.speeds))
            problem.qualitative(speed, dict(platform.speeds), allowed=allowed, prefer="standard",
                                label=f"{nid}.speed in {{{', '.join(platform.speeds)}}}")
        top, src = platform.max_speed
        problem.add(Linear({speed: 1.0}, "<=", top), label=f"{nid}.speed <= max speed {top:g} m/s ({src})")
    if plan is None:
        _altitudes(node, platform, problem)
        if node.type in ("wait", "hover") and is_free(p.get("duration")):
            _number(problem, var(node, "duration"), p["duration"], f"{nid}.duration", lo=0.0)
        return
    # after the expansion: the node's duration
    total = var(node, "duration")
    legs = int(plan.extra.get("legs", 0))
    fixed_s = (plan.expected_s or 0.0)
    if has_speed and plan.length_m:
        travel = var(node, "travel")
        v0 = plan.speed_m_s or 1.0
        extra_s = fixed_s - plan.length_m / v0 - legs * v0 / platform.max_accel
        problem.duration_at_speed(travel, plan.length_m, speed, extra_s=max(0.0, extra_s),
                                  label=f"{nid}.travel = {plan.length_m:.1f} m / {nid}.speed"
                                        + (f" + {extra_s:.1f} s" if extra_s > 1e-9 else ""))
        problem.variable(total)
        problem.add(Linear({total: 1.0, travel: -1.0, speed: -legs / platform.max_accel}, "==", 0.0),
                    label=f"{nid}.duration = {nid}.travel + {legs} legs x {nid}.speed / "
                          f"{platform.max_accel:g} m/s2", definition=True)
    else:
        problem.variable(total, value=fixed_s, label=f"{nid}.duration = {fixed_s:.1f} s ({node.type})")


def _altitudes(node: TstNode, platform: Platform, problem: ConstraintProblem) -> None:
    nid = str(node.id)
    ceiling, c_src = platform.ceiling
    floor, f_src = platform.floor
    p = node.params
    names: list[tuple[str, str]] = []
    if node.type == "take-off":
        alt = var(node, "altitude")
        problem.variable(alt, value=platform.takeoff_altitude,
                         label=f"{nid}.altitude = take-off altitude {platform.takeoff_altitude:g} m")
        names.append((alt, f"{nid}.altitude"))
    if node.type == "scan-ground":
        alt = var(node, "altitude")
        allowed = _qualitative_allowed(p.get("altitude"), dict(platform.altitudes))
        problem.qualitative(alt, dict(platform.altitudes), allowed=allowed, prefer="standard",
                            label=f"{nid}.altitude in {{{', '.join(platform.altitudes)}}}")
        names.append((alt, f"{nid}.altitude"))
    if p.get("follow_ground_flag") and "follow_ground_altitude" in p:
        fga = var(node, "follow_ground_altitude")
        _number(problem, fga, p["follow_ground_altitude"], f"{nid}.follow_ground_altitude", lo=0.0)
        names.append((fga, f"{nid}.follow_ground_altitude"))
    for name, label in names:
        if ceiling != float("inf"):
            problem.add(Linear({name: 1.0}, "<=", ceiling),
                        label=f"{label} <= ceiling {ceiling:g} m ({c_src})")
        if node.type != "take-off" and floor > 0:
            problem.add(Linear({name: 1.0}, ">=", floor), label=f"{label} >= floor {floor:g} m ({f_src})")


def _control_duration(node: TstNode, problem: ConstraintProblem) -> None:
    nid = str(node.id)
    total = var(node, "duration")
    problem.variable(total)
    kids = [var(c, "duration") for c in node.children]
    if node.type == "S":
        problem.add(Linear({total: 1.0, **{k: -1.0 for k in kids}}, "==", 0.0),
                    label=f"{nid}.duration = sum of its children's", definition=True)
    elif node.type == "WHILE":
        problem.add(Linear({total: 1.0, kids[0]: -1.0}, "==", 0.0),
                    label=f"{nid}.duration = one pass of its body", definition=True)
    else:
        for child, k in zip(node.children, kids, strict=True):
            problem.add(Linear({total: 1.0, k: -1.0}, ">=", 0.0),
                        label=f"{nid}.duration >= {child.id}.duration", definition=True)


def declare_platform(problem: ConstraintProblem, platform: Platform) -> None:
    """The platform quantities (:data:`PLATFORM_QUANTITIES`) as given variables."""
    problem.variable("endurance_left", value=platform.endurance_s,
                     label=f"endurance_left = {platform.endurance_s:g} s ({platform.endurance_source})")
    top = platform.max_speed[0]
    problem.variable("max_speed", value=top, label=f"max_speed = {top:g} m/s")
    if platform.ceiling[0] != float("inf"):
        problem.variable("ceiling", value=platform.ceiling[0], label=f"ceiling = {platform.ceiling[0]:g} m")
    problem.variable("floor", value=platform.floor[0], label=f"floor = {platform.floor[0]:g} m")
    problem.variable("takeoff_altitude", value=platform.takeoff_altitude,
                     label=f"takeoff_altitude = {platform.takeoff_altitude:g} m")


def get_relations(node: TstNode, problem: ConstraintProblem, ids: dict[str, TstNode]) -> list[str]:
    """Post the node's linear relations (``commanded_speed <= 0.5 * max_speed``), names resolved.

    A name is a parameter of the node, ``<node id>.<parameter>`` of another node, or a platform
    quantity. Returns the reasons it could not (an unknown name).
    """
    out: list[str] = []
    for pname, value in node.params.items():
        if not isinstance(value, LinearRelation):
            continue
        terms: dict[str, float] = {}
        for name, coef in value.coefficients:
            if name in PLATFORM_QUANTITIES:
                resolved = name
            elif "." in name and name.rsplit(".", 1)[0] in ids:
                other, param = name.rsplit(".", 1)
                resolved = var(ids[other], param)
            else:
                resolved = var(node, name)
            if resolved not in problem.variables:
                out.append(f"{where(node)}: bad parameters: relation '{value.text}' of {pname}: unknown name "
                           f"'{name}' (a free parameter, <node id>.<parameter> or one of "
                           f"{', '.join(PLATFORM_QUANTITIES)})")
                break
            terms[resolved] = terms.get(resolved, 0.0) + coef
        else:
            problem.add(Linear(terms, value.op, value.constant),
                        label=f"{node.id}.{pname}: {value.text} (given)")
    return out
