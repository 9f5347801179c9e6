"""``check()`` and ``get_constraints()`` of the delegation over a whole tree (seed 000 Sec. III-A, Fig. 3).

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
adds the node's duration too (``duration_at_speed`` with the planned path length). What a leaf checks and
constrains is its task type's (:class:`~companion.tst.leaves.base.LeafType`); control nodes' durations and
the relations between nodes are here.
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING, Any

from companion.tst.constraints import ConstraintProblem, Linear
from companion.tst.leaves.common import var, where
from companion.tst.params import LinearRelation
from companion.tst.plan import NodePlan
from companion.tst.platform import Platform
from companion.tst.registry import leaf_type
from companion.tst.tree import CONTROL_TYPES, ControlType, TstNode

if TYPE_CHECKING:
    from companion.behaviors.catalog import BehaviorCatalog

__all__ = ["check", "executive_reasons", "get_constraints", "get_relations", "upper_bounded", "var", "where"]

#: The behavior a leaf's executor activates for the bulk of its time (the executive layer's time-out applies
#: to each activation: a repeated scan restarts FOLLOW_PATH for each pass).
LEAF_BEHAVIORS = {"fly-to": "GO_TO_POINT", "scan-ground": "FOLLOW_PATH", "take-off": "TAKE_OFF",
                  "land": "LAND"}  # WAIT's time-out is a margin over its duration

#: The platform quantities a relation may name (``duration <= endurance_left``).
PLATFORM_QUANTITIES = ("endurance_left", "max_speed", "ceiling", "floor", "takeoff_altitude")


# --- check() -----------------------------------------------------------------------------------------
def check(node: TstNode, platform: Platform) -> list[str]:
    """Seed 000 Sec. III-A ``check()``: why ``platform`` cannot run ``node`` itself (empty: it can).

    Control nodes (S, IF, WHILE) are runnable here, their children checked on their own; a C node whose
    branches would fly at the same time is not (:func:`concurrency_reasons`). A leaf needs the platform to
    have its executor, then its task type's own check (:meth:`~companion.tst.leaves.base.LeafType.check`).
    """
    if node.type in CONTROL_TYPES:
        return concurrency_reasons(node)
    if node.type not in platform.tasks:
        return [f"{where(node)}: unknown task: platform {platform.name} has no executor for '{node.type}' "
                f"(it runs: {', '.join(platform.tasks)})"]
    return leaf_type(node.type).check(node, platform)


def flying_leaves(node: TstNode) -> list[TstNode]:
    """The leaves under ``node`` that move the vehicle (:attr:`~companion.tst.leaves.base.LeafType.flies`)."""
    out = []
    for n in node.iter():
        if n.is_leaf_task:
            try:
                flies = leaf_type(n.type).flies
            except (KeyError, ValueError):
                flies = True  # an unknown type: check() refuses it anyway
            if flies:
                out.append(n)
    return out


def concurrency_reasons(node: TstNode) -> list[str]:
    """A C node runs its branches at once on one vehicle with one flight-command queue: two branches that
    both fly would replace each other's behavior (the second evicts the first), so it is refused."""
    if node.control is not ControlType.C:
        return []
    flying = [(child, leaves) for child in node.children if (leaves := flying_leaves(child))]
    if len(flying) < 2:
        return []
    names = ", ".join(f"{child.id} ({leaves[0].id}: {leaves[0].type})" for child, leaves in flying)
    return [f"{where(node)}: concurrent flight: branches {names} would fly at the same time on one vehicle "
            "(one flight behavior at a time: put them in an S node, or keep one flying branch)"]


# --- what the executive layer allows -------------------------------------------------------------------
@functools.lru_cache(maxsize=1)
def _bundled_catalog() -> BehaviorCatalog:
    from companion.behaviors.catalog import load_catalog

    return load_catalog()


