"""The consistency check of a TST's constraints (seed 000 Sec. III, III-A): text form, solving, conflicts."""

from __future__ import annotations

import pytest

from companion.tst.conflict import components, minimal_conflict
from companion.tst.constraints import ConstraintError, ConstraintProblem, Linear, Solution
from companion.tst.linear import parse_linear

SPEEDS = {"slow": 1.0, "standard": 2.0, "fast": 5.0}


def assert_irreducible(p: ConstraintProblem, sol: Solution) -> None:
    """The conflict is infeasible, and dropping any one of its constraints (definitions kept) is not."""
    assert not sol.ok and sol.conflict
    definitions = [g.label for g in p._groups if g.definition]
    assert not p.feasible(sol.conflict + definitions)
    for label in sol.conflict:
        assert p.feasible([x for x in sol.conflict if x != label] + definitions), label


def legs(p: ConstraintProblem, lengths: dict[str, float], endurance: float, **qual: object) -> None:
    """Fly-to legs n<i> with qualitative speed, a duration from the length, and a shared endurance."""
    p.variable("endurance_left", value=endurance, label=f"endurance_left {endurance:g} s", reason="battery")
    for node, length in lengths.items():
        p.qualitative(f"{node}.speed", SPEEDS, reason="max 5 m/s", **qual)  # type: ignore[arg-type]
        p.duration_at_speed(f"{node}.duration", length, f"{node}.speed")
    p.add(" + ".join(f"{n}.duration" for n in lengths) + " <= endurance_left")


# --- the text form -------------------------------------------------------------------------------------


def test_parse_moves_variables_left_and_numbers_right() -> None:
    lin = parse_linear("n3.duration + n5.duration <= endurance_left")
    assert (dict(lin.terms), lin.op, lin.rhs) == ({"n3.duration": 1, "n5.duration": 1, "endurance_left": -1},
                                                 "<=", 0)
    lin = parse_linear("2 * n3.altitude >= 5")
    assert (dict(lin.terms), lin.op, lin.rhs) == ({"n3.altitude": 2}, ">=", 5)
    lin = parse_linear("n4.altitude - 0.5 * (n3.altitude + n5.altitude) + 1 == 3")
    assert dict(lin.terms) == {"n4.altitude": 1, "n3.altitude": -0.5, "n5.altitude": -0.5}
    assert lin.rhs == 2
    lin = parse_linear("-x / 4 + 2e1 >= -(y - 3) * 2")
    assert dict(lin.terms) == {"x": -0.25, "y": 2} and lin.rhs == -14


def test_parse_names_with_dots_dashes_and_underscores() -> None:
    lin = parse_linear("n3.fly-to.speed + scan_ground-b.alt_max2 <= max_speed")
    assert set(lin.terms) == {"n3.fly-to.speed", "scan_ground-b.alt_max2", "max_speed"}
    # a dash before a digit is a minus; spaces make a subtraction of two names
    lin = parse_linear("x-1 <= y - z")
    assert dict(lin.terms) == {"x": 1, "y": -1, "z": 1} and lin.rhs == 1


def test_terms_that_cancel_and_str() -> None:
    lin = parse_linear("a + b <= a + 3")
    assert dict(lin.terms) == {"b": 1} and lin.rhs == 3
    assert str(Linear({"a": 1, "b": -2}, ">=", 1.5)) == "a - 2 * b >= 1.5"


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("n3.speed < 5", "column 10: unknown operator '<'"),
        ("n3.speed = 5", "column 10: unknown operator '='"),
        ("a != b", "column 3: unknown operator '!='"),
        ("a * b <= 3", "column 1: non-linear term 'a * b'"),
        ("2 * (a + 1) * b >= 0", "column 1: non-linear term '2 * (a + 1) * b'"),
        ("n3.length / n3.speed <= 60", "column 1: non-linear term 'n3.length / n3.speed'"),
        ("n3.speed <= $5", "column 13: unexpected character '$'"),
        ("n3.speed 5", "column 10: expected an operator but found '5'"),
        ("n3.speed + 2", "column 13: no comparison operator"),
        ("a <= b <= c", "column 8: unexpected a second comparison"),
        ("3 <= 5", "no variables"),
        ("a + a <= a + a", "no variables"),
        ("a / 0 <= 1", "column 3: division by zero"),
        ("(a + b <= 1", "missing ')'"),
        ("a + <= 1", "column 5: expected a number, a name or '(' but found '<='"),
        ("", "empty constraint"),
        ("a <= 1e999", "out of range"),
    ],
)
def test_bad_text_says_where(text: str, expected: str) -> None:
    with pytest.raises(ConstraintError) as err:
        parse_linear(text)
    assert expected in str(err.value)
    assert repr(text) in str(err.value)


