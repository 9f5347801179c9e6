"""Module dependency resolution: seed 002 Sec. 4.1, Algorithm 1 (two-pass topological sort) and
Algorithm 2 (RESOLVE, a depth-first search after Cormen et al.).

First pass: starting from a root module whose dependencies are the user's selection, RESOLVE recurses
into every explicit module dependency (a module met again while still *unresolved* is a cycle);
functionalities (``@f``) and OR expressions (``a|b``) are only stored in the *required* list; conflicts
and provided functionalities are stored too. Then Algorithm 1 checks

1. no resolved module is in the conflict list,
2. no required functionality is in the conflict list,
3. every required functionality is provided, every OR expression is satisfied,

substitutes each functionality / OR expression by the real resolved module(s), and runs a second pass
on the updated graph (no new module, no checks) which yields the final fully ordered list: every
module comes after all the modules it depends on.

Choices where the paper is silent (documented here and in the report):

* OR expression with no alternative loaded: the first alternative that is a module of the library is
  added (and resolved with its own dependencies, first-pass rules) before the checks; it is an error
  (unmet OR) only when no alternative is a library module. A functionality alternative is never
  auto-loaded.
* A functionality is substituted by *all* the loaded modules providing it (so the dependent comes
  after each of them); an OR expression by its first satisfied alternative, in written order.
* The second pass starts from the selection followed by the auto-added OR modules, so it reaches
  exactly the modules of the first pass.
* "Module valid for firmware and target" (Algorithm 2) has no equivalent here: every module is valid.
"""

from __future__ import annotations

import itertools
import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from .errors import SchedulerError
from .spec import ModuleSpec, is_functionality, term_text

log = logging.getLogger(__name__)

_ROOT = "<select>"


@dataclass(frozen=True)
class Requirement:
    """A functionality or OR expression stored during the first pass (Algorithm 2, ``required``)."""

    module: str               # who requires it
    term: tuple[str, ...]     # ("@f",) or ("a", "b", "@g")


@dataclass(frozen=True)
class Resolution:
    """Result of Algorithm 1.

    ``order``: the fully ordered module list (second pass); ``first_pass``: the first-pass order
    (complete but not necessarily ordered w.r.t. functionalities); ``dependencies``: the substituted
    dependency edges of every module (module names only); ``provided``: functionality -> loaded
    providers; ``substitutions``: ``(module, "a|b")`` or ``(module, "@f")`` -> the modules chosen;
    ``auto_selected``: modules added to satisfy an OR expression no loaded module satisfied.
    """

    order: tuple[str, ...]
    first_pass: tuple[str, ...]
    dependencies: Mapping[str, tuple[str, ...]]
    provided: Mapping[str, tuple[str, ...]]
    substitutions: Mapping[tuple[str, str], tuple[str, ...]]
    auto_selected: tuple[str, ...]


class _Resolver:
    """The state of Algorithm 2: resolved, unresolved, conflict, provided (and required) lists."""

    def __init__(self, library: Mapping[str, ModuleSpec], deps: Mapping[str, Sequence[tuple[str, ...]]],
                 first_pass: bool, notes: Mapping[tuple[str, str], str] | None = None) -> None:
        self.library = library
        self.deps = deps
        self.first_pass = first_pass
        self.notes = notes or {}
        self.resolved: list[str] = []
        self.resolved_set: set[str] = set()
        self.unresolved: list[str] = []
        self.conflicts: list[tuple[str, str]] = []      # (declared by, module or @functionality)
        self.provided: dict[str, list[str]] = {}         # @functionality -> providers
        self.required: list[Requirement] = []

    def resolve(self, m: str) -> None:
        """RESOLVE(m) of Algorithm 2."""
        self.unresolved.append(m)
        for term in self.deps[m]:
            if len(term) == 1 and not is_functionality(term[0]):
                d = term[0]
                if d in self.resolved_set:
                    continue
                if d in self.unresolved:
                    raise SchedulerError(self._cycle_message(d))
                if d not in self.library:
                    who = "the selection" if m == _ROOT else f"module '{m}' ({self.library[m].where})"
                    raise SchedulerError(f"unknown module '{d}' required by {who}: not in the module library")
                self.resolve(d)
            elif self.first_pass:
                self.required.append(Requirement(m, term))   # functionality or logical expression
        if m != _ROOT:
            spec = self.library[m]
            if self.first_pass:
                self.conflicts.extend((m, c) for c in spec.conflicts)
                for f in spec.provides:
                    self.provided.setdefault(f, []).append(m)
            self.resolved.append(m)
            self.resolved_set.add(m)
        self.unresolved.pop()

    def _cycle_message(self, d: str) -> str:
        path = [*self.unresolved[self.unresolved.index(d):], d]
        text = " -> ".join(path)
        via = [f"{a} -> {b} via '{self.notes[(a, b)]}'" for a, b in itertools.pairwise(path)
               if (a, b) in self.notes]
        if via:
            text += " (" + "; ".join(via) + ")"
        return f"cyclic dependency: {text}"

    def satisfied_by(self, term: tuple[str, ...]) -> str | None:
        """First alternative of ``term`` that is a resolved module or a provided functionality."""
        for alt in term:
            if (alt in self.provided) if is_functionality(alt) else (alt in self.resolved_set):
                return alt
        return None