def executive_time_limit(catalog: BehaviorCatalog | None, behavior: str, expected_s: float) -> float | None:
    """The longest one activation of ``behavior`` expected to take ``expected_s`` may run before the
    executive layer ends it with ``time_out`` (None: no limit). A catalog time-out planned from the
    behavior's motion (``timeout: {factor, margin_s}``, :mod:`companion.behaviors.timeouts`) grows with
    the plan: factor x ``expected_s`` + margin; a fixed ``timeout`` is that number. The bundled catalog
    when ``catalog`` is None."""
    cat = catalog if catalog is not None else _bundled_catalog()
    try:
        d = cat.get(behavior)
    except (KeyError, ValueError):
        return None
    if d.category != "goal_based":
        return None
    if d.timeout_plan:
        return d.timeout_plan.get("factor", 1.0) * expected_s + d.timeout_plan.get("margin_s", 0.0)
    return d.timeout_s


def executive_reasons(root: TstNode, plans: dict[str, NodePlan], catalog: BehaviorCatalog | None = None
                      ) -> list[str]:
    """Why the executive layer would end a planned leaf before it is done: its expected time (the plan's
    ``expected_s``, the time model delegation checks the endurance with) above its behavior's time-out."""
    out = []
    for n in root.iter():
        behavior = LEAF_BEHAVIORS.get(n.type)
        plan = plans.get(str(n.id))
        if behavior is None or plan is None or not n.is_leaf_task or plan.expected_s is None:
            continue
        limit = executive_time_limit(catalog, behavior, plan.expected_s)
        if limit is not None and plan.expected_s > limit:
            out.append(f"{where(n)}: longer than the executive layer allows: {plan.expected_s:.0f} s "
                       f"expected (path {plan.length_m or 0:.0f} m at {plan.speed_m_s or 0:g} m/s), and "
                       f"{behavior} times out after {limit:g} s (behavior catalog): split the task or fly it "
                       "faster")
    return out


def upper_bounded(node: TstNode) -> dict[str, float]:
    """The solver objective that takes each parameter bounded only from above by its own relation
    (``duration: "duration <= endurance_left"``) to that bound, not to its lower limit (0 s)."""
    out: dict[str, float] = {}
    for pname, value in node.params.items():
        if not isinstance(value, LinearRelation):
            continue
        own = dict(value.coefficients).get(pname, 0.0)
        if (value.op == "<=" and own > 0) or (value.op == ">=" and own < 0):
            out[var(node, pname)] = -1.0
    return out


# --- get_constraints() ------------------------------------------------------------------------------
def get_constraints(node: TstNode, platform: Platform, problem: ConstraintProblem,
                    plan: NodePlan | None = None, fixed: dict[str, Any] | None = None) -> None:
    """Seed 000 Sec. III-A ``get_constraints()``: add the platform's constraints on ``node`` to ``problem``.

    Without ``plan`` (before the expansion): the parameters' constraints, the speed limit, altitude floor
    and ceiling. With ``plan`` (after it): the speeds again (qualitative ones still free, the others as
    ``fixed``: parameter -> value) and the node's duration ``<id>.duration`` from the planned path
    (``duration_at_speed``), which the endurance constraint sums. Control nodes add their duration from
    their children's (S: the sum; C, IF: at least each child's; WHILE: one pass of the body).
    """
    if node.type in CONTROL_TYPES:
        if plan is not None:
            _control_duration(node, problem)
        return
    leaf_type(node.type).get_constraints(node, platform, problem, plan, fixed)


def _control_duration(node: TstNode, problem: ConstraintProblem) -> None:
    nid = str(node.id)
    total = var(node, "duration")
    problem.variable(total)
    kids = [var(c, "duration") for c in node.children]
    if node.control is ControlType.S:
        problem.add(Linear({total: 1.0, **{k: -1.0 for k in kids}}, "==", 0.0),
                    label=f"{nid}.duration = sum of its children's", definition=True)
    elif node.control is ControlType.WHILE:
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
    if platform.takeoff_altitude is not None:
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
