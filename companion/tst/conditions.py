"""IF and WHILE conditions (seed 000 Sec. III): belief queries, optionally negated.

A condition is a query of the belief memory (seed 001 Sec. 6.2.4), e.g. ``visible(?x), object(?x,
person)``: it holds when the query has a solution, and its first solution's bindings (``?x`` = 7) are
what the nodes under the IF or WHILE may refer to (a hover ``over: ?x``). ``not <query>`` holds when
the query has no solution ("scan until a person is seen": ``WHILE not visible(?x), object(?x,
person)``); it binds nothing.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from companion.behaviors.belief_syntax import Query, parse_query
from companion.behaviors.beliefs import BeliefMemory

NEGATION = "not "


@dataclass(frozen=True)
class Condition:
    text: str
    query: Query
    negated: bool = False

    def evaluate(self, beliefs: BeliefMemory) -> tuple[bool, dict[str, Any]]:
        """(holds, bindings of the first solution; empty when negated or false)."""
        first = beliefs.first(self.query)
        if self.negated:
            return first is None, {}
        return first is not None, dict(first or {})


def parse_condition(text: str) -> Condition:
    """A condition from its text; :class:`~companion.behaviors.belief_syntax.BeliefError` when malformed."""
    stripped = text.strip()
    if stripped.lower().startswith(NEGATION):
        return Condition(text, parse_query(stripped[len(NEGATION):]), negated=True)
    return Condition(text, parse_query(stripped))
