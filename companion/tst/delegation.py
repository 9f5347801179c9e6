"""Delegation of a Task Specification Tree to a platform (seed 000 Sec. III-A, Fig. 3).

Seed 000 Sec. III: "A platform can accept the delegation of a TST - a mission or a part of a mission - if
it can execute the root node of that TST"; Sec. III-A: during delegation the TST Execution System calls
``expand()``, ``get_constraints()`` and ``check()`` of each executor, and the constraints "should be checked
for consistency with a constraint solver". :func:`delegate` does that for a whole tree, on a copy of the
mission:

1. ``check()`` of every node (:func:`~companion.tst.delegation_checks.check`): unknown task, a point or
   area outside the fence, a bad altitude, a speed above the envelope's limit, a missing sensor,
   follow-ground without a range sensor, a fly-to without a position, a take-off without an altitude, a
   C node whose branches both fly;
2. ``get_constraints()`` of every leaf, solved once (:class:`~companion.tst.constraints.ConstraintProblem`,
   HiGHS): fixes the free parameters (qualitative speeds and altitudes, intervals, relations) or names
   the constraints in conflict;
3. the plan of every leaf with those values (:func:`~companion.tst.delegation_plan.plan_leaf`: scan
   patterns, waypoint orders, path lengths; the vehicle's position followed through the tree), and a
   fence check of every straight leg;
4. the durations with the real path lengths and the mission-wide ``mission duration <= endurance_left``
   constraint, solved again (qualitative speeds still free, so the solver flies only as many legs
   faster as the endurance needs);
5. every leaf's expected time against what the executive layer allows (its behavior's catalog
   time-out: a plan the executive layer would kill mid-flight is refused here, naming the node);
6. ``expand()`` of every leaf (a scan-ground's waypoints become ``fly-to`` children), the free parameters
   of the copy replaced by their values.

A parameter bounded only from above by its relation (``duration: "duration <= endurance_left"``) is
taken to that bound (then checked against the endurance like any duration), never to its lower limit.

It either accepts, with every node's :class:`~companion.tst.plan.NodePlan`, or rejects with the
reasons. Durations over control nodes: S sums its children, C and IF take the longest child, WHILE counts
one pass of its body; hover without a duration, external-velocity and operator requests count 0 s.
"""

from __future__ import annotations

import copy
import itertools
import logging
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from companion.tst.constraints import ConstraintError, ConstraintProblem, Linear, Solution
from companion.tst.delegation_checks import (
    check,
    declare_platform,
    executive_reasons,
    get_constraints,
    get_relations,
    upper_bounded,
    var,
    where,
)
from companion.tst.delegation_plan import NEU, NodePlan, expand, expand_with_plans, plan_leaf
from companion.tst.params import Interval, LinearRelation, Qualitative, is_free
from companion.tst.platform import Platform
from companion.tst.registry import leaf_type
from companion.tst.spec import Mission
from companion.tst.tree import ControlType, TstNode

if TYPE_CHECKING:
    from companion.behaviors.catalog import BehaviorCatalog

__all__ = ["ENDURANCE_LABEL", "Delegation", "NodePlan", "check", "delegate", "expand", "get_constraints"]

log = logging.getLogger(__name__)

#: The label of the mission-wide endurance constraint.
ENDURANCE_LABEL = "mission duration <= endurance_left"


@dataclass
class Delegation:
    """The outcome of :func:`delegate`: accepted with a plan per node, or rejected with the reasons.

    ``mission`` is the delegated copy (expanded, free parameters fixed, when accepted); ``fixed`` maps
    ``<node id>.<parameter>`` to the value delegation chose for each free parameter; ``expected_s`` is
    the estimated duration of the whole mission; ``solution`` the last constraint check.
    """

    accepted: bool
    reasons: list[str]
    mission: Mission
    plans: dict[str, NodePlan]
    solution: Solution | None
    seconds: float
    fixed: dict[str, Any] = field(default_factory=dict)
    expected_s: float | None = None
    endurance_s: float | None = None
    platform: str = ""

    @property
    def waypoints(self) -> int:
        """Waypoints of all scan-ground nodes."""
        return sum(len(p.waypoints_neu) for p in self.plans.values())

    def to_dict(self) -> dict[str, Any]:
        """JSON: the verdict, the reasons, and the expanded tree with each node's ``plan``."""
        tree = self.mission.root.to_dict()
        if self.accepted:
            _attach(tree, self.plans)
        out: dict[str, Any] = {
            "accepted": self.accepted, "mission": self.mission.name, "platform": self.platform,
            "reasons": list(self.reasons), "seconds": round(self.seconds, 6),
            "nodes": sum(1 for _ in self.mission.root.iter()), "waypoints": self.waypoints,
            "expected_s": None if self.expected_s is None else round(self.expected_s, 3),
            "endurance_s": self.endurance_s, "fixed": dict(self.fixed), "tree": tree}
        if self.solution is not None and not self.solution.ok:
            out["conflict"] = list(self.solution.details)
        return out


