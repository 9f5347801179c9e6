"""An irreducible conflicting set of constraints (for the rejection of seed 000 Sec. III-A).

Seed 000 Sec. III-A: the constraints of a TST "should be checked for consistency with a constraint
solver"; when they are not consistent, the delegation is refused and the user must learn *which*
constraints disagree. :func:`minimal_conflict` finds a subset of the constraints that is infeasible
while every proper subset of it is feasible (an irreducible infeasible subset), given only a
feasibility oracle over subsets.

It is QuickXplain (U. Junker, AAAI 2004), the divide-and-conquer form of the deletion filter: the
candidates are halved, a half that is not needed (the background plus the other half is infeasible
already) is dropped whole, and otherwise both halves are searched with the other's contribution in the
background. It needs O(k log(n / k)) oracle calls for a conflict of k out of n constraints instead of
the deletion filter's n; the result is the same kind of set (irreducible, not necessarily the smallest).
The constraints are first split into independent components (those sharing no variable); infeasibility
always lies inside one of them, so only that one is searched.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable, Sequence

log = logging.getLogger(__name__)

#: ``feasible(indices)``: whether the constraints with these indices (together) can be satisfied.
Oracle = Callable[[Sequence[int]], bool]


def components(variables: Sequence[Iterable[int]]) -> list[list[int]]:
    """Group constraint indices into components connected through shared variables.

    ``variables[i]`` are the variable columns of constraint ``i``. Components are listed in the order of
    their first constraint, each with its indices ascending.
    """
    parent = list(range(len(variables)))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    owner: dict[int, int] = {}
    for i, cols in enumerate(variables):
        for c in cols:
            j = owner.setdefault(c, i)
            ri, rj = find(i), find(j)
            if ri != rj:
                parent[max(ri, rj)] = min(ri, rj)
    groups: dict[int, list[int]] = {}
    for i in range(len(variables)):
        groups.setdefault(find(i), []).append(i)
    return list(groups.values())


def minimal_conflict(candidates: Sequence[int], feasible: Oracle,
                     background: Sequence[int] = ()) -> list[int]:
    """An irreducible infeasible subset of ``candidates``, given ``background`` constraints that hold.

    ``background + candidates`` must be infeasible and ``background`` alone feasible. Returns the
    candidate indices ascending; ``[]`` if ``background + candidates`` is feasible after all (the oracle
    then disagrees with the caller, which is logged).
    """
    base = list(background)
    cands = list(candidates)
    if feasible(base + cands):
        log.warning("conflict search: the %d constraints are feasible together", len(base) + len(cands))
        return []
    calls = 0

    def check(subset: list[int]) -> bool:
        nonlocal calls
        calls += 1
        return feasible(subset)

    def qx(background: list[int], delta: bool, cs: list[int]) -> list[int]:
        # A set X of cs, minimal, with background + X infeasible (background + cs is infeasible).
        if delta and not check(background):
            return []
        if len(cs) == 1:
            return cs
        half = len(cs) // 2
        c1, c2 = cs[:half], cs[half:]
        d2 = qx(background + c1, bool(c1), c2)
        d1 = qx(background + d2, bool(d2), c1)
        return d1 + d2

    found = sorted(qx(base, False, cands))
    log.debug("conflict search: %d of %d constraints in conflict after %d solver calls",
              len(found), len(cands), calls + 1)
    return found
