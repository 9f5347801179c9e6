"""A leaf task type in one object: parameters, check, constraints, plan, expansion, executor (seed 000 Sec.
III-A, Fig. 3-5).

Seed 000 Sec. III-A: during delegation the TST Execution System calls ``check()`` ("whether the execution
can be performed with the provided input parameters as well as checking whether other platform-specific
requirements are met"), ``get_constraints()`` ("constraints [...] which are platform-specific and should
be checked for consistency with a constraint solver") and ``expand()`` of each node's executor; the
executor then runs the node (Fig. 3), reporting Fig. 4's execution information and Fig. 5's status.

A :class:`LeafType` gathers all of that for one task type; a subclass sets the class attributes and
overrides the hooks it needs, and the instance is registered (:func:`companion.tst.registry.register`).
The defaults serve most types:

* :meth:`LeafType.validate`: the parameters of a mission node checked against :attr:`LeafType.params`,
  defaults filled in, then the type's own rules (:meth:`LeafType.check_params`);
* :meth:`LeafType.check`: follow-ground flight needs a range sensor;
* :meth:`LeafType.get_constraints`: the speed (types with :attr:`LeafType.has_speed`), altitude variables
  (:meth:`LeafType.altitude_variables`) under the platform's ceiling and floor, a free ``duration``; after
  the plan, the node's duration from its path length;
* :meth:`LeafType.plan`: nothing to fly, no time (override it); :meth:`LeafType.expand`: no children.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, ClassVar

from companion.tst.constraints import ConstraintProblem, Linear, Solution
from companion.tst.executor import ExecContext, TstExecutor
from companion.tst.leaves.common import declare_number, qualitative_allowed, speed_reasons, var, where
from companion.tst.param_spec import ParamSpec
from companion.tst.params import ParamError, is_free
from companion.tst.plan import NodePlan, Vec3
from companion.tst.platform import Platform
from companion.tst.status import NodeExecutionInfo

if TYPE_CHECKING:
    from companion.tst.tree import TstNode

__all__ = ["LeafType", "ParamSpec"]


class LeafType:
    """One leaf task type (see the module docstring). Subclasses set the class attributes."""

    #: The task type's name in mission files (``fly-to``).
    name: ClassVar[str] = ""
    #: Where the paper defines it (``Fig. 12a``), or ``ours``.
    figure: ClassVar[str] = ""
    doc: ClassVar[str] = ""
    #: Its input parameters (Fig. 11a-14a).
    params: ClassVar[tuple[ParamSpec, ...]] = ()
    #: Other spellings of parameter names -> the name.
    aliases: ClassVar[Mapping[str, str]] = MappingProxyType({})
    #: Fig. 4: whether a running node of this type can be aborted, paused, enoughed.
    info: ClassVar[NodeExecutionInfo] = NodeExecutionInfo()
    #: The executor class that runs a node of this type (Fig. 3).
    executor: ClassVar[type[TstExecutor]]
    #: A speed the solver fixes (``speed`` / ``commanded_speed``), flown in :attr:`NodePlan.speed_m_s`.
    has_speed: ClassVar[bool] = False
    #: The platform's altitude floor bounds this type's altitude variables (not a take-off's).
    has_floor: ClassVar[bool] = True
    #: A node of this type moves the vehicle (a flight behavior): two such branches of one C node would
    #: replace each other on the one queue, so delegation refuses them.
    flies: ClassVar[bool] = True

    # --- parameters (the mission file loader) ----------------------------------------------------------
    def param(self, name: str) -> ParamSpec | None:
        return next((p for p in self.params if p.name == name), None)

    @property
    def param_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.params)

    def check_params(self, p: dict[str, Any]) -> None:
        """The rules relating the parameters (one given with another, defaults that depend on others);
        raise :class:`~companion.tst.params.ParamError` naming the parameter. By default none."""
        return None

    def validate(self, raw: Mapping[str, Any] | None) -> dict[str, Any]:
        """Checked parameters with defaults filled in; raises :class:`ParamError` naming the parameter."""
        out: dict[str, Any] = {}
        for key, value in dict(raw or {}).items():
            name = self.aliases.get(key, key) if isinstance(key, str) else key
            spec = self.param(name) if isinstance(name, str) else None
            if spec is None:
                known = ", ".join(self.param_names) or "none"
                raise ParamError(f"unknown parameter of {self.name} (known: {known})", str(key))
            if name in out:
                raise ParamError(f"given twice (as {key} and {name})", str(key))
            out[name] = spec.normalize(value)
        for spec in self.params:
            if spec.name in out:
                continue
            if spec.required:
                raise ParamError(f"missing required parameter of {self.name}", spec.name)
            if spec.default is not None:
                out[spec.name] = spec.default
        self.check_params(out)
        return out

    # --- delegation: check() and get_constraints() (Sec. III-A) ----------------------------------------
    def check(self, node: TstNode, platform: Platform) -> list[str]:
        """Why ``platform`` cannot run ``node`` (empty: it can). Overrides add to this."""
        out = speed_reasons(node, platform) if self.has_speed else []
        if node.params.get("follow_ground_flag") and not platform.range_sensor:
            out.append(f"{where(node)}: no range sensor: follow_ground_flag needs a ground range sensor and "
                       f"platform {platform.name} has none")
        return out

    def altitude_variables(self, node: TstNode, platform: Platform, problem: ConstraintProblem
                           ) -> list[tuple[str, str]]:
        """Declare the node's altitude variables; returns (variable, label) of each, for the ceiling and
        floor. By default none."""
        return []

    def get_constraints(self, node: TstNode, platform: Platform, problem: ConstraintProblem,
                        plan: NodePlan | None = None, fixed: Mapping[str, Any] | None = None) -> None:
        """Add the platform's constraints on ``node`` to ``problem`` (see
        :func:`companion.tst.delegation_checks.get_constraints`)."""
        nid = str(node.id)
        p = node.params
        speed = var(node, "speed")
        if self.has_speed:
            if "commanded_speed" in p:
                given = p["commanded_speed"]
                note = "given"
                if plan is not None:
                    chosen = (fixed or {}).get("commanded_speed", given)
                    if chosen is not given and not isinstance(given, int | float):
                        note = f"chosen by delegation from {given}"  # an interval or relation, not given
                    given = chosen
                declare_number(problem, speed, given, f"{nid}.commanded_speed",
                               lo=min(platform.speeds.values()), hi=platform.max_speed[0], note=note)
            else:
                allowed = qualitative_allowed(p.get("speed"), dict(platform.speeds))
                problem.qualitative(speed, dict(platform.speeds), allowed=allowed, prefer="standard",
                                    label=f"{nid}.speed in {{{', '.join(platform.speeds)}}}")
            top, src = platform.max_speed
            problem.add(Linear({speed: 1.0}, "<=", top),
                        label=f"{nid}.speed <= max speed {top:g} m/s ({src})")
        if plan is None:
            self._altitudes(node, platform, problem)
            if is_free(p.get("duration")):
                declare_number(problem, var(node, "duration"), p["duration"], f"{nid}.duration", lo=0.0)
            return
        total = var(node, "duration")
        legs = int(plan.extra.get("legs", 0))
        fixed_s = plan.expected_s or 0.0
        if self.has_speed and plan.length_m:
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

    def _altitudes(self, node: TstNode, platform: Platform, problem: ConstraintProblem) -> None:
        nid = str(node.id)
        ceiling, c_src = platform.ceiling
        floor, f_src = platform.floor
        p = node.params
        names = self.altitude_variables(node, platform, problem)
        if p.get("follow_ground_flag") and "follow_ground_altitude" in p:
            fga = var(node, "follow_ground_altitude")
            declare_number(problem, fga, p["follow_ground_altitude"], f"{nid}.follow_ground_altitude", lo=0.0)
            names.append((fga, f"{nid}.follow_ground_altitude"))
        for name, label in names:
            if ceiling != float("inf"):
                problem.add(Linear({name: 1.0}, "<=", ceiling),
                            label=f"{label} <= ceiling {ceiling:g} m ({c_src})")
            if self.has_floor and floor > 0:
                problem.add(Linear({name: 1.0}, ">=", floor), label=f"{label} >= floor {floor:g} m ({f_src})")

    def fix_values(self, node: TstNode, platform: Platform, solution: Solution, values: dict[str, Any]
                   ) -> None:
        """Add to ``values`` (the node's parameters, free ones fixed) what the plan needs of the solution
        besides them; by default nothing."""
        return None

    # --- the plan and expand() ---------------------------------------------------------------------------
    def plan(self, node: TstNode, platform: Platform, values: dict[str, Any], start: Vec3,
             speed_m_s: float | None) -> tuple[NodePlan, Vec3]:
        """The node's :class:`NodePlan` from ``start`` and where it leaves the vehicle.

        ``values`` are the node's parameters with every free one fixed; ``speed_m_s`` the fixed speed in
        m/s for types with :attr:`has_speed`. By default: nothing to fly, no time (an operator ends it).
        """
        plan = NodePlan(str(node.id), node.type, expected_s=0.0, length_m=0.0)
        plan.extra["until"] = "operator"
        plan.extra.update({k: v for k, v in values.items() if isinstance(v, str | bool | int | float)})
        return plan, start

    def expand(self, node: TstNode, platform: Platform, values: dict[str, Any], plan: NodePlan,
               speed_word: str | None = None) -> list[tuple[TstNode, NodePlan]]:
        """Sec. III-A ``expand()``: the children appended to ``node``, each with its plan. By default none."""
        return []

    # --- execution (Fig. 3) -------------------------------------------------------------------------------
    def make_executor(self, node: TstNode, plan: NodePlan, ctx: ExecContext) -> TstExecutor:
        return self.executor(node, plan, ctx)
