"""Task Specification Trees (seed 000 Sec. III, Fig. 2-5): the tree, its parameters and constraints, the
mission YAML format, and the executor execution information (Fig. 4) and status (Fig. 5).

Modules, one job each:

* :mod:`companion.tst.params`: parameter values and constraints (interval, qualitative values, linear
  relation), geopoints and area polygons and their conversion to the local frame;
* :mod:`companion.tst.registry`: the registry of leaf task types (``register``, ``leaf_type``), the one
  place a task type's name is looked up;
* :mod:`companion.tst.leaves`: one module per leaf task type (Fig. 11-14 and ours), each holding its
  parameters (:mod:`~companion.tst.param_spec`), ``check()``, ``get_constraints()``, plan, ``expand()``,
  Fig. 4 flags and executor (:mod:`~companion.tst.executor`); importing this package registers them;
* :mod:`companion.tst.planning`: the scan-ground planners (coverage pattern, waypoint order, routes
  inside a region);
* :mod:`companion.tst.tree`: ``TstNode`` (S, C, IF, WHILE and leaves), ids, walking, ``append_child``;
* :mod:`companion.tst.spec`: the mission YAML / JSON format, validated with errors naming file, line, field;
* :mod:`companion.tst.status`: ``NodeExecutionInfo`` (Fig. 4), ``NodeExecutionStatus`` (Fig. 5) and the
  ``ExecutorLifecycle`` state machine (Fig. 3);
* :mod:`companion.tst.constraints` (with :mod:`~companion.tst.linear`, :mod:`~companion.tst.milp`,
  :mod:`~companion.tst.conflict`): the consistency check of a tree's constraints (Sec. III-A) with a MILP
  (scipy's HiGHS), fixing free parameters or naming the constraints in conflict;
* :mod:`companion.tst.platform`: ``Platform``, what a vehicle can do (fence, limits, speeds, sensors,
  endurance), from ``mission_specs/platform_*.yaml``;
* :mod:`companion.tst.delegation` (with :mod:`~companion.tst.delegation_checks` for ``check()`` and
  ``get_constraints()`` and :mod:`~companion.tst.delegation_plan` for ``NodePlan`` and ``expand()``):
  delegation of a tree to a platform (Sec. III-A, Fig. 3), accepted with a plan per node or rejected
  with the reasons;
* :mod:`companion.tst.execution`: the TST execution system that runs a delegated tree (Fig. 3).
"""

# The bundled leaf task types register themselves here, so that any use of the package sees them.
from companion.tst import leaves as leaves