def resolve_modules(library: Mapping[str, ModuleSpec], select: Sequence[str]) -> Resolution:
    """Seed 002 Algorithm 1: order the selected modules and everything they depend on.

    Raises :class:`SchedulerError` naming the cycle path (``a -> b -> a``), the two conflicting
    modules (or the conflicting functionality, who requires it and who forbids it), the unmet OR
    expression or the missing functionality and who required it.
    """
    if not select:
        raise SchedulerError("no module selected (the 'select' list is empty)")
    deps: dict[str, Sequence[tuple[str, ...]]] = {name: spec.depends for name, spec in library.items()}
    deps[_ROOT] = tuple((name,) for name in select)

    # --- first pass -----------------------------------------------------------------------------
    r = _Resolver(library, deps, first_pass=True)
    r.resolve(_ROOT)

    # OR expressions that nothing loaded satisfies: load the first alternative that exists.
    auto: list[str] = []
    done = 0
    while done < len(r.required):  # required grows while auto-added modules are resolved
        req = r.required[done]
        done += 1
        if len(req.term) > 1 and r.satisfied_by(req.term) is None:
            pick = next((a for a in req.term if not is_functionality(a) and a in library), None)
            if pick is not None:
                log.info("module '%s' requires '%s': none loaded, adding '%s' (first alternative in the "
                         "library)", req.module, term_text(req.term), pick)
                auto.append(pick)
                r.resolve(pick)

    where = {name: spec.where for name, spec in library.items()}
    # 1. a resolved module in the conflict list
    for who, item in r.conflicts:
        if not is_functionality(item) and item in r.resolved_set and item != who:
            raise SchedulerError(
                f"conflict: module '{who}' ({where[who]}) conflicts with module '{item}' "
                f"({where[item]}), but both are loaded")
    # 2. a required functionality in the conflict list
    for who, item in r.conflicts:
        if is_functionality(item):
            for req in r.required:
                if item in req.term and (len(req.term) == 1 or r.satisfied_by(req.term) == item):
                    raise SchedulerError(
                        f"conflict: module '{who}' ({where[who]}) conflicts with functionality '{item}', "
                        f"which module '{req.module}' ({where[req.module]}) requires")
    # 3. every required functionality provided, every OR expression satisfied
    for req in r.required:
        if r.satisfied_by(req.term) is not None:
            continue
        if len(req.term) == 1:
            f = req.term[0]
            candidates = [n for n, s in library.items() if f in s.provides]
            hint = (f"; library modules providing it: {', '.join(candidates)} (select one)"
                    if candidates else "; no module of the library provides it")
            raise SchedulerError(f"missing functionality '{f}' required by module '{req.module}' "
                                 f"({where[req.module]}): no loaded module provides it{hint}")
        raise SchedulerError(
            f"unmet dependency '{term_text(req.term)}' of module '{req.module}' ({where[req.module]}): "
            f"none of {', '.join(req.term)} is loaded, provided, or a module of the library")

    # --- substitution of functionalities / logical expressions with real modules ------------------
    provided = {f: tuple(p) for f, p in r.provided.items()}
    substitutions: dict[tuple[str, str], tuple[str, ...]] = {}
    notes: dict[tuple[str, str], str] = {}
    new_deps: dict[str, Sequence[tuple[str, ...]]] = {}
    for m in r.resolved:
        out: list[tuple[str, ...]] = []
        for term in deps[m]:
            if len(term) == 1 and not is_functionality(term[0]):
                out.append(term)
                continue
            alt = r.satisfied_by(term)
            assert alt is not None  # checked above
            mods = tuple(p for p in provided[alt] if p != m) if is_functionality(alt) else (alt,)
            substitutions[(m, term_text(term))] = mods
            for d in mods:
                out.append((d,))
                notes.setdefault((m, d), term_text(term))
        new_deps[m] = tuple(out)
    new_deps[_ROOT] = tuple((name,) for name in (*select, *auto))

    # --- second pass ----------------------------------------------------------------------------
    r2 = _Resolver(library, new_deps, first_pass=False, notes=notes)
    r2.resolve(_ROOT)
    if r2.resolved_set != r.resolved_set:  # pragma: no cover - guarded by construction
        raise SchedulerError(f"internal error: second pass reached {sorted(r2.resolved_set)}, "
                             f"first pass {sorted(r.resolved_set)}")
    dependencies = {m: tuple(t[0] for t in new_deps[m]) for m in r2.resolved}
    log.debug("resolved modules: %s", ", ".join(r2.resolved))
    return Resolution(order=tuple(r2.resolved), first_pass=tuple(r.resolved), dependencies=dependencies,
                      provided=provided, substitutions=substitutions, auto_selected=tuple(auto))
