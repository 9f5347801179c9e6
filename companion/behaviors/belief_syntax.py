"""The text form of beliefs and belief queries (seed 001 Sec. 5.2.2, 6.2.4).

A belief is a ground predicate with one or two arguments: ``property(object)`` (``visible(32)``) or
``predicate(object, value)`` (``charge(92, full)``, ``position(57, (3.0, 4.5, 0.0))``). A query is a
conjunction of such patterns separated by commas at the top level, where arguments may be
``?variables``: ``object(?x, battery), charge(?x, ?y)``.

Terms (the Python values used for arguments and bindings):

* symbols (``self``, ``battery``, ``point_A``) and double-quoted strings (``"front door"``) are both
  ``str``; a string whose characters form an identifier prints bare, so ``"full"`` and ``full`` are the
  same term (the text form round-trips: ``parse_belief(str(b)) == b``);
* numbers are ``int`` or finite ``float`` (``92`` and ``92.0`` are equal, as in Python);
* tuples of terms, ``(3.0, 4.5, 0.0)``; ``()`` is the empty tuple and ``(x)`` a one-element tuple.

Errors are :class:`BeliefError` (a ``ValueError``) whose message says what was parsed, the 1-based
column and what went wrong: ``query: column 14: expected ')' or ',' but found 'charge'``.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

#: A ground term: a symbol or string, a number, or a tuple of terms.
Term = str | int | float | tuple

_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_NUMBER = re.compile(r"[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?")
_WS = re.compile(r"\s+")
_STRING_ESCAPES = {'"': '"', "\\": "\\", "n": "\n", "t": "\t"}


class BeliefError(ValueError):
    """A malformed belief, query or term; the message says what and where."""


@dataclass(frozen=True)
class Var:
    """A query variable, written ``?name``."""

    name: str

    def __str__(self) -> str:
        return f"?{self.name}"


def check_term(term: Any, what: str = "term") -> Term:
    """``term`` itself if it is a ground term (lists are not: see :func:`term_from_json`)."""
    if isinstance(term, bool) or term is None:
        raise BeliefError(f"{what}: {term!r} is not a term (symbol, string, number or tuple)")
    if isinstance(term, str):
        return term
    if isinstance(term, int):
        return term
    if isinstance(term, float):
        if not math.isfinite(term):
            raise BeliefError(f"{what}: {term!r} is not a finite number")
        return term
    if isinstance(term, tuple):
        for item in term:
            check_term(item, what)
        return term
    raise BeliefError(f"{what}: {term!r} ({type(term).__name__}) is not a term")


def format_term(term: Any) -> str:
    """The text form of a term (or of a pattern argument holding :class:`Var`)."""
    if isinstance(term, str):
        return term if _IDENT.fullmatch(term) else json.dumps(term, ensure_ascii=False)
    if isinstance(term, tuple):
        return "(" + ", ".join(format_term(t) for t in term) + ")"
    if isinstance(term, float):
        return repr(term + 0.0)  # -0.0 prints as 0.0
    return str(term)


def _check_args(predicate: str, args: tuple, what: str) -> None:
    if not isinstance(predicate, str) or not _IDENT.fullmatch(predicate):
        raise BeliefError(f"{what}: predicate {predicate!r} is not an identifier")
    if not 1 <= len(args) <= 2:
        raise BeliefError(f"{what}: {predicate} has {len(args)} arguments; a belief is property(object) "
                          "or predicate(object, value)")


@dataclass(frozen=True)
class Belief:
    """A ground proposition the robot believes: ``property(object)`` or ``predicate(object, value)``.

    Lists among the arguments are turned into tuples, so a belief built from JSON is hashable.
    """

    predicate: str
    args: tuple

    def __post_init__(self) -> None:
        args = tuple(term_from_json(a) if isinstance(a, list) else a for a in self.args)
        object.__setattr__(self, "args", args)
        _check_args(self.predicate, args, "belief")
        for a in args:
            if _contains_var(a):
                raise BeliefError(f"belief: variable {a} in a belief (only queries have variables)")
            check_term(a, "belief")

    @property
    def obj(self) -> Term:
        """The object the belief is about (its first argument)."""
        return self.args[0]

    @property
    def value(self) -> Term | None:
        """The attribute value of ``predicate(object, value)``; None for ``property(object)``."""
        return self.args[1] if len(self.args) == 2 else None

    def __str__(self) -> str:
        return f"{self.predicate}(" + ", ".join(format_term(a) for a in self.args) + ")"


def _contains_var(term: Any) -> bool:
    if isinstance(term, Var):
        return True
    return isinstance(term, tuple) and any(_contains_var(t) for t in term)


@dataclass(frozen=True)
class Pattern:
    """One conjunct of a query: a predicate whose arguments may hold :class:`Var`."""

    predicate: str
    args: tuple

    def __post_init__(self) -> None:
        _check_args(self.predicate, self.args, "query")

    def __str__(self) -> str:
        return f"{self.predicate}(" + ", ".join(format_term(a) for a in self.args) + ")"


@dataclass(frozen=True)
class Query:
    """A conjunction of patterns (Sec. 6.2.4 "belief expressions that may include variables")."""

    patterns: tuple[Pattern, ...]

    @property
    def variables(self) -> tuple[str, ...]:
        """Variable names (without ``?``) in order of first appearance."""
        seen: dict[str, None] = {}

        def walk(t: Any) -> None:
            if isinstance(t, Var):
                seen.setdefault(t.name, None)
            elif isinstance(t, tuple):
                for x in t:
                    walk(x)

        for p in self.patterns:
            for a in p.args:
                walk(a)
        return tuple(seen)

    def __str__(self) -> str:
        return ", ".join(str(p) for p in self.patterns)

    @classmethod
    def of(cls, belief: Belief) -> Query:
        """The ground query that holds exactly when ``belief`` does."""
        return cls((Pattern(belief.predicate, belief.args),))


# --- the tokenizer and recursive-descent parser ----------------------------------------------------------


@dataclass(frozen=True)
class _Token:
    kind: str  # ident, number, string, var, '(', ')', ',', end
    text: str
    value: Any
    col: int  # 1-based


def _tokens(text: str, what: str) -> list[_Token]:
    out: list[_Token] = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        m = _WS.match(text, i)
        if m:
            i = m.end()
            continue
        col = i + 1
        if c in "(),":
            out.append(_Token(c, c, None, col))
            i += 1
        elif c == "?":
            m = _IDENT.match(text, i + 1)
            if not m:
                raise BeliefError(f"{what}: column {col}: '?' must be followed by a variable name")
            out.append(_Token("var", text[i:m.end()], Var(m.group()), col))
            i = m.end()
        elif c == '"':
            i, value = _string(text, i, what)
            out.append(_Token("string", text[col - 1:i], value, col))
        elif c.isdigit() or (c in "+-." and i + 1 < n and (text[i + 1].isdigit() or text[i + 1] == ".")):
            m = _NUMBER.match(text, i)
            if not m or (m.end() < n and (text[m.end()].isalnum() or text[m.end()] in "_.")):
                end = m.end() if m else i + 1
                while end < n and (text[end].isalnum() or text[end] in "_."):
                    end += 1
                raise BeliefError(f"{what}: column {col}: bad number {text[i:end]!r}")
            s = m.group()
            number: float | int = float(s) if any(ch in s for ch in ".eE") else int(s)
            if isinstance(number, float) and not math.isfinite(number):
                raise BeliefError(f"{what}: column {col}: number {s!r} is out of range")
            out.append(_Token("number", s, number, col))
            i = m.end()
        else:
            m = _IDENT.match(text, i)
            if not m:
                raise BeliefError(f"{what}: column {col}: unknown character {c!r}")
            out.append(_Token("ident", m.group(), m.group(), col))
            i = m.end()
    out.append(_Token("end", "", None, n + 1))
    return out


def _string(text: str, i: int, what: str) -> tuple[int, str]:
    """Parse the double-quoted string starting at ``text[i]``; return (end index, value)."""
    chars: list[str] = []
    j = i + 1
    while j < len(text):
        c = text[j]
        if c == '"':
            return j + 1, "".join(chars)
        if c == "\\":
            esc = text[j + 1] if j + 1 < len(text) else ""
            if esc not in _STRING_ESCAPES:
                raise BeliefError(f"{what}: column {j + 1}: unknown escape '\\{esc}' in a string")
            chars.append(_STRING_ESCAPES[esc])
            j += 2
            continue
        chars.append(c)
        j += 1
    raise BeliefError(f"{what}: column {i + 1}: string not closed (missing '\"')")


def _describe(tok: _Token) -> str:
    return "the end" if tok.kind == "end" else repr(tok.text)


class _Parser:
    def __init__(self, text: str, what: str, allow_vars: bool) -> None:
        if not isinstance(text, str):
            raise BeliefError(f"{what}: expected text, got {type(text).__name__}")
        self.what = what
        self.allow_vars = allow_vars
        self.toks = _tokens(text, what)
        self.pos = 0

    def peek(self) -> _Token:
        return self.toks[self.pos]

    def take(self) -> _Token:
        tok = self.toks[self.pos]
        if tok.kind != "end":
            self.pos += 1
        return tok

    def fail(self, tok: _Token, expected: str) -> BeliefError:
        return BeliefError(f"{self.what}: column {tok.col}: expected {expected} but found {_describe(tok)}")

    def expect(self, kind: str, expected: str) -> _Token:
        tok = self.take()
        if tok.kind != kind:
            raise self.fail(tok, expected)
        return tok

    def atom(self) -> tuple[str, tuple, int]:
        """``name(term, ...)``: the predicate, its arguments and its column."""
        name = self.expect("ident", "a predicate name")
        self.expect("(", f"'(' after {name.text!r}")
        args = [self.term()]
        while self.peek().kind == ",":
            self.take()
            args.append(self.term())
        self.expect(")", "')' or ','")
        if not 1 <= len(args) <= 2:
            raise BeliefError(f"{self.what}: column {name.col}: {name.text} has {len(args)} arguments; "
                              "a belief is property(object) or predicate(object, value)")
        return name.text, tuple(args), name.col

    def term(self) -> Any:
        tok = self.take()
        if tok.kind in ("ident", "number", "string"):
            return tok.value
        if tok.kind == "var":
            if not self.allow_vars:
                raise BeliefError(f"{self.what}: column {tok.col}: variable {tok.text} in a belief "
                                  "(only queries have variables)")
            return tok.value
        if tok.kind == "(":
            items: list[Any] = []
            if self.peek().kind == ")":
                self.take()
                return ()
            items.append(self.term())
            while self.peek().kind == ",":
                self.take()
                if self.peek().kind == ")":  # trailing comma: (1, 2,)
                    break
                items.append(self.term())
            self.expect(")", "')' or ',' in a tuple")
            return tuple(items)
        raise self.fail(tok, "a term (symbol, number, \"string\", tuple" +
                        (" or ?variable)" if self.allow_vars else ")"))

    def end(self) -> None:
        tok = self.peek()
        if tok.kind != "end":
            raise self.fail(tok, "the end" + (" or ','" if self.allow_vars else ""))


@lru_cache(maxsize=512)
def _parse_belief(text: str) -> Belief:
    p = _Parser(text, "belief", allow_vars=False)
    if p.peek().kind == "end":
        raise BeliefError("belief: empty")
    name, args, _ = p.atom()
    p.end()
    return Belief(name, args)


@lru_cache(maxsize=512)
def _parse_query(text: str) -> Query:
    p = _Parser(text, "query", allow_vars=True)
    if p.peek().kind == "end":
        raise BeliefError("query: empty")
    patterns = []
    while True:
        name, args, _ = p.atom()
        patterns.append(Pattern(name, args))
        if p.peek().kind != ",":
            break
        p.take()
    p.end()
    return Query(tuple(patterns))


def parse_belief(text: str) -> Belief:
    """Parse a ground belief: ``charge(92, full)``. Raises :class:`BeliefError`."""
    if not isinstance(text, str):
        raise BeliefError(f"belief: expected text, got {type(text).__name__}")
    return _parse_belief(text)


def parse_query(text: str) -> Query:
    """Parse a conjunction of patterns with ``?variables``. Raises :class:`BeliefError`."""
    if not isinstance(text, str):
        raise BeliefError(f"query: expected text, got {type(text).__name__}")
    return _parse_query(text)


# --- JSON ----------------------------------------------------------------------------------------------


def term_to_json(term: Term) -> Any:
    """A term as JSON-able data: tuples become lists."""
    if isinstance(term, tuple):
        return [term_to_json(t) for t in term]
    return check_term(term)


def term_from_json(data: Any) -> Term:
    """The term for JSON data: lists become tuples; objects, booleans and null are refused."""
    if isinstance(data, list):
        return tuple(term_from_json(d) for d in data)
    return check_term(data)


def belief_to_json(belief: Belief) -> dict[str, Any]:
    """``{"predicate": ..., "args": [...], "text": ...}``."""
    return {"predicate": belief.predicate, "args": [term_to_json(a) for a in belief.args],
            "text": str(belief)}


def belief_from_json(data: Any) -> Belief:
    """A belief from ``{"predicate": ..., "args": [...]}`` or from its text form (a JSON string)."""
    if isinstance(data, str):
        return parse_belief(data)
    if not isinstance(data, dict) or "predicate" not in data or "args" not in data:
        raise BeliefError("belief: expected text or an object with 'predicate' and 'args'")
    args = data["args"]
    if not isinstance(args, list):
        raise BeliefError("belief: 'args' must be a list")
    return Belief(data["predicate"], tuple(term_from_json(a) for a in args))


def bindings_to_json(bindings: list[dict[str, Term]]) -> list[dict[str, Any]]:
    """Query answers as JSON-able data (tuples become lists)."""
    return [{k: term_to_json(v) for k, v in b.items()} for b in bindings]
