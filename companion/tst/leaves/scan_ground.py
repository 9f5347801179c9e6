"""scan-ground (seed 000 Sec. VI-E, Fig. 14; Sec. VII break-in, resume, enough): fly a scanning pattern
over an area or along waypoints.

Parameters as Fig. 14a; its ``generate_scan_specs_flag`` is used (the text also writes
``generate_scan_spec_flag``, accepted too), and ``loiter_mode``'s values, which Fig. 14a does not give, are
ours: ``pass`` (fly through the waypoint) and ``stop`` (come to rest at it). The plan is the area's
boustrophedon pattern (:mod:`companion.tst.planning.coverage`) or the waypoints in the order their flags
ask (:mod:`companion.tst.planning.waypoint_order`); ``expand()`` (Sec. III-A: "an expansion of the task
into subtasks [...] returned and appended to the tree") makes them ``fly-to`` children. The executor flies
them as one FOLLOW_PATH (H_Pos, V_WithHor, E_H, E_V per waypoint). Fig. 4: "has all three execution info
flags ... true" (VI-E).
"""

from __future__ import annotations

import itertools
import math
from types import MappingProxyType
from typing import Any

from companion.behaviors.activation import format_activation
from companion.sensing.footprint import Sensor, footprint_size
from companion.tst.constraints import ConstraintProblem, Solution
from companion.tst.executor import TstExecutor
from companion.tst.leaves.base import LeafType
from companion.tst.leaves.common import (
    check_follow_ground,
    declare_number,
    finish_plan,
    follow_ground_params,
    leg_time,
    point_reasons,
    qualitative_allowed,
    var,
    vertical_time,
    where,
)
from companion.tst.param_spec import ParamSpec
from companion.tst.params import ParamError, area_to_local, plan_point, plan_point_to_geopoint
from companion.tst.plan import NodePlan, Vec3
from companion.tst.planning.coverage import line_spacing, scan_pattern, scan_specs
from companion.tst.planning.waypoint_order import (
    order_segments,
    order_waypoints,
    path_length,
    segments,
)
from companion.tst.platform import Platform
from companion.tst.status import NodeExecutionInfo
from companion.tst.tree import TstNode

#: Parameters that only go with ``waypoints_scan_flag: true`` (Fig. 14a, *).
_WAYPOINT_ONLY = ("waypoints", "loiter_mode", "segment_flag", "any_order_flag")


