"""What each leaf of a delegated TST will fly, and the expansion of scan-ground (seed 000 Sec. III-A, VI).

Seed 000 Sec. III-A: "Specific implementations, however, may include an expansion of the task into
subtasks. This process is invoked by calling the expand() method [...]. These are then returned and
appended to the tree". :func:`plan_leaf` computes, for one leaf whose free parameters are fixed, the
:class:`NodePlan` the executors need (in the local frame: north, east, up from home) and the path length
and time the endurance check needs; :func:`expand` turns a scan-ground leaf (Sec. VI-E, Fig. 14a) into its
sequence of ``fly-to`` children, one per waypoint, as :meth:`~companion.tst.tree.TstNode.append_child`
appends them.

Time model (``expected_s``; the endurance check uses the same, linear in the speed): a horizontal path of
``length`` flown at ``v`` in ``legs`` rest-to-rest legs (every waypoint is reached with E_H, Fig. 14b)
takes ``length / v + legs * v / a`` (a trapezoidal profile, an upper bound for short legs), plus the
vertical moves at the platform's climb / descent speed, plus any wait.
"""

from __future__ import annotations

import itertools
import math
from typing import Any

from companion.executors.coverage import Sensor, line_spacing, scan_pattern, scan_specs
from companion.executors.waypoint_order import order_segments, order_waypoints, path_length, segments
from companion.tst.params import area_to_local, geopoint_to_local
from companion.tst.plan import NodePlan
from companion.tst.platform import Platform
from companion.tst.tree import TstNode
from taskflight_common.geo import ned_to_geodetic

__all__ = ["NodePlan", "expand", "leg_time", "local_to_geopoint", "plan_leaf"]

NEU = tuple[float, float, float]


def local_to_geopoint(neu: NEU, platform: Platform) -> tuple[float, float, float]:
    """``[lat, lon, alt above home]`` of a local (north, east, up) point (:mod:`taskflight_common.geo`)."""
    lat, lon, alt = ned_to_geodetic((platform.home[0], platform.home[1], 0.0), neu[0], neu[1], -neu[2])
    return (round(lat, 9), round(lon, 9), round(alt, 4))


def leg_time(length_m: float, speed: float, accel: float) -> float:
    """Time of one rest-to-rest leg with the linear model of the module docstring."""
    return length_m / speed + (speed / accel if length_m > 0 else 0.0)


def vertical_time(dz: float, platform: Platform) -> float:
    """Seconds to climb (dz > 0) or descend (dz < 0) at the platform's vertical speeds."""
    return dz / platform.max_climb if dz >= 0 else -dz / platform.max_descent


def _finish(plan: NodePlan, start: NEU, platform: Platform, legs: int, extra_s: float = 0.0) -> NodePlan:
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


def plan_leaf(node: TstNode, platform: Platform, values: dict[str, Any], start: NEU,
              speed_m_s: float | None = None) -> tuple[NodePlan, NEU]:
    """The plan of a leaf from ``start`` (local NEU), its free parameters fixed in ``values``.

    ``values`` are the node's parameters with every free one fixed (qualitative words, numbers);
    ``speed_m_s`` is the fixed speed in m/s where the task has one. Returns the plan and the position
    where the task leaves the vehicle.
    """
    kind = node.type
    nid = str(node.id)
    standard = platform.speeds.get("standard", 1.0)
    if kind == "take-off":
        alt = platform.takeoff_altitude
        plan = NodePlan(nid, kind, altitude_m=alt, position_neu=(start[0], start[1], alt), length_m=0.0)
        return _finish(plan, start, platform, 0), plan.position_neu  # type: ignore[return-value]
    if kind == "fly-to":
        target = geopoint_to_local(values["position"], platform.home)
        plan = NodePlan(nid, kind, speed_m_s=speed_m_s, altitude_m=target[2], position_neu=target,
                        straight_line=bool(values.get("fly_straight_line_flag", False)),
                        length_m=math.dist(start[:2], target[:2]))
        if values.get("follow_ground_flag"):
            plan.extra["follow_ground_altitude"] = values.get("follow_ground_altitude")
        if "speed" in values:
            plan.extra["speed"] = values["speed"]
        return _finish(plan, start, platform, 1), target
    if kind == "land":
        if values.get("land_at_current_position_flag", True) or "position" not in values:
            target = (start[0], start[1], 0.0)
        else:
            n, e, _ = geopoint_to_local(values["position"], platform.home)
            target = (n, e, 0.0)
        length = math.dist(start[:2], target[:2])
        plan = NodePlan(nid, kind, speed_m_s=standard if length > 0 else None, altitude_m=0.0,
                        position_neu=target, length_m=length)
        plan.extra["land_at_current_position"] = bool(values.get("land_at_current_position_flag", True))
        return _finish(plan, start, platform, 1 if length > 0 else 0), target
    if kind in ("wait", "hover"):
        duration = values.get("duration")
        target = start
        if kind == "hover" and "position" in values:
            target = geopoint_to_local(values["position"], platform.home)
        length = math.dist(start[:2], target[:2])
        plan = NodePlan(nid, kind, speed_m_s=standard if length > 0 else None, altitude_m=target[2],
                        position_neu=target, length_m=length, duration_s=duration)
        if duration is None:
            plan.extra["until"] = "enough"
        return _finish(plan, start, platform, 1 if length > 0 else 0, duration or 0.0), target
    if kind == "scan-ground":
        return _plan_scan(node, platform, values, start, speed_m_s)
    plan = NodePlan(nid, kind, expected_s=0.0, length_m=0.0)  # external-velocity, request-operator-assistance
    plan.extra["until"] = "operator"
    plan.extra.update({k: v for k, v in values.items() if isinstance(v, str | bool | int | float)})
    return plan, start