def _attach(tree: Any, plans: dict[str, NodePlan]) -> None:
    if isinstance(tree, dict):
        if isinstance(tree.get("id"), str) and tree["id"] in plans and "type" in tree:
            tree["plan"] = plans[tree["id"]].to_dict()
        for key in ("children", "then", "else", "body", "expansion"):
            _attach(tree.get(key), plans)
    elif isinstance(tree, list):
        for item in tree:
            _attach(item, plans)


def delegate(mission: Mission, platform: Platform, catalog: BehaviorCatalog | None = None) -> Delegation:
    """Delegate ``mission`` to ``platform``: check, constrain, solve, plan, expand (module docstring).

    ``catalog``: the executive layer's behavior catalog whose time-outs the plan must fit (None: the
    bundled one)."""
    t0 = time.perf_counter()
    mission = copy.deepcopy(mission)
    root = mission.root
    nodes = list(root.iter())

    def reject(reasons: list[str], solution: Solution | None = None) -> Delegation:
        seconds = time.perf_counter() - t0
        log.info("delegation of %s to %s rejected in %.1f ms: %s", mission.name, platform.name,
                 seconds * 1e3, "; ".join(reasons))
        return Delegation(False, reasons, mission, {}, solution, seconds, endurance_s=platform.endurance_s,
                          platform=platform.name)

    reasons = [r for n in nodes for r in check(n, platform)]
    if reasons:
        return reject(reasons)
    # 2. the parameters' constraints, solved once: fixes the free parameters
    problem = ConstraintProblem()
    ids = {str(n.id): n for n in nodes}
    try:
        declare_platform(problem, platform)
        for n in nodes:
            get_constraints(n, platform, problem)
        reasons = [r for n in nodes for r in get_relations(n, problem, ids)]
    except ConstraintError as exc:
        return reject([f"bad parameters: {exc}"])
    if reasons:
        return reject(reasons)
    upper = {k: v for n in nodes for k, v in upper_bounded(n).items() if k in problem.variables}
    first = _solve(problem, upper)
    if not first.ok:
        if upper and not first.conflict:
            return reject([f"bad parameters: a relation bounds {', '.join(upper)} only from above and "
                           f"nothing bounds it: {first.message}"], first)
        return reject(_conflict_reasons(first, {}), first)
    values = {str(n.id): _fixed_values(n, platform, first) for n in nodes if n.is_leaf_task}
    # 3. plans with those values, the position followed through the tree
    plans: dict[str, NodePlan] = {}
    reasons = []
    _plan(root, platform, values, (0.0, 0.0, 0.0), plans, reasons)
    if reasons:
        return reject(reasons)
    # 4. durations with the real path lengths, under the endurance
    problem = ConstraintProblem()
    try:
        declare_platform(problem, platform)
        for n in reversed(nodes):  # children before their parents
            fixed = {"commanded_speed": plans[str(n.id)].speed_m_s} if str(n.id) in plans else None
            get_constraints(n, platform, problem, plans.get(str(n.id)) or NodePlan(str(n.id), n.type), fixed)
        problem.add(Linear({var(root, "duration"): 1.0, "endurance_left": -1.0}, "<=", 0.0),
                    label=ENDURANCE_LABEL, reason="sum of the durations of the tree")
    except ConstraintError as exc:
        return reject([f"bad parameters: {exc}"])
    second = _solve(problem)
    if not second.ok:
        fastest = _fastest(root, platform, plans)
        return reject(_conflict_reasons(second, {"fastest": fastest, "endurance": platform.endurance_s,
                                                 "source": platform.endurance_source}), second)
    # 5. the speeds the endurance asked for, then the expansion
    fixed_out: dict[str, Any] = {}
    for n in nodes:
        if n.is_leaf_task:
            _apply(n, platform, second, values[str(n.id)], plans[str(n.id)], fixed_out)
    _plan(root, platform, values, (0.0, 0.0, 0.0), plans, reasons, keep_speeds=True)
    for n in nodes:
        if n.is_leaf_task:
            word = values[str(n.id)].get("speed")
            kids = expand_with_plans(n, platform, values[str(n.id)], plans[str(n.id)], word)
            for child, child_plan in kids:
                plans[str(child.id)] = child_plan
    reasons = executive_reasons(root, plans, catalog)
    if reasons:
        return reject(reasons, second)
    expected = _tree_seconds(root, {k: p.expected_s or 0.0 for k, p in plans.items()})
    seconds = time.perf_counter() - t0
    log.info("delegation of %s to %s accepted in %.1f ms: %d nodes, expected %.1f s of %.1f s endurance",
             mission.name, platform.name, seconds * 1e3, sum(1 for _ in root.iter()), expected,
             platform.endurance_s)
    return Delegation(True, [], mission, plans, second, seconds, fixed_out, expected, platform.endurance_s,
                      platform.name)


