"""The solver call of the TST constraint check and its outcome (seed 000 Sec. III-A).

Seed 000 Sec. III-A asks for the constraints of a tree to be "checked for consistency with a constraint
solver"; :func:`run_milp` is that solver: a mixed-integer linear program from sparse rows, solved by
HiGHS through ``scipy.optimize.milp``. :class:`Solution` is what
:meth:`companion.tst.constraints.ConstraintProblem.solve` returns.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from scipy.optimize import OptimizeResult

#: One row ``lower <= sum(coef * x[column]) <= upper``: (coefficients by column, lower, upper).
Row = tuple[dict[int, float], float, float]


@dataclass
class Solution:
    """The outcome of the constraint check of a tree.

    ``ok``: the constraints are consistent; then ``values`` holds every variable (qualitative ones at
    their chosen option's value) and ``choices`` the option chosen per qualitative variable. Otherwise
    ``conflict`` lists the labels of the constraints in conflict, in the order they were posed: an
    irreducible conflicting set (each one is needed for the conflict) for every independent group of
    constraints in conflict; empty when the solver failed for another reason (see ``message``).
    ``details`` are the same with their reasons. ``message`` is one
    line for the user (``accepted: ...`` or ``rejected: ...``); ``seconds`` the time the check took.
    """

    ok: bool
    values: dict[str, float] = field(default_factory=dict)
    choices: dict[str, str] = field(default_factory=dict)
    conflict: list[str] = field(default_factory=list)
    details: list[str] = field(default_factory=list)
    message: str = ""
    seconds: float = 0.0

    def __str__(self) -> str:
        return self.message


def run_milp(cost: np.ndarray, integer: Sequence[bool], rows: Sequence[Row]) -> OptimizeResult:
    """Minimise ``cost @ x`` subject to ``rows``; integer columns are binaries, the others free.

    Columns past ``len(integer)`` (auxiliary ones) are continuous and >= 0. Status 0: optimal, 2:
    infeasible, 3: unbounded (scipy's codes). SciPy is imported at the first check, not at start-up (half
    of a companion's start-up imports).
    """
    from scipy.optimize import Bounds, LinearConstraint, milp
    from scipy.sparse import csr_matrix

    n = len(cost)
    integrality = np.zeros(n, dtype=np.uint8)
    integrality[: len(integer)] = np.asarray(integer, dtype=np.uint8)
    lb = np.full(n, -math.inf)
    ub = np.full(n, math.inf)
    lb[integrality == 1], ub[integrality == 1] = 0.0, 1.0
    lb[len(integer):] = 0.0
    constraints = []
    if rows:
        data = [v for r, _, _ in rows for v in r.values()]
        cols = [k for r, _, _ in rows for k in r]
        ptr = np.cumsum([0] + [len(r) for r, _, _ in rows])
        a = csr_matrix((data, cols, ptr), shape=(len(rows), n))
        constraints.append(LinearConstraint(a, [r[1] for r in rows], [r[2] for r in rows]))
    return milp(cost, integrality=integrality, bounds=Bounds(lb, ub), constraints=constraints)
