"""The consistency check of a Task Specification Tree's constraints (seed 000 Sec. III, III-A).

Seed 000 Sec. III: task parameters "can either be specified directly or constrained through a general
constraint language", e.g. speed and altitude "within specific intervals, allowing these parameters to
be adapted to fuel and time constraints"; Sec. III-A: ``get_constraints()`` returns the platform's
constraints ("a maximum duration of a task which is limited by the current fuel level"), which "should
be checked for consistency with a constraint solver". :class:`ConstraintProblem` collects them all for
one tree and :meth:`ConstraintProblem.solve` is that one check: a mixed-integer linear program solved by
HiGHS (``scipy.optimize.milp``) which either fixes every free parameter or rejects the tree naming an
irreducible set of constraints in conflict (:mod:`companion.tst.conflict`), one per independent group
of constraints in conflict.

The pieces, each a *labelled* constraint (the label is what the user reads when it is in conflict):

* :meth:`~ConstraintProblem.variable`: a real variable, given (``value``) or in an interval (``lo``,
  ``hi``); the bound is one labelled constraint (``n3.altitude in [2, 40]``);
* :meth:`~ConstraintProblem.qualitative`: a choice among named options mapped to platform values (the
  paper's ``slow | standard | fast`` speeds): one binary variable per option, exactly one chosen, the
  variable equal to the chosen value; the option set and a mission's restriction of it
  (``allowed``) are labelled constraints;
* :meth:`~ConstraintProblem.add`: a linear constraint, as text or :class:`~companion.tst.linear.Linear`;
* :meth:`~ConstraintProblem.duration_at_speed`: ``duration = length / speed`` linearised over the speed's
  options (``duration = sum(length / v_o * b_o)``), so a mission longer than the endurance is caught
  while the speed is still free.

A *definition* (``duration_at_speed``, or ``add(..., definition=True)``) is assumed to hold: the
conflict search keeps it in the background and names the constraints it links instead (the endurance,
the sum of durations, the speeds' option sets), unless the definitions alone are inconsistent.

The default objective (how free parameters are fixed; ``solve(objective=...)`` puts a caller's first and
keeps this one as a tie-break at 1e-6 of its weight):

1. each qualitative choice takes its preferred option (``solve(prefer=...)``, else the variable's own
   ``prefer``, else the option with the largest value: the fastest speed) and otherwise the nearest in
   value order: a cost of 1 per step away, so as few choices as possible leave their preference (with
   ``prefer="standard"``, only as many legs fly fast as the endurance needs);
2. an interval variable goes to the middle of its interval, a half-bounded one to its bound: a cost of
   1e-3 per interval width away (a tie-break below any choice);
3. given values stay given, and variables fixed by equalities (durations) follow; an unconstrained
   free variable gets whatever HiGHS returns.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np

from .conflict import components, minimal_conflict
from .linear import NAME, ConstraintError, Linear, parse_linear
from .milp import Row, Solution, run_milp

log = logging.getLogger(__name__)

__all__ = ["ConstraintError", "ConstraintProblem", "Linear", "Solution"]

_INF = math.inf
_MID_WEIGHT = 1e-3
_TIE_WEIGHT = 1e-6


@dataclass
class _Group:
    label: str
    reason: str
    rows: list[Row]  # (coefficients by column, lower, upper)
    definition: bool = False

    @property
    def detail(self) -> str:
        return f"{self.label} ({self.reason})" if self.reason else self.label


@dataclass
class _Qualitative:
    column: int
    options: dict[str, float]
    binaries: dict[str, int]
    prefer: str


def _finite(x: object) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)


class ConstraintProblem:
    """The constraints of one TST and of the platform, checked together (seed 000 Sec. III-A).

    ``strict``: a name in :meth:`add` must be declared first (with :meth:`variable` or
    :meth:`qualitative`), so a misspelt parameter is an error instead of a new free variable.
    """

    def __init__(self, strict: bool = True) -> None:
        self.strict = strict
        self._columns: list[str] = []  # user variables by name; binaries as "name#option"
        self._index: dict[str, int] = {}
        self._integer: list[bool] = []
        self._declared: dict[str, tuple[float, float, float | None]] = {}  # name -> (lo, hi, value)
        self._qualitative: dict[str, _Qualitative] = {}
        self._groups: list[_Group] = []
        self._labels: set[str] = set()

    # --- building --------------------------------------------------------------------------------------

    @property
    def variables(self) -> list[str]:
        """The declared variables (real and qualitative), in declaration order."""
        return [c for c in self._columns if "#" not in c]

    @property
    def labels(self) -> list[str]:
        """The labels of the constraints, in the order they were posed."""
        return [g.label for g in self._groups]

    def variable(self, name: str, lo: float | None = None, hi: float | None = None,
                 value: float | None = None, label: str | None = None, reason: str = "") -> str:
        """Declare a real variable: given (``value``), in ``[lo, hi]`` (either side may be open) or free.

        The bound is one labelled constraint (default label ``name = v``, ``name in [lo, hi]``,
        ``name >= lo`` or ``name <= hi``); an empty interval is not an error here but a conflict when
        solving. Returns ``name``.
        """
        self._check_name(name)
        if value is not None and (lo is not None or hi is not None):
            raise ConstraintError(f"variable {name}: give either a value or an interval, not both")
        nums = {"lo": lo, "hi": hi, "value": value}
        for what, x in nums.items():
            if x is not None and not _finite(x):
                raise ConstraintError(f"variable {name}: {what} {x!r} is not a finite number")
        col = self._new_column(name)
        if value is not None:
            lo_b = hi_b = float(value)
            default = f"{name} = {value:g}"
        else:
            lo_b = -_INF if lo is None else float(lo)
            hi_b = _INF if hi is None else float(hi)
            if lo is not None and hi is not None:
                default = f"{name} in [{lo:g}, {hi:g}]"
            elif lo is not None:
                default = f"{name} >= {lo:g}"
            else:
                default = "" if hi is None else f"{name} <= {hi:g}"
        self._declared[name] = (lo_b, hi_b, None if value is None else float(value))
        if value is not None or lo is not None or hi is not None:
            self._group(label or default, reason, [({col: 1.0}, lo_b, hi_b)])
        return name

    def qualitative(self, name: str, options: Mapping[str, float], allowed: str | Iterable[str] | None = None,
                    prefer: str = "max", label: str | None = None, reason: str | None = None) -> str:
        """Declare a choice among ``options`` (option -> platform value, e.g. speeds in m/s).

        The variable ``name`` equals the chosen option's value. Two labelled constraints: the option set
        (default label ``name in {slow, standard, fast}``, reason the values) and, when ``allowed``
        narrows it (one option: given; several: the mission's set), ``name = fast (given)`` or
        ``name in {slow, standard} (given)``. ``prefer``: ``"max"``, ``"min"`` or an option (see the
        module's default objective). Returns ``name``.
        """
        self._check_name(name)
        if not options:
            raise ConstraintError(f"qualitative {name}: no options")
        opts: dict[str, float] = {}
        for opt, v in options.items():
            if not isinstance(opt, str) or not opt or "#" in opt:
                raise ConstraintError(f"qualitative {name}: bad option name {opt!r}")
            if not _finite(v):
                raise ConstraintError(f"qualitative {name}: option {opt} = {v!r} is not a finite number")
            opts[opt] = float(v)
        if prefer not in ("max", "min") and prefer not in opts:
            raise ConstraintError(f"qualitative {name}: prefer {prefer!r} is not max, min or an option")
        keep = None if allowed is None else [allowed] if isinstance(allowed, str) else list(allowed)
        for opt in keep or ():
            if opt not in opts:
                raise ConstraintError(f"qualitative {name}: {opt!r} is not one of {{{', '.join(opts)}}}")
        if keep is not None and not keep:
            raise ConstraintError(f"qualitative {name}: no allowed option")
        col = self._new_column(name)
        bins = {opt: self._new_column(f"{name}#{opt}", integer=True) for opt in opts}
        self._qualitative[name] = _Qualitative(col, opts, bins, prefer)
        one = {b: 1.0 for b in bins.values()}
        value = {col: 1.0, **{bins[o]: -v for o, v in opts.items()}}
        default_reason = ", ".join(f"{o} {v:g}" for o, v in opts.items())
        self._group(label or f"{name} in {{{', '.join(opts)}}}",
                    default_reason if reason is None else reason, [(one, 1.0, 1.0), (value, 0.0, 0.0)])
        out = [o for o in opts if o not in (keep or opts)]
        if out:
            text = (f"{name} = {keep[0]}" if keep and len(keep) == 1
                    else f"{name} in {{{', '.join(keep or ())}}}")
            self._group(f"{text} (given)", "", [({bins[o]: 1.0 for o in out}, 0.0, 0.0)])
        return name

    def add(self, constraint: str | Linear, label: str | None = None, reason: str = "",
            definition: bool = False) -> Linear:
        """Pose a linear constraint (text as in :mod:`companion.tst.linear`, or a :class:`Linear`).

        ``label`` (default: the text) names it when it is in conflict, e.g.
        ``"n4.altitude <= envelope ceiling 30 m"``; ``reason`` says where it came from. A ``definition``
        (e.g. a duration computed from a length) is assumed to hold: a conflict names it only when
        definitions alone are inconsistent.
        """
        where = f"constraint {label!r}:" if label else "constraint"
        if isinstance(constraint, str):
            lin = parse_linear(constraint, where)
            default = " ".join(constraint.split())
        elif isinstance(constraint, Linear):
            lin, default = constraint, str(constraint)
        else:
            raise ConstraintError(f"{where} expected text or Linear, got {type(constraint).__name__}")
        row: dict[int, float] = {}
        for name, coef in lin.terms.items():
            if name not in self._index:
                if self.strict:
                    raise ConstraintError(f"{where} {default!r}: unknown variable {name!r} "
                                          "(declare it with variable() or qualitative())")
                self._new_column(name)
            row[self._index[name]] = coef
        lo, hi = {"<=": (-_INF, lin.rhs), ">=": (lin.rhs, _INF), "==": (lin.rhs, lin.rhs)}[lin.op]
        self._group(label or default, reason, [(row, lo, hi)], definition)
        return lin

    def duration_at_speed(self, duration: str, length_m: float, speed: str, extra_s: float = 0.0,
                          label: str | None = None, reason: str = "", definition: bool = True) -> str:
        """Pose ``duration = length_m / speed + extra_s`` linearly.

        ``speed`` is qualitative (then ``duration = sum(length_m / v_o * b_o) + extra_s`` over its option
        binaries, exact for the chosen option) or a given variable; a speed in a free interval makes the
        relation non-linear and is refused. ``duration`` is declared (free) if it is not yet. It is a
        ``definition`` (see :meth:`add`) unless told otherwise, so a conflict over the endurance names
        the endurance, the sum and the speeds' option sets. Returns ``duration``.
        """
        where = f"duration {duration}"
        for what, x in (("length", length_m), ("extra time", extra_s)):
            if not _finite(x) or x < 0:
                raise ConstraintError(f"{where}: {what} {x!r} is not a finite number >= 0")
        if duration not in self._index:
            self.variable(duration)
        elif duration in self._qualitative:
            raise ConstraintError(f"{where}: {duration} is qualitative")
        row: dict[int, float] = {self._index[duration]: 1.0}
        if speed in self._qualitative:
            q = self._qualitative[speed]
            for opt, v in q.options.items():
                if v <= 0:
                    raise ConstraintError(f"{where}: option {speed} = {opt} is {v:g}, not a speed > 0")
                row[q.binaries[opt]] = -length_m / v
        elif speed in self._declared and self._declared[speed][2] is not None:
            v = self._declared[speed][2] or 0.0
            if v <= 0:
                raise ConstraintError(f"{where}: {speed} = {v:g} is not a speed > 0")
            extra_s += length_m / v
        elif speed in self._declared:
            raise ConstraintError(f"{where}: {duration} = length / {speed} is non-linear while {speed} "
                                  "is free; make the speed qualitative or give its value")
        else:
            raise ConstraintError(f"{where}: unknown speed variable {speed!r}")
        text = f"{duration} = {length_m:g} m / {speed}" + (f" + {extra_s:g} s" if extra_s else "")
        self._group(label or text, reason, [(row, extra_s, extra_s)], definition)
        return duration

    # --- solving ---------------------------------------------------------------------------------------

    def solve(self, objective: Mapping[str, float] | None = None, prefer: str | None = None,
              maximize: Iterable[str] = ()) -> Solution:
        """Check all constraints together; fix the free parameters or name the conflict.

        ``objective``: coefficients of variables to minimise (the default objective of the module
        docstring breaks ties); ``prefer``: an option (e.g. ``"standard"``), ``"max"`` or ``"min"``,
        preferred by every qualitative variable that has it, in place of each variable's own preference;
        ``maximize``: variables taken to their upper bound (a parameter a relation bounds only from above),
        at the weight of rule 2 of the default objective.
        """
        t0 = time.perf_counter()
        n = len(self._columns)
        c = self._default_objective(prefer)
        for name in maximize:
            if name not in self._index or "#" in name:
                raise ConstraintError(f"maximize: unknown variable {name!r}")
            c[self._index[name]] -= 2 * _MID_WEIGHT  # beats rule 2 pulling a half-bounded one to lo
        aux_rows, aux_cost = self._middle_rows(n)
        if objective:
            user = np.zeros(n)
            for name, coef in objective.items():
                if name not in self._index or "#" in name or not math.isfinite(coef):
                    raise ConstraintError(f"objective: unknown variable {name!r} or bad coefficient")
                user[self._index[name]] = coef
            c, aux_cost = user + _TIE_WEIGHT * c, [_TIE_WEIGHT * w for w in aux_cost]
        rows = [r for g in self._groups for r in g.rows] + aux_rows
        res = run_milp(np.concatenate([c, aux_cost]), self._integer, rows)
        sol = Solution(ok=res.status == 0)
        if res.status == 0:
            x = res.x
            for name in self.variables:
                v = float(x[self._index[name]])
                sol.values[name] = round(v, 9) + 0.0
            for name, q in self._qualitative.items():
                bins = q.binaries
                sol.choices[name] = max(bins, key=lambda o: float(x[bins[o]]))
                sol.values[name] = q.options[sol.choices[name]]
            chosen = ", ".join(f"{k} = {v}" for k, v in sol.choices.items())
            sol.message = f"accepted: {chosen}" if chosen else "accepted"
        elif res.status == 2:
            found = self._conflict()
            sol.conflict = [self._groups[i].label for i in found]
            sol.details = [self._groups[i].detail for i in found]
            sol.message = "rejected: " + "; ".join(sol.details)
        else:
            sol.message = f"not decided: the solver stopped (status {res.status}): {res.message}"
        sol.seconds = time.perf_counter() - t0
        log.info("constraint check of %d variables, %d constraints in %.1f ms: %s", len(self.variables),
                 len(self._groups), sol.seconds * 1e3, sol.message)
        return sol

    def feasible(self, labels: Iterable[str] | None = None) -> bool:
        """Whether the constraints with these labels (default all) can hold together."""
        if labels is None:
            return self._feasible(range(len(self._groups)))
        want = set(labels)
        unknown = want - self._labels
        if unknown:
            raise ConstraintError(f"unknown constraint labels: {sorted(unknown)}")
        return self._feasible([i for i, g in enumerate(self._groups) if g.label in want])

    # --- internals -------------------------------------------------------------------------------------

    def _check_name(self, name: str) -> None:
        if not isinstance(name, str) or not NAME.fullmatch(name):
            raise ConstraintError(f"bad variable name {name!r}")
        if name in self._declared or name in self._qualitative:
            raise ConstraintError(f"variable {name} declared twice")

    def _new_column(self, name: str, integer: bool = False) -> int:
        if name in self._index:  # declared after an implicit use in a non-strict problem
            return self._index[name]
        self._index[name] = len(self._columns)
        self._columns.append(name)
        self._integer.append(integer)
        return self._index[name]

    def _group(self, label: str, reason: str, rows: list[Row],
               definition: bool = False) -> None:
        if label in self._labels:
            raise ConstraintError(f"two constraints labelled {label!r}; labels must tell them apart")
        self._labels.add(label)
        self._groups.append(_Group(label, reason, rows, definition))

    def _default_objective(self, prefer: str | None) -> np.ndarray:
        c = np.zeros(len(self._columns))
        if prefer is not None and prefer not in ("max", "min") and not any(
                prefer in q.options for q in self._qualitative.values()):
            raise ConstraintError(f"prefer {prefer!r} is not max, min or an option of a qualitative variable")
        for q in self._qualitative.values():
            own = prefer is None or (prefer not in ("max", "min") and prefer not in q.options)
            want = q.prefer if own else prefer
            values = q.options
            order = sorted(values, key=lambda o: values[o])
            target = (len(order) - 1 if want == "max" else 0 if want == "min"
                      else order.index(str(want)))
            for rank, opt in enumerate(order):
                c[q.binaries[opt]] = abs(rank - target)
        return c

    def _middle_rows(self, n: int) -> tuple[list[Row], list[float]]:
        """Rows ``d >= |x - target|`` (d a new column) and the cost of each d, for rule 2."""
        rows: list[Row] = []
        cost: list[float] = []
        for name, (lo, hi, value) in self._declared.items():
            if value is not None or (lo == -_INF and hi == _INF):
                continue
            col = self._index[name]
            finite = math.isfinite(lo) and math.isfinite(hi)
            target = (lo + hi) / 2 if finite else lo if math.isfinite(lo) else hi
            d = n + len(cost)
            rows += [({d: 1.0, col: -1.0}, -target, _INF), ({d: 1.0, col: 1.0}, target, _INF)]
            cost.append(_MID_WEIGHT / max(hi - lo, 1e-9) if finite else _MID_WEIGHT / max(abs(target), 1.0))
        return rows, cost

    def _feasible(self, groups: Iterable[int]) -> bool:
        rows = [r for g in groups for r in self._groups[g].rows]
        res = run_milp(np.zeros(len(self._columns)), self._integer, rows)
        if res.status not in (0, 2):
            log.warning("feasibility check stopped: %s", res.message)
        return res.status != 2

    def _conflict(self) -> list[int]:
        """Indices of the constraints in conflict: an irreducible set per independent group in conflict.

        The constraints fall into components that share no variable; each infeasible component
        contributes one irreducible conflicting set, so a tree with an altitude above the ceiling *and*
        an endurance too short is told both at once.
        """
        cols = [[k for r, _, _ in g.rows for k in r] for g in self._groups]
        pending = components(cols)
        found: list[int] = []
        while pending and not self._feasible([i for c in pending for i in c]):
            comp = next((c for c in pending if not self._feasible(c)), None)
            if comp is None:
                log.warning("no component is infeasible alone, searching them together")
                comp = [i for c in pending for i in c]
            found += self._search(comp)
            pending = [c for c in pending if c is not comp]
        return sorted(found)

    def _search(self, comp: list[int]) -> list[int]:
        base = [i for i in comp if self._groups[i].definition]
        if base and not self._feasible(base):
            log.info("the definitions alone are inconsistent")
            return minimal_conflict(comp, self._feasible)
        return minimal_conflict([i for i in comp if not self._groups[i].definition], self._feasible, base)