def _solve(problem: ConstraintProblem, maximize: dict[str, float] | None = None) -> Solution:
    """Solve preferring the ``standard`` option of every qualitative choice (speeds, altitudes); the
    parameters in ``maximize`` (bounded only from above by their relation) go to their bound."""
    try:
        return problem.solve(prefer="standard", maximize=list(maximize or ()))
    except ConstraintError:  # no qualitative variable has a "standard" option (none was declared)
        return problem.solve(maximize=list(maximize or ()))


def _fixed_values(node: TstNode, platform: Platform, sol: Solution) -> dict[str, Any]:
    """The node's parameters with the free ones fixed from the first solution."""
    out = dict(node.params)
    for key, value in node.params.items():
        if key == "speed" and (is_free(value) or value == "unspecified"):
            out[key] = sol.choices.get(var(node, "speed"), "standard")
        elif key == "altitude" and (is_free(value) or value == "unspecified"):
            out[key] = sol.choices.get(var(node, "altitude"), "standard")
        elif isinstance(value, Interval | LinearRelation):
            out[key] = sol.values.get(var(node, key))
    leaf = leaf_type(node.type)
    leaf.fix_values(node, platform, sol, out)
    if leaf.has_speed and "commanded_speed" not in node.params:
        out.setdefault("speed", sol.choices.get(var(node, "speed"), "standard"))
    return out


def _speed(node: TstNode, platform: Platform, values: dict[str, Any]) -> float | None:
    if not leaf_type(node.type).has_speed:
        return None
    if values.get("commanded_speed") is not None:
        return float(values["commanded_speed"])
    return platform.speeds.get(values.get("speed", "standard"), platform.speeds.get("standard"))


def _plan(node: TstNode, platform: Platform, values: dict[str, dict[str, Any]], start: NEU,
          plans: dict[str, NodePlan], reasons: list[str], keep_speeds: bool = False) -> NEU:
    """Plan the subtree from ``start``; returns the position it ends at. Fence breaches go to ``reasons``."""
    if node.is_leaf_task:
        v = values[str(node.id)]
        try:
            plan, end = plan_leaf(node, platform, v, start, _speed(node, platform, v))
        except ValueError as exc:
            reasons.append(f"{where(node)}: bad parameters: {exc}")
            return start
        if not keep_speeds:
            legs = [start, *plan.waypoints_neu] if plan.waypoints_neu else [start, end]
            for a, b in itertools.pairwise(legs):
                why = platform.segment_reason(a[:2], b[:2])
                if why:
                    reasons.append(f"{where(node)}: flight outside the fence: the leg from ({a[0]:.1f}, "
                                   f"{a[1]:.1f}) to ({b[0]:.1f}, {b[1]:.1f}) m (north, east of home): {why}")
                    break
        plans[str(node.id)] = plan
        return end
    pos = start
    ends = []
    for child in node.children:
        parallel = node.control in (ControlType.C, ControlType.IF)  # each child starts where the node does
        child_end = _plan(child, platform, values, start if parallel else pos, plans, reasons, keep_speeds)
        pos = child_end
        ends.append(child_end)
    plans.setdefault(str(node.id), NodePlan(str(node.id), node.type))
    return ends[0] if node.control is ControlType.IF and ends else pos