def test_bad_text_in_add_names_the_label() -> None:
    p = ConstraintProblem()
    p.variable("a")
    p.variable("b")
    with pytest.raises(ConstraintError, match=r"'n4 ceiling'.*column 1: non-linear term 'a \* b'"):
        p.add("a * b <= 30", label="n4 ceiling")
    with pytest.raises(ConstraintError, match="unknown operator"):
        Linear({"a": 1}, "<", 3)


# --- solving: free parameters fixed ------------------------------------------------------------------


def test_feasible_problem_fixes_free_parameters() -> None:
    p = ConstraintProblem()
    p.variable("n3.altitude", lo=4, hi=20)  # free: middle of the interval
    p.variable("n5.altitude", lo=3)  # half-bounded: its bound
    p.variable("n6.altitude", value=7.5)  # given
    p.variable("n7.altitude", lo=4, hi=16)  # nothing else on it: the middle, not a vertex
    p.variable("n8.altitude", hi=25)
    p.variable("ceiling", value=12)
    p.add("n3.altitude <= ceiling", label="n3.altitude <= envelope ceiling 12 m")
    p.qualitative("n3.speed", SPEEDS)
    p.duration_at_speed("n3.duration", 500, "n3.speed", extra_s=4)
    sol = p.solve()
    assert sol.ok, sol.message
    assert sol.conflict == []
    # middle of [4, 20] is 12, exactly at the ceiling
    assert sol.values["n3.altitude"] == pytest.approx(12)
    assert sol.values["n5.altitude"] == pytest.approx(3)
    assert sol.values["n6.altitude"] == 7.5
    assert sol.values["n7.altitude"] == pytest.approx(10)
    assert sol.values["n8.altitude"] == pytest.approx(25)
    assert sol.choices == {"n3.speed": "fast"}
    assert sol.values["n3.speed"] == 5.0
    assert sol.values["n3.duration"] == pytest.approx(500 / 5 + 4)
    p.add("n3.altitude <= 8", label="lower ceiling")  # the middle is clipped to the nearest feasible
    assert p.solve().values["n3.altitude"] == pytest.approx(8)


def test_objective_and_prefer() -> None:
    p = ConstraintProblem()
    p.variable("alt", lo=4, hi=20)
    p.qualitative("n1.speed", SPEEDS)
    p.qualitative("n2.speed", SPEEDS, prefer="slow")
    assert p.solve(objective={"alt": 1}).values["alt"] == pytest.approx(4)
    assert p.solve(objective={"alt": -1}).values["alt"] == pytest.approx(20)
    assert p.solve().choices == {"n1.speed": "fast", "n2.speed": "slow"}
    assert p.solve(prefer="standard").choices == {"n1.speed": "standard", "n2.speed": "standard"}
    assert p.solve(prefer="min").choices == {"n1.speed": "slow", "n2.speed": "slow"}
    assert p.solve(objective={"n2.speed": -1}).choices["n2.speed"] == "fast"
    free = ConstraintProblem()
    free.variable("a", hi=3)
    assert free.solve().message == "accepted"
    sol = free.solve(objective={"a": -1})
    assert sol.ok and sol.values["a"] == 3
    sol = free.solve(objective={"a": 1})  # unbounded: no decision, and no conflict either
    assert not sol.ok and sol.conflict == [] and sol.message.startswith("not decided: the solver stopped")
    with pytest.raises(ConstraintError, match="prefer 'warp'"):
        p.solve(prefer="warp")
    with pytest.raises(ConstraintError, match="objective: unknown variable 'nope'"):
        p.solve(objective={"nope": 1})


def test_endurance_fast_only_where_needed() -> None:
    # 3 x 1000 m; standard everywhere is 1500 s, one fast leg 1200 s, two fast legs 900 s <= 1100 s
    p = ConstraintProblem()
    legs(p, {"n2": 1000, "n3": 1000, "n4": 1000}, 1100)
    sol = p.solve(prefer="standard")
    assert sol.ok, sol.message
    assert sorted(sol.choices.values()) == ["fast", "fast", "standard"]
    total = sum(sol.values[f"n{i}.duration"] for i in (2, 3, 4))
    assert total == pytest.approx(900)
    for i in (2, 3, 4):
        assert sol.values[f"n{i}.duration"] == pytest.approx(1000 / sol.values[f"n{i}.speed"])