class ScanGroundExecutor(TstExecutor):
    """Flies the expanded waypoints (delegation's ``expand()``) as one FOLLOW_PATH, so the scan is paused,
    resumed and enoughed as one task. While it runs the camera (if the platform has one) labels its
    detections with the scan's ``data_uuid``. Progress: the waypoint being flown, of how many; after an
    enough, the waypoints skipped.

    ``repeat_flag`` (Fig. 14a: "we are in patrol mode and repeat the scan of the area"): each finished pass
    starts the next one back over the same waypoints in the reverse order (w0 .. wn, wn .. w0, ...; the
    back-and-forth of :func:`~companion.tst.planning.waypoint_order.repeat`), until an enough or an abort
    ends the patrol (seed 003's patrol tasks: "flown back and forth until cancelled")."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.skipped: list[int] = []
        self.lap = 0
        self._seen_from: int | None = None  # the camera's detection count when the scan started
        self._found: list[Any] = []  # the scan's detections, kept when it ends
        #: with ``generate_scan_specs_flag``: the scan's specs and one sub-area of interest per detection
        self.scan_specs: dict[str, Any] | None = None

    @property
    def repeat(self) -> bool:
        return bool(self.plan.extra.get("repeat"))

    def activation(self) -> str:
        path = [tuple(round(c, 3) for c in w) for w in self.plan.waypoints_neu]
        if self.lap % 2 == 1:
            path.reverse()
        params: dict[str, Any] = {"path": tuple(path)}
        if self.plan.speed_m_s:
            params["speed"] = self.plan.speed_m_s
        if self.plan.extra.get("follow_ground_altitude") is not None:  # flown above the measured ground
            params["follow_ground"] = float(self.plan.extra["follow_ground_altitude"])
        if self.plan.extra.get("loiter_mode"):  # waypoint scans: pass (fly through) or stop at each
            params["loiter_mode"] = self.plan.extra["loiter_mode"]
        return format_activation("FOLLOW_PATH", params)

    def _camera(self) -> Any:
        procs = self.ctx.layer.processes
        return procs.get("camera") if "camera" in procs else None

    def on_start(self) -> None:
        if not self.plan.waypoints_neu:
            raise ValueError(f"{self.node.id}: scan-ground has no waypoints (was it delegated?)")
        camera = self._camera()
        if camera is not None:
            self._seen_from = camera.label(str(self.node.id), self.plan.extra.get("data_uuid"))

    def on_end(self) -> None:
        camera = self._camera()
        if camera is not None:
            if self._seen_from is not None:
                self._found = camera.detections_of(str(self.node.id), self._seen_from)
            self._seen_from = None
            camera.label(None, None)
        if self.plan.extra.get("generate_scan_specs"):
            self.scan_specs = follow_up_specs(self.plan, self._found)

    def detections(self) -> list[Any]:
        """What the camera saw while this scan ran (:class:`~companion.sensing.camera.Detection`)."""
        camera = self._camera()
        if camera is None or self._seen_from is None:  # not started, or ended: what it kept
            return list(self._found)
        return camera.detections_of(str(self.node.id), self._seen_from)

    def flown(self) -> int:
        act = self.ctx.coordinator.activation("FOLLOW_PATH")
        if act is None or act.activation_id != self.activation_id:
            return self._flown
        self._flown = len(getattr(act.controller, "finished", ()))
        return self._flown

    _flown = 0

    def on_behavior_end(self, ended: Any) -> None:
        if self.repeat and ended.cause.value == "goal_achieved" and not self.finished:
            self.lap += 1
            self._flown = 0
            self.ctx.mark("patrol_lap", node=self.node.id, lap=self.lap)
            self._ask(self.activation())
            return
        super().on_behavior_end(ended)

    def enough_requested(self) -> Any:
        done = self.flown()
        status = super().enough_requested()
        self.skipped = list(range(done, len(self.plan.waypoints_neu)))  # not reached
        self.ctx.mark("scan_enoughed", node=self.node.id, flown=done, skipped=self.skipped)
        return status

    def progress(self) -> dict[str, Any]:
        n = len(self.plan.waypoints_neu)
        done = self.flown() if not self.finished else self._flown
        out: dict[str, Any] = {"waypoint": min(done + 1, n), "waypoints": n,
                               "text": f"waypoint {min(done + 1, n)} of {n}"}
        if self.repeat:
            out["lap"] = self.lap + 1
            out["text"] += f", pass {self.lap + 1}"
        if self.skipped:
            out["skipped"] = self.skipped
        return out


class ScanGround(LeafType):
    name = "scan-ground"
    figure = "Fig. 14a"
    doc = "Fly a scanning pattern over an area or along waypoints."
    params = (
        ParamSpec("area", "area", "Specification of the area to scan."),
        ParamSpec("waypoints_scan_flag", "bool", "If true scan flying the waypoints instead of area scan.",
                  default=False),
        ParamSpec("waypoints", "waypoints", "A list of waypoints ([lat, lon] or [lat, lon, alt])."),
        ParamSpec("loiter_mode", "qualitative", "Behavior at a waypoint (values ours: pass, stop).",
                  options=("pass", "stop")),
        ParamSpec("segment_flag", "bool", "Interpret the waypoints as a sequence of straight line segments."),
        ParamSpec("any_order_flag", "bool", "If true fly segments or waypoints in any order."),
        ParamSpec("speed", "qualitative", '"fast", "standard", "slow", unspecified.',
                  options=("fast", "standard", "slow", "unspecified"), default="unspecified"),
        ParamSpec("commanded_speed", "float", "Wanted speed in m/s (instead of speed; ours, as fly-to's).",
                  unit="m/s", minimum=0.0),
        ParamSpec("altitude", "qualitative", '"high", "standard", "low", unspecified.',
                  options=("high", "standard", "low", "unspecified"), default="unspecified"),
        ParamSpec("commanded_altitude", "float", "Scan altitude in m above home (instead of altitude; ours).",
                  unit="m", minimum=0.0),
        *follow_ground_params(),
        ParamSpec("repeat_flag", "bool",
                  "If this is true we are in patrol mode and repeat the scan of the area.", default=False),
        ParamSpec("sensor_type", "qualitative", '"artva", "laser", "camera".',
                  options=("artva", "laser", "camera"), default="camera"),
        ParamSpec("data_uuid", "string", "Used to identify the result of the scan."),
        ParamSpec("generate_scan_specs_flag", "bool", "If true generate scan specs and put in queue.",
                  default=False),
    )
    aliases = MappingProxyType({"generate_scan_spec_flag": "generate_scan_specs_flag"})
    info = NodeExecutionInfo(can_be_aborted=True, can_be_paused=True, can_be_enoughed=True)
    executor = ScanGroundExecutor
    has_speed = True

    def check_params(self, p: dict[str, Any]) -> None:
        for word, number in (("speed", "commanded_speed"), ("altitude", "commanded_altitude")):
            if number in p and p.get(word, "unspecified") != "unspecified":
                raise ParamError(f"given with {word} {p[word]!r}: give one of them", number)
        if p.get("waypoints_scan_flag"):
            if "waypoints" not in p:
                raise ParamError("required when waypoints_scan_flag is true", "waypoints")
            if "area" in p:
                raise ParamError("given, but waypoints_scan_flag is true (the waypoints are scanned)", "area")
            p.setdefault("loiter_mode", "pass")
            p.setdefault("segment_flag", False)
            p.setdefault("any_order_flag", False)
        else:
            if "area" not in p:
                raise ParamError("missing required parameter of scan-ground (or set waypoints_scan_flag)",
                                 "area")
            for name in _WAYPOINT_ONLY:
                if name in p:
                    raise ParamError("only with waypoints_scan_flag: true (Fig. 14a, *)", name)
        check_follow_ground(p)

    def check(self, node: TstNode, platform: Platform) -> list[str]:
        out = super().check(node, platform)
        at, p = where(node), node.params
        sensor = p.get("sensor_type", "camera")
        if sensor not in platform.sensors:
            out.append(f"{at}: missing sensor: sensor_type {sensor}, but platform {platform.name} has no "
                       f"{sensor} (sensors: {', '.join(sorted(platform.sensors)) or 'none'})")
        if "area" in p:
            local = area_to_local(p["area"], platform.home)
            outside = [i for i, v in enumerate(local) if platform.fence_reason(v)]
            if outside:
                n, e = local[outside[0]]
                out.append(f"{at}: area outside the fence: vertex {outside[0]} of the area "
                           f"({n:.1f} m north, {e:.1f} m east of home) and {len(outside) - 1} more: "
                           f"{platform.fence_reason((n, e))}")
        for i, wp in enumerate(p.get("waypoints") or ()):
            out += point_reasons(at, f"waypoint {i}", wp, platform, altitude=len(wp) == 3)
        if p.get("segment_flag") and len(p.get("waypoints") or ()) % 2:
            out.append(f"{at}: bad parameters: segment_flag needs an even number of waypoints (pairs)")
        return out

    def altitude_variables(self, node: TstNode, platform: Platform, problem: ConstraintProblem
                           ) -> list[tuple[str, str]]:
        alt = var(node, "altitude")
        if "commanded_altitude" in node.params:
            declare_number(problem, alt, node.params["commanded_altitude"], f"{node.id}.commanded_altitude")
            return [(alt, f"{node.id}.commanded_altitude")]
        allowed = qualitative_allowed(node.params.get("altitude"), dict(platform.altitudes))
        problem.qualitative(alt, dict(platform.altitudes), allowed=allowed, prefer="standard",
                            label=f"{node.id}.altitude in {{{', '.join(platform.altitudes)}}}")
        return [(alt, f"{node.id}.altitude")]

    def fix_values(self, node: TstNode, platform: Platform, solution: Solution, values: dict[str, Any]
                   ) -> None:
        default = platform.altitudes.get(str(values.get("altitude")), 0.0)
        values["altitude_m"] = solution.values.get(var(node, "altitude"), default)

    def plan(self, node: TstNode, platform: Platform, values: dict[str, Any], start: Vec3,
             speed_m_s: float | None) -> tuple[NodePlan, Vec3]:
        alt = float(values["altitude_m"])
        sensor = platform.sensors.get(values.get("sensor_type", "camera")) or Sensor()
        plan = NodePlan(str(node.id), node.type, speed_m_s=speed_m_s, altitude_m=alt)
        extra = plan.extra
        extra.update({"sensor_type": sensor.type, "fov_deg": sensor.fov_deg, "overlap": sensor.overlap,
                      "repeat": bool(values.get("repeat_flag", False)),
                      "speed": values.get("speed"), "altitude": values.get("altitude")})
        if values.get("data_uuid"):
            extra["data_uuid"] = values["data_uuid"]
        if values.get("follow_ground_flag"):
            extra["follow_ground_altitude"] = values.get("follow_ground_altitude")
        if values.get("generate_scan_specs_flag"):  # the executor adds a sub-area per detection
            extra.update({"generate_scan_specs": True, "home": [float(h) for h in platform.home[:2]]})
        if values.get("waypoints_scan_flag"):
            plan.waypoints_neu = self._waypoints(values, platform, start, alt, extra)
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
        plan = finish_plan(plan, start, platform, len(wps))
        # vertical moves between waypoints of different altitudes (waypoint scans with altitudes)
        plan.expected_s = (plan.expected_s or 0.0) + sum(
            vertical_time(b[2] - a[2], platform) for a, b in itertools.pairwise(wps))
        return plan, end

    @staticmethod
    def _waypoints(values: dict[str, Any], platform: Platform, start: Vec3, alt: float,
                   extra: dict[str, Any]) -> list[Vec3]:
        pts = [plan_point(p, platform.home) for p in values["waypoints"]]
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
        extra["order"] = order
        return [pts[i] for i in order]

    def expand(self, node: TstNode, platform: Platform, values: dict[str, Any], plan: NodePlan,
               speed_word: str | None = None) -> list[tuple[TstNode, NodePlan]]:
        """The scan's waypoints as ``fly-to`` children, in flight order.

        Each child flies straight (``fly_straight_line_flag``) to one waypoint at the scan altitude and
        speed; its ``position`` is a geopoint (``[lat, lon, alt above home]``). Ids are ``<scan id>.wp1``,
        ``.wp2``, ...
        """
        word = speed_word or values.get("speed")
        if word not in platform.speeds:
            word = "standard"
        root = node.root
        out: list[tuple[TstNode, NodePlan]] = []
        for k, wp in enumerate(plan.waypoints_neu, start=1):
            child_id = f"{node.id}.wp{k}"
            params = {"position": list(plan_point_to_geopoint(wp, platform.home)), "speed": word,
                      "fly_straight_line_flag": True}
            child = node.append_child(
                TstNode("fly-to", params=params, id=None if root.find(child_id) else child_id))
            out.append((child, self._child_plan(child, k - 1, plan, platform)))
        return out

    @staticmethod
    def _child_plan(child: TstNode, idx: int, scan: NodePlan, platform: Platform) -> NodePlan:
        """The plan of the ``idx``-th fly-to child of an expanded scan (its waypoint ``idx + 1``)."""
        wps = scan.waypoints_neu
        target = wps[min(idx, len(wps) - 1)]
        if idx == 0:
            length = (scan.length_m or 0.0) - path_length([w[:2] for w in wps])
        else:
            length = math.dist(wps[idx - 1][:2], target[:2])
        plan = NodePlan(str(child.id), child.type, speed_m_s=scan.speed_m_s, altitude_m=target[2],
                        position_neu=target, straight_line=True, length_m=length,
                        expected_s=leg_time(length, scan.speed_m_s or 1.0, platform.max_accel))
        plan.extra["expanded_from"] = scan.node_id
        plan.extra["waypoint"] = idx + 1
        return plan


def follow_up_specs(plan: NodePlan, detections: list[Any]) -> dict[str, Any]:
    """``generate_scan_specs_flag`` (Fig. 14a: "generate scan specs and put in queue"; Sec. VI-E: "a
    sub-area of interest to be subsequently scanned"): the scan's own specs (the plan's ``scan_specs`` of
    an area scan) and, per detection, a square sub-area one camera footprint wide centred on the object,
    with the parameters of the scan-ground node that would scan it (lat/lon around the plan's home, low
    and slow: a closer look). These are what ``GET /mission/detections`` returns with the detections."""
    home = plan.extra.get("home") or [0.0, 0.0]
    alt = plan.altitude_m or 0.0
    width, _ = footprint_size(max(alt, 1.0), plan.extra.get("fov_deg") or Sensor().fov_deg)
    half = max(width / 2.0, 1.0)
    areas = []
    for d in detections:
        n, e = float(d.position[0]), float(d.position[1])
        corners = [(n - half, e - half), (n - half, e + half), (n + half, e + half), (n + half, e - half)]
        area = [list(plan_point_to_geopoint((cn, ce, 0.0), home)[:2]) for cn, ce in corners]
        uuid = f"{plan.extra.get('data_uuid') or plan.node_id}/{d.object_id}"
        areas.append({"object": d.object_id, "class": d.cls, "center_ne": [n, e],
                      "side_m": round(2 * half, 3), "scan": {"type": "scan-ground", "params": {
                          "area": area, "altitude": "low", "speed": "slow",
                          "sensor_type": plan.extra.get("sensor_type", "camera"), "data_uuid": uuid}}})
    return {"specs": dict(plan.extra.get("scan_specs") or {}), "areas_of_interest": areas}


SCAN_GROUND = ScanGround()