def _apply(node: TstNode, platform: Platform, sol: Solution, values: dict[str, Any], plan: NodePlan,
           fixed_out: dict[str, Any]) -> None:
    """Write the chosen values into the node (the copy) and its values; record them in ``fixed_out``."""
    choice = sol.choices.get(var(node, "speed"))
    if choice is not None:
        values["speed"] = choice
        if "speed" not in node.params and "commanded_speed" not in node.params:  # absent: free
            node.params["speed"] = choice
            fixed_out[f"{node.id}.speed"] = choice
    for key, value in list(node.params.items()):
        if key == "speed" and (isinstance(value, Qualitative) or value == "unspecified") and choice:
            node.params[key] = choice
        elif key == "altitude" and (isinstance(value, Qualitative) or value == "unspecified"):
            node.params[key] = values["altitude"]
        elif isinstance(value, Interval | LinearRelation):
            node.params[key] = values[key]
        else:
            continue
        fixed_out[f"{node.id}.{key}"] = node.params[key]


def _tree_seconds(node: TstNode, leaf_s: dict[str, float]) -> float:
    """The duration of a subtree: S sums, C and IF take the longest child, WHILE one pass."""
    if node.is_leaf_task:
        return leaf_s.get(str(node.id), 0.0)
    kids = [_tree_seconds(c, leaf_s) for c in node.children]
    return sum(kids) if node.control in (ControlType.S, ControlType.WHILE) else max(kids, default=0.0)


def _fastest(root: TstNode, platform: Platform, plans: dict[str, NodePlan]) -> float:
    """The mission's duration with every qualitative speed at its fastest allowed option."""
    top = platform.max_speed[0]
    leaf_s: dict[str, float] = {}
    for n in root.iter():
        plan = plans.get(str(n.id))
        if plan is None or not n.is_leaf_task:
            continue
        v0 = plan.speed_m_s
        v = v0
        if v and "commanded_speed" not in n.params:
            allowed = n.params.get("speed")
            opts = (list(allowed.options) if isinstance(allowed, Qualitative)
                    else [str(allowed)] if allowed in platform.speeds else list(platform.speeds))
            v = max((platform.speeds[o] for o in opts if platform.speeds[o] <= top), default=v)
        if v and v0 and plan.length_m:
            legs = int(plan.extra.get("legs", 0))
            base = (plan.expected_s or 0.0) - plan.length_m / v0 - legs * v0 / platform.max_accel
            leaf_s[str(n.id)] = base + plan.length_m / v + legs * v / platform.max_accel
        else:
            leaf_s[str(n.id)] = plan.expected_s or 0.0
    return _tree_seconds(root, leaf_s)


def _conflict_reasons(sol: Solution, endurance: dict[str, Any]) -> list[str]:
    """The reasons of a rejected constraint check, tagged for the user."""
    if not sol.conflict:
        return [f"the constraint check failed: {sol.message}"]
    conflict = "; ".join(sol.details)
    if ENDURANCE_LABEL in sol.conflict and endurance:
        return [f"mission longer than the endurance: {endurance['fastest']:.0f} s at the fastest allowed "
                f"speeds, {endurance['endurance']:.0f} s left ({endurance['source']}); constraints in "
                f"conflict: {conflict}"]
    if any(".altitude" in label or "follow_ground_altitude" in label for label in sol.conflict):
        return [f"bad altitude: constraints in conflict: {conflict}"]
    if any(".speed" in label for label in sol.conflict):
        return [f"bad speed: constraints in conflict: {conflict}"]
    return [f"constraints in conflict: {conflict}"]