def test_qualitative_choices_respect_constraints() -> None:
    p = ConstraintProblem()
    p.variable("max_speed", value=2.5, label="max_speed 2.5 m/s (autopilot WPNAV_SPEED)")
    p.qualitative("n3.speed", SPEEDS)
    p.qualitative("n4.speed", SPEEDS, allowed=["slow", "fast"])
    p.qualitative("n5.altitude", {"low": 3, "standard": 10, "high": 40}, allowed="standard")
    p.add("n3.speed <= max_speed")
    p.add("n4.speed <= max_speed")
    sol = p.solve()
    assert sol.ok, sol.message
    assert sol.choices == {"n3.speed": "standard", "n4.speed": "slow", "n5.altitude": "standard"}
    assert sol.values["n5.altitude"] == 10


def test_duration_at_given_speed_and_refusals() -> None:
    p = ConstraintProblem()
    p.variable("n3.commanded-speed", value=4)
    p.duration_at_speed("n3.duration", 100, "n3.commanded-speed", extra_s=5)
    assert p.solve().values["n3.duration"] == pytest.approx(30)
    p.variable("n4.speed", lo=1, hi=5)
    with pytest.raises(ConstraintError, match=r"non-linear while n4\.speed is free"):
        p.duration_at_speed("n4.duration", 100, "n4.speed")
    with pytest.raises(ConstraintError, match=r"unknown speed variable 'n9\.speed'"):
        p.duration_at_speed("n9.duration", 100, "n9.speed")
    p.qualitative("n5.speed", {"hover": 0, "slow": 1})
    with pytest.raises(ConstraintError, match="hover is 0, not a speed > 0"):
        p.duration_at_speed("n5.duration", 100, "n5.speed")
    with pytest.raises(ConstraintError, match="length -1"):
        p.duration_at_speed("n6.duration", -1, "n3.commanded-speed")


def test_declaration_errors() -> None:
    p = ConstraintProblem()
    p.variable("a", lo=0)
    with pytest.raises(ConstraintError, match="variable a declared twice"):
        p.variable("a")
    with pytest.raises(ConstraintError, match="unknown variable 'b'"):
        p.add("a + b <= 3")
    with pytest.raises(ConstraintError, match="either a value or an interval"):
        p.variable("c", lo=1, value=2)
    with pytest.raises(ConstraintError, match="hi inf is not a finite number"):
        p.variable("d", hi=float("inf"))
    with pytest.raises(ConstraintError, match="bad variable name '2x'"):
        p.variable("2x")
    with pytest.raises(ConstraintError, match="'warp' is not one of"):
        p.qualitative("s", SPEEDS, allowed="warp")
    p.add("a <= 3", label="limit")
    with pytest.raises(ConstraintError, match="two constraints labelled 'limit'"):
        p.add("a <= 4", label="limit")
    loose = ConstraintProblem(strict=False)
    loose.add("a + b <= 3")
    loose.variable("a", lo=5)
    assert loose.solve().ok and loose.variables == ["a", "b"]


# --- solving: the conflicts named --------------------------------------------------------------------


def test_endurance_exceeded_names_the_endurance_and_the_speeds() -> None:
    p = ConstraintProblem()
    p.variable("n2.altitude", lo=2, hi=40)  # unrelated: never in the conflict
    legs(p, {"n2": 1000, "n3": 1100, "n4": 1000}, 600)  # 3100 m at 5 m/s is 620 s
    sol = p.solve()
    assert sol.conflict == [
        "endurance_left 600 s",
        "n2.speed in {slow, standard, fast}",
        "n3.speed in {slow, standard, fast}",
        "n4.speed in {slow, standard, fast}",
        "n2.duration + n3.duration + n4.duration <= endurance_left",
    ]
    assert sol.message.startswith("rejected: endurance_left 600 s (battery); n2.speed in {slow, standard, "
                                  "fast} (max 5 m/s);")
    assert sol.values == {} and sol.choices == {}
    assert_irreducible(p, sol)


