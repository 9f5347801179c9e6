"""Dependency resolution: seed 002 Sec. 4.1, Algorithms 1-2, with the Fig. 3 example."""

from __future__ import annotations

import random
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import pytest

from autopilot_model.scheduler import (
    ModuleSpec,
    Resolution,
    SchedulerError,
    load_modules,
    parse_modules,
    resolve_modules,
)

FIXTURES = Path(__file__).parent / "fixtures"


def lib(*modules: dict[str, Any]) -> Mapping[str, ModuleSpec]:
    """A library from short dicts; task group defaults to core."""
    return parse_modules({"modules": [{"task_group": "core", **m} for m in modules]}).modules


def assert_ordered(res: Resolution) -> None:
    """Every module comes after every module it depends on (after substitution)."""
    pos = {m: i for i, m in enumerate(res.order)}
    for m, deps in res.dependencies.items():
        for d in deps:
            assert pos[d] < pos[m], f"{d} must come before {m} in {res.order}"


# Fig. 3: <depends>module1,module2|module3,@func1</depends> <provides>func2</provides>
#         <conflicts>module4,@func3</conflicts>
FIG3 = dict(name="example", depends="module1,module2|module3,@func1", provides="func2",
            conflicts="module4,@func3")


def fig3_library(*extra: dict[str, Any]) -> Mapping[str, ModuleSpec]:
    return lib(FIG3, {"name": "module1"}, {"name": "module2"}, {"name": "module3", "provides": "@func1"},
               {"name": "module4"}, {"name": "module5", "provides": "@func3"}, *extra)


def test_fig3_two_pass_order() -> None:
    cfg = load_modules(FIXTURES / "scheduler_fig3.yaml")
    res = resolve_modules(cfg.modules, cfg.select)
    # First pass: module3 is only a functionality / OR alternative of 'example', so it is not
    # recursed into and comes after 'example' -- the list is complete but not ordered.
    assert res.first_pass == ("module1", "example", "module3")
    # Second pass after substitution: fully ordered.
    assert res.order == ("module1", "module3", "example")
    assert res.substitutions == {("example", "module2|module3"): ("module3",),
                                 ("example", "@func1"): ("module3",)}
    assert res.provided == {"@func1": ("module3",), "@func2": ("example",)}
    assert res.auto_selected == ()
    assert set(res.dependencies["example"]) == {"module1", "module3"}
    assert_ordered(res)


def test_fig3_or_expression_loads_first_library_alternative() -> None:
    library = fig3_library({"name": "func1_provider", "provides": "func1"})
    res = resolve_modules(library, ["example", "func1_provider"])
    assert res.auto_selected == ("module2",)      # neither loaded: first alternative in the library
    assert res.substitutions[("example", "module2|module3")] == ("module2",)
    assert res.substitutions[("example", "@func1")] == ("func1_provider",)
    assert set(res.order) == {"module1", "module2", "example", "func1_provider"}
    assert_ordered(res)


def test_or_expression_skips_alternatives_missing_from_library() -> None:
    library = lib({"name": "a", "depends": "ghost|@nothing|b"}, {"name": "b", "depends": "c"}, {"name": "c"})
    res = resolve_modules(library, ["a"])
    assert res.auto_selected == ("b",)
    assert res.order == ("c", "b", "a")


def test_or_expression_satisfied_by_functionality() -> None:
    library = lib({"name": "a", "depends": "x|@f"}, {"name": "x"}, {"name": "p", "provides": "@f"})
    res = resolve_modules(library, ["a", "p"])
    assert res.auto_selected == ()
    assert res.order == ("p", "a")


def test_functionality_substituted_by_all_providers() -> None:
    library = lib({"name": "user", "depends": "@gps"}, {"name": "ubx", "provides": "@gps"},
                  {"name": "nmea", "provides": "@gps"})
    res = resolve_modules(library, ["user", "ubx", "nmea"])
    assert res.order == ("ubx", "nmea", "user")


