"""The memory of beliefs and its belief manager (seed 001 Sec. 5.2.2, 6.2.4).

"A belief is a proposition about the world that the robot believes is true" (Sec. 5.2.2), written
``predicate(object, value)`` or ``property(object)`` (the syntax: :mod:`companion.behaviors.belief_syntax`).
The belief manager (Sec. 6.2.4) offers the services *adding belief*, *removing belief* and
*consulting belief* and keeps the memory consistent: "attribute values defined for an object are
assumed to be mutually exclusive", so adding ``charge(92, empty)`` retracts ``charge(92, full)``;
a predicate whose values are not exclusive "must be treated as an exception", declared here with
``multi_valued``. One-argument beliefs (``visible(32)``) are plain set membership.

A consultation is a conjunction of patterns with ``?variables`` (``object(?x, battery), charge(?x, ?y)``)
answered with every binding (``[{"x": 92, "y": "full"}]``; variable names without the ``?``); a ground
query that holds answers ``[{}]``, one that fails ``[]``. Beliefs are indexed by predicate and by
(predicate, object), so a consultation over a few hundred beliefs takes microseconds.

Thread-safe: one lock guards the memory; every method is atomic. Bad input raises
:class:`BeliefError` and changes nothing.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Iterable, Iterator
from typing import Any

from companion.behaviors.belief_syntax import (
    Belief,
    BeliefError,
    Pattern,
    Query,
    Term,
    Var,
    belief_from_json,
    belief_to_json,
    bindings_to_json,
    check_term,
    parse_belief,
    parse_query,
    term_from_json,
    term_to_json,
)

__all__ = [
    "Belief", "BeliefError", "BeliefMemory", "Pattern", "Query", "Term", "Var", "belief_from_json",
    "belief_to_json", "bindings_to_json", "parse_belief", "parse_query", "term_from_json", "term_to_json",
]

log = logging.getLogger(__name__)

Bindings = dict[str, Term]


def _as_belief(belief: Belief | str) -> Belief:
    if isinstance(belief, Belief):
        return belief
    if isinstance(belief, str):
        return parse_belief(belief)
    raise BeliefError(f"belief: expected a Belief or its text, got {type(belief).__name__}")


def _as_query(query: Query | Belief | str) -> Query:
    if isinstance(query, Query):
        return query
    if isinstance(query, Belief):
        return Query.of(query)
    if isinstance(query, str):
        return parse_query(query)
    raise BeliefError(f"query: expected a Query or its text, got {type(query).__name__}")


def _as_object(obj: Any, what: str) -> Term:
    """An object given by a caller (JSON lists accepted) as a hashable term."""
    return check_term(term_from_json(obj) if isinstance(obj, list) else obj, what)


def _match(pattern: Any, term: Term, env: Bindings) -> Bindings | None:
    """Unify a pattern argument with a ground term under ``env``; the extended bindings or None.

    ``env`` is never modified: a new dict is returned only when a variable gets bound.
    """
    if isinstance(pattern, Var):
        if pattern.name in env:
            bound = env[pattern.name]
            return env if _same(bound, term) else None
        new = dict(env)
        new[pattern.name] = term
        return new
    if isinstance(pattern, tuple):
        if not isinstance(term, tuple) or len(term) != len(pattern):
            return None
        for p, t in zip(pattern, term, strict=True):
            sub = _match(p, t, env)
            if sub is None:
                return None
            env = sub
        return env
    return env if _same(pattern, term) else None


def _same(a: Any, b: Any) -> bool:
    """Term equality: numbers by value, strings by text, tuples element-wise; never str == number."""
    if isinstance(a, str) or isinstance(b, str):
        return isinstance(a, str) and isinstance(b, str) and a == b
    if isinstance(a, tuple) or isinstance(b, tuple):
        return (isinstance(a, tuple) and isinstance(b, tuple) and len(a) == len(b)
                and all(_same(x, y) for x, y in zip(a, b, strict=True)))
    return a == b


def _resolve(pattern: Any, env: Bindings) -> tuple[bool, Any]:
    """(ground?, value) of a pattern argument under ``env``."""
    if isinstance(pattern, Var):
        if pattern.name in env:
            return True, env[pattern.name]
        return False, None
    if isinstance(pattern, tuple):
        out = []
        for p in pattern:
            ok, v = _resolve(p, env)
            if not ok:
                return False, None
            out.append(v)
        return True, tuple(out)
    return True, pattern


class BeliefMemory:
    """The belief manager's store (Sec. 6.2.4): add / remove / consult, exclusive attribute values."""

    def __init__(self, multi_valued: Iterable[str] = ()) -> None:
        multi = frozenset(multi_valued)
        for p in multi:
            if not isinstance(p, str) or not p:
                raise BeliefError(f"multi_valued: {p!r} is not a predicate name")
        self._multi = multi
        self._lock = threading.Lock()
        self._all: dict[Belief, None] = {}  # insertion-ordered set
        self._by_pred: dict[str, dict[Belief, None]] = {}
        self._by_obj: dict[tuple[str, Any], dict[Belief, None]] = {}
        self._version = 0

    # --- properties ---------------------------------------------------------------------------------
    @property
    def multi_valued(self) -> frozenset[str]:
        """The predicates whose values are not mutually exclusive."""
        return self._multi

    @property
    def version(self) -> int:
        """Bumped on every change (an add that changes nothing does not bump it)."""
        with self._lock:
            return self._version

    def __len__(self) -> int:
        with self._lock:
            return len(self._all)

    def __contains__(self, belief: object) -> bool:
        if not isinstance(belief, (Belief, str)):
            return False
        b = _as_belief(belief)
        with self._lock:
            return b in self._all

    # --- adding and removing belief ---------------------------------------------------------------------
    def add(self, belief: Belief | str) -> list[Belief]:
        """Add a belief; return the beliefs it retracted (its object's previous exclusive value)."""
        b = _as_belief(belief)
        with self._lock:
            retracted = self._add_locked(b)
        if retracted:
            log.debug("added %s, retracted %s", b, ", ".join(map(str, retracted)))
        return retracted

    def add_all(self, beliefs: Iterable[Belief | str]) -> list[Belief]:
        """Add several beliefs atomically (all parsed first: one bad one and nothing changes)."""
        parsed = [_as_belief(b) for b in beliefs]
        retracted: dict[Belief, None] = {}
        with self._lock:
            added: set[Belief] = set()
            for b in parsed:
                held = b in self._all
                retracted.update((r, None) for r in self._add_locked(b) if r not in added)
                if not held:
                    added.add(b)
            return [r for r in retracted if r not in self._all]

    def remove(self, belief: Belief | str) -> bool:
        """Remove a belief; True if it was held."""
        b = _as_belief(belief)
        with self._lock:
            if b not in self._all:
                return False
            self._remove_locked(b)
            self._version += 1
            return True

    def forget(self, predicate: str, obj: Term) -> list[Belief]:
        """Remove every belief ``predicate(obj, ...)`` (e.g. a charge that is no longer known)."""
        key = (predicate, _as_object(obj, "forget"))
        with self._lock:
            gone = list(self._by_obj.get(key, {}))
            for b in gone:
                self._remove_locked(b)
            if gone:
                self._version += 1
        return gone

    def clear(self) -> None:
        """Forget everything."""
        with self._lock:
            if self._all:
                self._version += 1
            self._all.clear()
            self._by_pred.clear()
            self._by_obj.clear()

    def _add_locked(self, b: Belief) -> list[Belief]:
        if b in self._all:
            return []
        retracted: list[Belief] = []
        if len(b.args) == 2 and b.predicate not in self._multi:
            for old in list(self._by_obj.get((b.predicate, b.obj), ())):
                if len(old.args) == 2:
                    self._remove_locked(old)
                    retracted.append(old)
        self._all[b] = None
        self._by_pred.setdefault(b.predicate, {})[b] = None
        self._by_obj.setdefault((b.predicate, b.obj), {})[b] = None
        self._version += 1
        return retracted

    def _remove_locked(self, b: Belief) -> None:
        del self._all[b]
        bucket = self._by_pred[b.predicate]
        del bucket[b]
        if not bucket:
            del self._by_pred[b.predicate]
        key = (b.predicate, b.obj)
        bucket = self._by_obj[key]
        del bucket[b]
        if not bucket:
            del self._by_obj[key]

    # --- consulting belief ------------------------------------------------------------------------------
    def consult(self, query: Query | Belief | str) -> list[Bindings]:
        """Every binding of the query's variables that makes all its patterns hold."""
        q = _as_query(query)
        with self._lock:
            return [dict(env) for env in self._solve(q.patterns, 0, {})]

    def holds(self, query: Query | Belief | str) -> bool:
        """True if the query has at least one answer."""
        q = _as_query(query)
        with self._lock:
            env = next(self._solve(q.patterns, 0, {}), None)
        return env is not None

    def first(self, query: Query | Belief | str) -> Bindings | None:
        """The first answer, or None."""
        q = _as_query(query)
        with self._lock:
            env = next(self._solve(q.patterns, 0, {}), None)
        return None if env is None else dict(env)

    def _solve(self, patterns: tuple[Pattern, ...], i: int, env: Bindings) -> Iterator[Bindings]:
        if i == len(patterns):
            yield env
            return
        pat = patterns[i]
        ground, obj = _resolve(pat.args[0], env)
        if ground:
            try:
                candidates = self._by_obj.get((pat.predicate, obj), ())
            except TypeError:  # an unhashable binding cannot be an object
                candidates = ()
        else:
            candidates = self._by_pred.get(pat.predicate, ())
        n = len(pat.args)
        for b in tuple(candidates):
            if len(b.args) != n:
                continue
            e: Bindings | None = env
            for p, t in zip(pat.args, b.args, strict=True):
                e = _match(p, t, e) if e is not None else None
                if e is None:
                    break
            if e is not None:
                yield from self._solve(patterns, i + 1, e)

    def value(self, predicate: str, obj: Term) -> Term | None:
        """The exclusive value of ``predicate(obj, ?)``, or None if there is none."""
        if predicate in self._multi:
            raise BeliefError(f"value: {predicate} is multi-valued; use values()")
        vals = self.values(predicate, obj)
        return vals[0] if vals else None

    def values(self, predicate: str, obj: Term) -> list[Term]:
        """All values of ``predicate(obj, ?)`` (at most one unless the predicate is multi-valued)."""
        key = (predicate, _as_object(obj, "values"))
        with self._lock:
            return [b.args[1] for b in self._by_obj.get(key, ()) if len(b.args) == 2]

    def beliefs(self, predicate: str | None = None) -> list[Belief]:
        """The beliefs held (of one predicate if given), in the order they were added."""
        with self._lock:
            if predicate is None:
                return list(self._all)
            return list(self._by_pred.get(predicate, ()))

    def to_json(self) -> list[dict[str, Any]]:
        """Every belief as ``{"predicate", "args", "text"}``."""
        return [belief_to_json(b) for b in self.beliefs()]

    def __repr__(self) -> str:
        return f"BeliefMemory({len(self)} beliefs, version {self.version})"