def test_endurance_with_given_speeds_names_only_the_free_one() -> None:
    p = ConstraintProblem()
    p.variable("endurance_left", value=600, label="endurance_left 600 s")
    p.variable("n2.speed", value=5)
    p.duration_at_speed("n2.duration", 1500, "n2.speed")
    p.qualitative("n3.speed", SPEEDS, allowed=["slow", "standard"])
    p.duration_at_speed("n3.duration", 700, "n3.speed")
    p.add("n2.duration + n3.duration <= endurance_left")
    sol = p.solve()  # 300 s + 350 s at standard
    assert sol.conflict == ["endurance_left 600 s", "n3.speed in {slow, standard, fast}",
                            "n3.speed in {slow, standard} (given)",
                            "n2.duration + n3.duration <= endurance_left"]
    assert_irreducible(p, sol)


def test_altitude_above_ceiling() -> None:
    p = ConstraintProblem()
    p.variable("n3.altitude", lo=2, hi=40)
    p.variable("n4.altitude", value=35, label="n4.altitude = 35 (given)")
    p.add("n3.altitude <= 30", label="n3.altitude <= envelope ceiling 30 m")
    p.add("n4.altitude <= 30", label="n4.altitude <= envelope ceiling 30 m", reason="fence FENCE_ALT_MAX")
    sol = p.solve()
    assert sol.conflict == ["n4.altitude = 35 (given)", "n4.altitude <= envelope ceiling 30 m"]
    assert sol.details[1] == "n4.altitude <= envelope ceiling 30 m (fence FENCE_ALT_MAX)"
    assert_irreducible(p, sol)


def test_speed_interval_empty_against_platform_max() -> None:
    p = ConstraintProblem()
    p.variable("max_speed", value=5, label="max_speed 5 m/s")
    p.variable("n3.commanded-speed", lo=6, hi=8)
    p.variable("n4.commanded-speed", lo=3, hi=8)
    p.add("n3.commanded-speed <= max_speed")
    p.add("n4.commanded-speed <= max_speed")
    sol = p.solve()
    assert sol.conflict == ["max_speed 5 m/s", "n3.commanded-speed in [6, 8]",
                            "n3.commanded-speed <= max_speed"]
    assert_irreducible(p, sol)
    q = ConstraintProblem()
    q.variable("n3.speed", lo=9, hi=6)  # empty on its own
    sol = q.solve()
    assert sol.conflict == ["n3.speed in [9, 6]"]


def test_contradictory_equalities() -> None:
    p = ConstraintProblem()
    for v in ("a", "b", "c"):
        p.variable(v)
    p.add("a + b == 10")
    p.add("a - b == 2")  # a = 6, b = 4
    p.add("c == 2 * a")
    p.add("a == 7")
    sol = p.solve()
    assert sol.conflict == ["a + b == 10", "a - b == 2", "a == 7"]
    assert_irreducible(p, sol)


def test_independent_conflicts_are_all_named() -> None:
    p = ConstraintProblem()
    legs(p, {"n2": 2000}, 300)
    p.variable("n3.altitude", lo=35, hi=40)
    p.add("n3.altitude <= 30", label="ceiling 30 m")
    sol = p.solve()
    assert sol.conflict == ["endurance_left 300 s", "n2.speed in {slow, standard, fast}",
                            "n2.duration <= endurance_left", "n3.altitude in [35, 40]", "ceiling 30 m"]


def test_inconsistent_definitions_are_named() -> None:
    p = ConstraintProblem()
    p.variable("v", value=5)
    p.duration_at_speed("d", 100, "v", label="d from the path")
    p.add("d == 30", label="d from the log", definition=True)
    sol = p.solve()
    # the given speed is folded into the definition: only the two definitions disagree
    assert sol.conflict == ["d from the path", "d from the log"]


# --- the conflict search ------------------------------------------------------------------------------


def test_minimal_conflict_few_calls() -> None:
    calls = []

    def feasible(ix: object) -> bool:
        calls.append(1)
        return not {17, 42, 88} <= set(ix)  # type: ignore[call-overload]

    assert minimal_conflict(range(100), feasible) == [17, 42, 88]
    assert len(calls) < 40  # the deletion filter needs 100
    assert minimal_conflict(range(10), lambda ix: True) == []
    assert minimal_conflict([5], lambda ix: 5 not in ix) == [5]
    assert minimal_conflict([1, 2], lambda ix: not {0, 2} <= set(ix), background=[0]) == [2]


def test_components() -> None:
    assert components([[0], [1], [0, 2], [3], [2], [1]]) == [[0, 2, 4], [1, 5], [3]]
    assert components([]) == []