def test_missing_functionality_names_it_and_who_required_it() -> None:
    library = fig3_library()
    with pytest.raises(SchedulerError) as info:
        resolve_modules(library, ["example", "module2"])
    msg = str(info.value)
    assert "missing functionality '@func1' required by module 'example'" in msg
    assert "module3" in msg     # the hint: a library module providing it


def test_unmet_or_expression() -> None:
    library = lib({"name": "a", "depends": "b,ghost1|ghost2"}, {"name": "b"})
    with pytest.raises(SchedulerError, match=r"unmet dependency 'ghost1\|ghost2' of module 'a'"):
        resolve_modules(library, ["a"])


def test_conflict_between_modules() -> None:
    with pytest.raises(SchedulerError) as info:
        resolve_modules(fig3_library(), ["example", "module3", "module4"])
    msg = str(info.value)
    assert "conflict" in msg and "'example'" in msg and "'module4'" in msg


def test_conflict_with_pulled_in_dependency() -> None:
    library = lib({"name": "a", "conflicts": "c"}, {"name": "b", "depends": "c"}, {"name": "c"})
    with pytest.raises(SchedulerError, match=r"module 'a' .* conflicts with module 'c'"):
        resolve_modules(library, ["a", "b"])


def test_conflict_with_required_functionality() -> None:
    library = fig3_library({"name": "module6", "depends": "@func3"})
    with pytest.raises(SchedulerError) as info:
        resolve_modules(library, ["example", "module3", "module5", "module6"])
    msg = str(info.value)
    assert "conflicts with functionality '@func3'" in msg
    assert "'example'" in msg and "'module6'" in msg


def test_provided_but_unrequired_conflicting_functionality_is_accepted() -> None:
    # Algorithm 1 only rejects a conflicting functionality that is *required*.
    res = resolve_modules(fig3_library(), ["example", "module3", "module5"])
    assert res.order == ("module1", "module3", "example", "module5")


def test_cycle_names_the_path() -> None:
    library = lib({"name": "a", "depends": "b"}, {"name": "b", "depends": "x,c"},
                  {"name": "c", "depends": "a"}, {"name": "x"})
    with pytest.raises(SchedulerError, match=r"cyclic dependency: a -> b -> c -> a$"):
        resolve_modules(library, ["a"])


def test_cycle_through_functionality_found_in_second_pass() -> None:
    library = lib({"name": "a", "depends": "@fb"}, {"name": "b", "provides": "@fb", "depends": "a"})
    with pytest.raises(SchedulerError, match=r"cyclic dependency: a -> b -> a \(a -> b via '@fb'\)"):
        resolve_modules(library, ["a", "b"])


def test_unknown_module_dependency() -> None:
    with pytest.raises(SchedulerError, match=r"unknown module 'nope' required by module 'a'"):
        resolve_modules(lib({"name": "a", "depends": "nope"}), ["a"])


def test_empty_selection() -> None:
    with pytest.raises(SchedulerError, match="no module selected"):
        resolve_modules(lib({"name": "a"}), [])


def test_random_dags_are_ordered_and_complete() -> None:
    rng = random.Random(2)
    for _ in range(50):
        n = rng.randint(2, 25)
        mods = []
        for i in range(n):
            deps = []
            for j in rng.sample(range(i), k=min(i, rng.randint(0, 3))):
                if rng.random() < 0.3:
                    deps.append(f"@f{j}")
                elif rng.random() < 0.2:
                    deps.append(f"ghost{j}|m{j}")
                else:
                    deps.append(f"m{j}")
            mods.append({"name": f"m{i}", "depends": ",".join(deps), "provides": f"@f{i}"})
        library = lib(*mods)
        select = [f"m{i}" for i in rng.sample(range(n), k=rng.randint(1, n))]
        # providers of functionalities are not pulled in automatically: select every module
        # that provides a functionality someone needs, the way an airframe does.
        select = select + [f"m{i}" for i in range(n) if f"m{i}" not in select]
        res = resolve_modules(library, select)
        assert sorted(res.order) == sorted(select)
        assert_ordered(res)
