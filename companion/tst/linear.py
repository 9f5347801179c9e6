"""Linear constraints over named task parameters and their text form (seed 000 Sec. III, III-A).

Seed 000 Sec. III: a task's parameters "can either be specified directly or constrained through a
general constraint language", e.g. "the flight velocity and altitude for a particular task can be
constrained to be within specific intervals, allowing these parameters to be adapted to fuel and time
constraints". This module is the linear part of that language: a :class:`Linear` constraint
``sum(coef * variable) op rhs`` with ``op`` one of ``<=``, ``>=``, ``==``, and its text form::

    n3.duration + n5.duration <= endurance_left
    2 * n3.altitude >= 5
    n4.altitude - 0.5 * (n3.altitude + n5.altitude) == 0
    n7.duration <= endurance_left / 2

Names are task parameters (``n3.speed``) and platform quantities (``max_speed``): a letter or ``_``
followed by letters, digits and ``_``, in parts joined by ``.`` or ``-`` (``n3.fly-to.speed``); a ``-``
joins only when a letter or ``_`` follows it, so ``x-1`` is ``x`` minus 1 but ``a-b`` is one name:
write a subtraction of two names with spaces (``a - b``). Numbers are decimals with an optional
exponent. Products need a number on one side and division a number below; anything else is a
non-linear term and is refused. Errors are :class:`ConstraintError` naming the text and the 1-based
column: ``constraint 'a * b <= 3': column 1: non-linear term 'a * b'``.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field

#: The comparison operators of a :class:`Linear` constraint.
OPERATORS = ("<=", ">=", "==")

#: A variable name, as in the module docstring.
NAME = re.compile(r"[A-Za-z_]\w*(?:\.\w+|-[A-Za-z_]\w*)*")

_TOKEN = re.compile(
    r"\s*(?:(?P<num>(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)"
    rf"|(?P<name>{NAME.pattern})"
    r"|(?P<cmp><=|>=|==|=<|=>|!=|<>|<|>|=)"
    r"|(?P<op>[-+*/()]))"
)


class ConstraintError(ValueError):
    """A constraint that cannot be read or posed; the message says which and where."""


@dataclass(frozen=True)
class Linear:
    """``sum(terms[name] * name) op rhs``: one linear constraint (seed 000 Sec. III)."""

    terms: Mapping[str, float]
    op: str
    rhs: float
    _frozen_terms: tuple[tuple[str, float], ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.op not in OPERATORS:
            raise ConstraintError(f"unknown operator {self.op!r} (use <=, >= or ==)")
        if not math.isfinite(self.rhs):
            raise ConstraintError(f"right-hand side {self.rhs!r} is not a finite number")
        for name, coef in self.terms.items():
            if not isinstance(name, str) or not NAME.fullmatch(name):
                raise ConstraintError(f"bad variable name {name!r}")
            if not math.isfinite(coef):
                raise ConstraintError(f"coefficient of {name} is {coef!r}, not a finite number")
        object.__setattr__(self, "terms", {n: float(c) for n, c in self.terms.items() if c != 0})
        object.__setattr__(self, "rhs", float(self.rhs))
        if not self.terms:
            raise ConstraintError("the constraint has no variables")

    def __str__(self) -> str:
        return f"{format_terms(self.terms)} {self.op} {self.rhs:g}"


def format_terms(terms: Mapping[str, float]) -> str:
    """``{"a": 1, "b": -2}`` -> ``"a - 2 * b"``."""
    out: list[str] = []
    for name, coef in terms.items():
        mag = abs(coef)
        text = name if mag == 1 else f"{mag:g} * {name}"
        if not out:
            out.append(text if coef > 0 else f"-{text}")
        else:
            out.append(("+ " if coef > 0 else "- ") + text)
    return " ".join(out)


@dataclass
class _Expr:
    """A linear expression while parsing: ``sum(terms) + const``; start/end are 0-based columns."""

    terms: dict[str, float]
    const: float
    start: int
    end: int

    def scaled(self, k: float, start: int, end: int) -> _Expr:
        return _Expr({n: c * k for n, c in self.terms.items()}, self.const * k, start, end)


class _Parser:
    """Recursive descent over ``expr cmp expr`` (grammar in :func:`parse_linear`)."""

    def __init__(self, text: str, where: str) -> None:
        self.text = text
        self.where = where
        self.tokens: list[tuple[str, str, int, int]] = []  # (kind, text, start, end)
        pos = 0
        while pos < len(text):
            m = _TOKEN.match(text, pos)
            if m is None or m.end() == pos:
                rest = text[pos:]
                if not rest.strip():
                    break
                col = pos + len(rest) - len(rest.lstrip())
                self.fail(col, f"unexpected character {text[col]!r}")
            assert m is not None  # fail() raised otherwise
            kind = m.lastgroup or ""
            self.tokens.append((kind, m.group(kind), m.start(kind), m.end(kind)))
            pos = m.end()
        self.i = 0

    def fail(self, col: int, msg: str) -> None:
        raise ConstraintError(f"{self.where} {self.text!r}: column {col + 1}: {msg}")

    def peek(self) -> tuple[str, str, int, int] | None:
        return self.tokens[self.i] if self.i < len(self.tokens) else None

    def parse(self) -> Linear:
        if not self.tokens:
            self.fail(0, "empty constraint")
        left = self.expr()
        tok = self.peek()
        if tok is None:
            self.fail(len(self.text), "no comparison operator (use <=, >= or ==)")
        assert tok is not None
        kind, op, start, _ = tok
        if kind != "cmp":
            self.fail(start, f"expected an operator but found {op!r}")
        if op not in OPERATORS:
            self.fail(start, f"unknown operator {op!r} (use <=, >= or ==)")
        self.i += 1
        right = self.expr()
        tok = self.peek()
        if tok is not None:
            what = "a second comparison" if tok[0] == "cmp" else f"{tok[1]!r} after the right-hand side"
            self.fail(tok[2], f"unexpected {what}")
        terms = dict(left.terms)
        for n, c in right.terms.items():
            terms[n] = terms.get(n, 0.0) - c
        terms = {n: c for n, c in terms.items() if c != 0}
        if not terms:
            self.fail(0, "the constraint has no variables (they cancel or none is named)")
        return Linear(terms, op, right.const - left.const)

    def expr(self) -> _Expr:
        out = self.term()
        while (tok := self.peek()) is not None and tok[1] in "+-" and tok[0] == "op":
            self.i += 1
            rhs = self.term()
            sign = 1.0 if tok[1] == "+" else -1.0
            terms = dict(out.terms)
            for n, c in rhs.terms.items():
                terms[n] = terms.get(n, 0.0) + sign * c
            out = _Expr(terms, out.const + sign * rhs.const, out.start, rhs.end)
        return out

    def term(self) -> _Expr:
        out = self.unary()
        while (tok := self.peek()) is not None and tok[0] == "op" and tok[1] in "*/":
            self.i += 1
            rhs = self.unary()
            span = self.text[out.start:rhs.end]
            if tok[1] == "*":
                if out.terms and rhs.terms:
                    self.fail(out.start, f"non-linear term {span!r} (a product of two variables)")
                out = rhs.scaled(out.const, out.start, rhs.end) if rhs.terms else out.scaled(
                    rhs.const, out.start, rhs.end)
            else:
                if rhs.terms:
                    self.fail(out.start, f"non-linear term {span!r} (division by a variable)")
                if rhs.const == 0:
                    self.fail(tok[2], f"division by zero in {span!r}")
                out = out.scaled(1.0 / rhs.const, out.start, rhs.end)
        return out

    def unary(self) -> _Expr:
        tok = self.peek()
        if tok is not None and tok[0] == "op" and tok[1] in "+-":
            self.i += 1
            inner = self.unary()
            return inner.scaled(-1.0 if tok[1] == "-" else 1.0, tok[2], inner.end)
        return self.atom()

    def atom(self) -> _Expr:
        tok = self.peek()
        if tok is None:
            self.fail(len(self.text), "expression ends too early: expected a number, a name or '('")
        assert tok is not None
        kind, text, start, end = tok
        self.i += 1
        if kind == "num":
            value = float(text)
            if not math.isfinite(value):
                self.fail(start, f"number {text!r} is out of range")
            return _Expr({}, value, start, end)
        if kind == "name":
            return _Expr({text: 1.0}, 0.0, start, end)
        if text == "(":
            inner = self.expr()
            close = self.peek()
            if close is None or close[1] != ")":
                self.fail(close[2] if close else len(self.text), "missing ')'")
            self.i += 1
            return _Expr(inner.terms, inner.const, start, close[3] if close else end)
        self.fail(start, f"expected a number, a name or '(' but found {text!r}")
        raise AssertionError  # unreachable: fail raises


def parse_linear(text: str, where: str = "constraint") -> Linear:
    """Read one linear constraint: ``expr (<= | >= | ==) expr``.

    ``expr`` is a sum of terms (``+``/``-``), a term a product or quotient of factors (``*``, ``/``) with
    at most one factor holding variables and no variable below ``/``, a factor a number, a name, a
    signed factor or a parenthesised ``expr``. Variables are moved to the left, numbers to the right.
    ``where`` starts the error messages (e.g. the constraint's label).
    """
    if not isinstance(text, str):
        raise ConstraintError(f"{where}: expected text, got {type(text).__name__}")
    return _Parser(text, where).parse()