def _plan_scan(node: TstNode, platform: Platform, values: dict[str, Any], start: NEU,
               speed_m_s: float | None) -> tuple[NodePlan, NEU]:
    alt = float(values["altitude_m"])
    sensor = platform.sensors.get(values.get("sensor_type", "camera")) or Sensor()
    plan = NodePlan(str(node.id), "scan-ground", speed_m_s=speed_m_s, altitude_m=alt)
    extra = plan.extra
    extra.update({"sensor_type": sensor.type, "fov_deg": sensor.fov_deg, "overlap": sensor.overlap,
                  "repeat": bool(values.get("repeat_flag", False)),
                  "speed": values.get("speed"), "altitude": values.get("altitude")})
    if values.get("data_uuid"):
        extra["data_uuid"] = values["data_uuid"]
    if values.get("follow_ground_flag"):
        extra["follow_ground_altitude"] = values.get("follow_ground_altitude")
    if values.get("waypoints_scan_flag"):
        pts = [geopoint_to_local(p, platform.home) for p in values["waypoints"]]
        pts = [pt if len(p) == 3 else (pt[0], pt[1], alt)
               for p, pt in zip(values["waypoints"], pts, strict=True)]
        extra.update({"loiter_mode": values.get("loiter_mode", "pass"),
                      "segment_flag": bool(values.get("segment_flag")),
                      "any_order_flag": bool(values.get("any_order_flag"))})
        if values.get("segment_flag"):
            segs = segments([p[:2] for p in pts])
            plan_order = (order_segments(segs, start[:2]) if values.get("any_order_flag")
                          else [(i, False) for i in range(len(segs))])
            order: list[int] = []
            for i, rev in plan_order:
                order += [2 * i + 1, 2 * i] if rev else [2 * i, 2 * i + 1]
            extra["segments"] = [[k, k + 1] for k in range(0, len(order), 2)]
        elif values.get("any_order_flag"):
            order = order_waypoints([p[:2] for p in pts], start[:2])
        else:
            order = list(range(len(pts)))
        plan.waypoints_neu = [pts[i] for i in order]
        extra["order"] = order
    else:
        plan.area_ne = area_to_local(values["area"], platform.home)
        spacing = line_spacing(alt, sensor.fov_deg, sensor.overlap)
        pattern = scan_pattern(plan.area_ne, spacing, start_ne=start[:2])
        plan.waypoints_neu = [(n, e, alt) for n, e in pattern.waypoints]
        extra.update({"spacing_m": pattern.spacing, "lines": len(pattern.lines),
                      "angle_deg": pattern.angle_deg})
        if values.get("generate_scan_specs_flag") and speed_m_s:
            extra["scan_specs"] = scan_specs(pattern, alt, speed_m_s, sensor, platform.max_accel,
                                             plan.area_ne)
    wps = plan.waypoints_neu
    plan.length_m = math.dist(start[:2], wps[0][:2]) + path_length([w[:2] for w in wps])
    end = wps[-1]
    plan = _finish(plan, start, platform, len(wps))
    # vertical moves between waypoints of different altitudes (waypoint scans with altitudes)
    plan.expected_s = (plan.expected_s or 0.0) + sum(
        vertical_time(b[2] - a[2], platform) for a, b in itertools.pairwise(wps))
    return plan, end


def expand(node: TstNode, platform: Platform, values: dict[str, Any], plan: NodePlan | None = None,
           start: NEU = (0.0, 0.0, 0.0), speed_word: str | None = None) -> list[TstNode]:
    """Seed 000 Sec. III-A ``expand()``: a scan-ground leaf's waypoints as ``fly-to`` children.

    Each child flies straight (``fly_straight_line_flag``) to one waypoint of the scan, in flight order,
    at the scan altitude and speed; its ``position`` is a geopoint (``[lat, lon, alt above home]``). The
    children are appended to ``node`` (:meth:`~companion.tst.tree.TstNode.append_child`) and returned;
    ids are ``<scan id>.wp1``, ``.wp2``, ... Other task types do not expand (an empty list).
    ``values`` are the node's parameters with the free ones fixed (see :func:`plan_leaf`).
    """
    if node.type != "scan-ground":
        return []
    if plan is None:
        plan, _ = plan_leaf(node, platform, values, start)
    word = speed_word or values.get("speed")
    if word not in platform.speeds:
        word = "standard"
    root = node.root
    out: list[TstNode] = []
    for k, wp in enumerate(plan.waypoints_neu, start=1):
        child_id = f"{node.id}.wp{k}"
        params = {"position": list(local_to_geopoint(wp, platform)), "speed": word,
                  "fly_straight_line_flag": True}
        child = TstNode("fly-to", params=params, id=None if root.find(child_id) else child_id)
        out.append(node.append_child(child))
    return out
