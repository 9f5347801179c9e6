"""Task Specification Trees (seed 000 Sec. III, Fig. 2-5): the tree, its parameters and constraints, the
mission YAML format, and the executor execution information (Fig. 4) and status (Fig. 5).

Modules, one job each:

* :mod:`companion.tst.params`: parameter values and constraints (interval, qualitative values, linear
  relation), geopoints and area polygons and their conversion to the local frame;
* :mod:`companion.tst.task_types`: the registry ``TASK_TYPES`` of leaf task types and their parameters as
  Fig. 11a-14a list them;
* :mod:`companion.tst.tree`: ``TstNode`` (S, C, IF, WHILE and leaves), ids, walking, ``append_child``;
* :mod:`companion.tst.spec`: the mission YAML / JSON format, validated with errors naming file, line, field;
* :mod:`companion.tst.status`: ``NodeExecutionInfo`` (Fig. 4), ``NodeExecutionStatus`` (Fig. 5) and the
  ``ExecutorLifecycle`` state machine (Fig. 3);
* :mod:`companion.tst.composite`: the Fig. 5 status of S, C and IF nodes derived from their children;
* :mod:`companion.tst.constraints` (with :mod:`~companion.tst.linear`, :mod:`~companion.tst.milp`,
  :mod:`~companion.tst.conflict`): the consistency check of a tree's constraints (Sec. III-A) with a MILP
  (scipy's HiGHS), fixing free parameters or naming the constraints in conflict;
* :mod:`companion.tst.platform`: ``Platform``, what a vehicle can do (fence, limits, speeds, sensors,
  endurance), from ``mission_specs/platform_*.yaml``;
* :mod:`companion.tst.delegation` (with :mod:`~companion.tst.delegation_checks` for ``check()`` and
  ``get_constraints()`` and :mod:`~companion.tst.delegation_plan` for ``NodePlan`` and ``expand()``):
  delegation of a tree to a platform (Sec. III-A, Fig. 3), accepted with a plan per node or rejected
  with the reasons.
"""
