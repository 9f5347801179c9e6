"""The memory of beliefs and the belief manager (seed 001 Sec. 5.2.2, 6.2.4)."""

from __future__ import annotations

import json
import threading

import pytest

from companion.behaviors.beliefs import (
    Belief,
    BeliefError,
    BeliefMemory,
    Var,
    belief_from_json,
    belief_to_json,
    bindings_to_json,
    parse_belief,
    parse_query,
    term_from_json,
    term_to_json,
)

# --- the text form -----------------------------------------------------------------------------------


def test_parse_and_print_round_trip() -> None:
    cases = {
        "position(57, (3.0, 4.5, 0.0))": Belief("position", (57, (3.0, 4.5, 0.0))),
        "visible(32)": Belief("visible", (32,)),
        "charge(92, full)": Belief("charge", (92, "full")),
        'name(5, "front door")': Belief("name", (5, "front door")),
        "offset(self, (-1.5, 0.25, 1000.0))": Belief("offset", ("self", (-1.5, 0.25, 1000.0))),
        "Flight_state(self, flying)": Belief("Flight_state", ("self", "flying")),
        "path(7, ((1, 2), (3, 4), ()))": Belief("path", (7, ((1, 2), (3, 4), ()))),
    }
    for text, belief in cases.items():
        assert parse_belief(text) == belief
        assert str(belief) == text
        assert parse_belief(str(belief)) == belief
    # spacing is free; a quoted identifier is the same term as the bare symbol
    assert parse_belief("  charge ( 92 ,\"full\" ) ") == Belief("charge", (92, "full"))
    assert parse_belief('note(1, "say \\"hi\\"")').args[1] == 'say "hi"'
    b = parse_belief("k(1e3, -2)")
    assert b.args == (1000.0, -2) and isinstance(b.args[0], float) and isinstance(b.args[1], int)


@pytest.mark.parametrize("text, fragment", [
    ("", "empty"),
    ("   ", "empty"),
    ("charge(92, full", "column 16: expected ')' or ','"),
    ("charge(92 full)", "column 11: expected ')' or ','"),
    ("charge(92, full) x", "column 18: expected the end"),
    ("charge(92, &)", "column 12: unknown character '&'"),
    ("charge(?x, full)", "variable ?x in a belief"),
    ("p(1, 2, 3)", "3 arguments"),
    ("p()", "column 3: expected a term"),
    ("p(12ab)", "bad number"),
    ('p("open)', "string not closed"),
    ("(1, 2)", "expected a predicate name"),
    ("p(1), q(2)", "expected the end"),
])
def test_bad_belief_text(text: str, fragment: str) -> None:
    with pytest.raises(BeliefError) as err:
        parse_belief(text)
    assert str(err.value).startswith("belief: ")
    assert fragment in str(err.value)


@pytest.mark.parametrize("text, fragment", [
    ("", "query: empty"),
    ("object(?x, battery) charge(?x, ?y)", "query: column 21: expected the end or ','"),
    ("object(?x, battery), charge(?x ?y)", "query: column 32: expected ')' or ','"),
    ("object(?x, battery),", "query: column 21: expected a predicate name but found the end"),
    ("object(?, battery)", "query: column 8: '?' must be followed by a variable name"),
    ("object(?x; battery)", "query: column 10: unknown character ';'"),
])
def test_bad_query_text(text: str, fragment: str) -> None:
    with pytest.raises(BeliefError) as err:
        parse_query(text)
    assert fragment in str(err.value)


def test_query_structure() -> None:
    q = parse_query("object(?x, battery), charge(?x, ?y), position(?x, (?n, 4.5, ?u))")
    assert len(q.patterns) == 3
    assert q.variables == ("x", "y", "n", "u")
    assert q.patterns[2].args[1] == (Var("n"), 4.5, Var("u"))
    assert str(q) == "object(?x, battery), charge(?x, ?y), position(?x, (?n, 4.5, ?u))"


def test_belief_construction_is_checked() -> None:
    with pytest.raises(BeliefError):
        Belief("charge", (92, True))
    with pytest.raises(BeliefError):
        Belief("charge", (92, float("nan")))
    with pytest.raises(BeliefError):
        Belief("bad name", (1,))
    with pytest.raises(BeliefError):
        Belief("p", ())
    with pytest.raises(BeliefError):
        Belief("p", (Var("x"),))
    assert Belief("position", (1, [1.0, 2.0])) == Belief("position", (1, (1.0, 2.0)))  # JSON lists


# --- adding, removing, exclusive values -------------------------------------------------------------------


def test_exclusive_values_are_retracted() -> None:
    m = BeliefMemory()
    assert m.add("object(92, battery)") == []
    assert m.add("charge(92, full)") == []
    assert m.add("charge(92, empty)") == [Belief("charge", (92, "full"))]
    assert m.value("charge", 92) == "empty"
    assert Belief("charge", (92, "full")) not in m
    assert "charge(92, empty)" in m
    # other objects are independent; a one-arg belief of the same name is not an attribute value
    m.add("charge(93, full)")
    m.add("charge(92)")
    assert m.add("charge(92, low)") == [Belief("charge", (92, "empty"))]
    assert m.holds("charge(92)") and m.value("charge", 93) == "full"


def test_multi_valued_predicates_keep_every_value() -> None:
    m = BeliefMemory(multi_valued=["color"])
    m.add("color(32, blue)")
    assert m.add("color(32, red)") == []
    assert sorted(m.values("color", 32)) == ["blue", "red"]
    with pytest.raises(BeliefError, match="multi-valued"):
        m.value("color", 32)
    assert m.remove("color(32, blue)") is True
    assert m.values("color", 32) == ["red"]


def test_version_counts_changes_only() -> None:
    m = BeliefMemory()
    v0 = m.version
    m.add("visible(32)")
    v1 = m.version
    assert v1 > v0
    m.add("visible(32)")  # already held: no change
    assert m.version == v1
    assert m.remove("visible(33)") is False and m.version == v1
    assert m.remove("visible(32)") is True and m.version > v1
    m.add("a(1)")
    v2 = m.version
    m.clear()
    assert len(m) == 0 and m.version > v2


def test_bad_input_changes_nothing() -> None:
    m = BeliefMemory()
    m.add("charge(92, full)")
    before, v = m.beliefs(), m.version
    for bad in ("charge(92, ?x)", "charge(92, empty", "", "charge(92, full, x)"):
        with pytest.raises(BeliefError):
            m.add(bad)
    with pytest.raises(BeliefError):
        m.add_all(["charge(92, empty)", "charge(92, "])  # one bad: none added
    with pytest.raises(BeliefError):
        m.consult("charge(?x")
    with pytest.raises(BeliefError):
        m.add(42)  # type: ignore[arg-type]
    assert m.beliefs() == before and m.version == v


def test_add_all_reports_what_it_retracted_from_before() -> None:
    m = BeliefMemory()
    m.add("charge(1, full)")
    retracted = m.add_all(["charge(1, high)", "charge(1, medium)", "visible(3)"])
    assert retracted == [Belief("charge", (1, "full"))]
    assert m.value("charge", 1) == "medium"


def test_forget_removes_every_value_of_an_attribute() -> None:
    m = BeliefMemory(multi_valued=["color"])
    m.add_all(["color(1, red)", "color(1, blue)", "color(2, red)"])
    assert sorted(map(str, m.forget("color", 1))) == ["color(1, blue)", "color(1, red)"]
    assert m.beliefs() == [Belief("color", (2, "red"))]
    assert m.forget("color", 1) == []


# --- consulting --------------------------------------------------------------------------------------------


def _world() -> BeliefMemory:
    m = BeliefMemory(multi_valued=["color", "same"])
    m.add_all([
        "object(92, battery)", "charge(92, full)",
        "object(93, battery)", "charge(93, low)",
        "object(32, obstacle)", "color(32, blue)", "color(32, red)", "visible(32)",
        "object(57, aerial_robot)", "position(57, (3.0, 4.5, 0.0))",
        "object(58, aerial_robot)", "position(58, (1.0, 1.0, 0.0))",
        "same(4, 4)", "same(4, 5)",
    ])
    return m


def test_conjunction_returns_every_binding() -> None:
    m = _world()
    got = m.consult("object(?x, battery), charge(?x, ?y)")
    assert sorted(got, key=lambda b: b["x"]) == [{"x": 92, "y": "full"}, {"x": 93, "y": "low"}]
    assert m.consult("object(?x, obstacle), visible(?x), color(?x, ?c)") == [
        {"x": 32, "c": "blue"}, {"x": 32, "c": "red"}]
    assert m.consult("object(?x, battery), charge(?x, empty)") == []


def test_ground_queries() -> None:
    m = _world()
    assert m.consult("charge(92, full)") == [{}]
    assert m.consult("charge(92, low)") == []
    assert m.consult("visible(32), charge(92, full)") == [{}]
    assert m.holds("visible(32)") and not m.holds("visible(57)")
    assert m.holds(Belief("charge", (93, "low")))


def test_repeated_variables_unify() -> None:
    m = _world()
    assert m.consult("same(?a, ?a)") == [{"a": 4}]
    # a variable bound in one pattern constrains the next
    assert m.consult("charge(?b, low), object(?b, ?kind)") == [{"b": 93, "kind": "battery"}]
    assert m.consult("charge(?b, low), object(?b, obstacle)") == []


def test_tuple_patterns_with_variables() -> None:
    m = _world()
    assert m.consult("position(?r, (?n, 4.5, ?u))") == [{"r": 57, "n": 3.0, "u": 0.0}]
    assert sorted(b["r"] for b in m.consult("position(?r, (?n, ?e, 0))")) == [57, 58]  # 0 == 0.0
    assert m.consult("position(?r, (?n, ?n, ?u))") == [{"r": 58, "n": 1.0, "u": 0.0}]
    assert m.consult("position(57, ?p)") == [{"p": (3.0, 4.5, 0.0)}]
    assert m.consult("position(57, (?n, ?e))") == []  # wrong length
    # a bound tuple can be used as an object
    m.add("label((3.0, 4.5, 0.0), gate)")
    assert m.consult("position(57, ?p), label(?p, ?l)") == [{"p": (3.0, 4.5, 0.0), "l": "gate"}]


def test_strings_and_numbers_do_not_unify() -> None:
    m = BeliefMemory()
    m.add('code(1, "92")')
    m.add("code(2, 92)")
    assert m.consult("code(?x, 92)") == [{"x": 2}]
    assert m.consult('code(?x, "92")') == [{"x": 1}]


def test_consult_joins_in_a_large_memory_and_text_queries_are_cached() -> None:
    """The answer over 900 beliefs (how fast: ``python -m bench.bench_hotpath``, not a test)."""
    m = BeliefMemory()
    for i in range(300):
        m.add(f"object({i}, {'battery' if i % 10 == 0 else 'obstacle'})")
        m.add(f"charge({i}, {'full' if i % 20 == 0 else 'low'})")
        m.add(f"position({i}, ({i}.0, 1.0, 2.0))")
    assert len(m) == 900
    q = parse_query("object(?x, battery), charge(?x, full)")
    assert sorted(b["x"] for b in m.consult(q)) == list(range(0, 300, 20))
    assert m.holds("charge(150, low)") and not m.holds("charge(160, low)")
    assert parse_query("charge(150, low)") is parse_query("charge(150, low)")  # parsed once, then cached


def test_concurrent_writers_keep_one_value() -> None:
    m = BeliefMemory()
    levels = ["full", "high", "medium", "low", "empty"]
    errors: list[BaseException] = []

    def writer(k: int) -> None:
        try:
            for i in range(400):
                m.add(Belief("charge", (1, levels[(i + k) % 5])))
                assert len(m.consult("charge(1, ?v)")) == 1
        except BaseException as exc:  # reported below
            errors.append(exc)

    threads = [threading.Thread(target=writer, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(10.0)
    assert not errors
    assert len(m.values("charge", 1)) == 1 and len(m) == 1


# --- JSON --------------------------------------------------------------------------------------------------


def test_json_conversions() -> None:
    b = parse_belief("position(57, (3.0, 4.5, 0.0))")
    data = json.loads(json.dumps(belief_to_json(b)))
    assert data == {"predicate": "position", "args": [57, [3.0, 4.5, 0.0]],
                    "text": "position(57, (3.0, 4.5, 0.0))"}
    assert belief_from_json(data) == b
    assert belief_from_json("charge(92, full)") == Belief("charge", (92, "full"))
    assert term_to_json(((1, 2), "a")) == [[1, 2], "a"]
    assert term_from_json([[1, 2], "a"]) == ((1, 2), "a")
    assert bindings_to_json([{"p": (1.0, 2.0)}]) == [{"p": [1.0, 2.0]}]
    for bad in ({"a": 1}, None, True):
        with pytest.raises(BeliefError):
            term_from_json(bad)
    with pytest.raises(BeliefError):
        belief_from_json({"predicate": "p"})


def test_answers_are_copies_and_objects_may_come_from_json() -> None:
    m = _world()
    first = m.consult("position(57, ?p)")[0]
    first["p"] = "tampered"
    assert m.consult("position(57, ?p)") == [{"p": (3.0, 4.5, 0.0)}]
    m.add("label((3.0, 4.5, 0.0), gate)")
    assert m.values("label", [3.0, 4.5, 0.0]) == ["gate"] and m.value("label", (3.0, 4.5, 0.0)) == "gate"
    assert m.first("object(?x, obstacle)") == {"x": 32} and m.first("object(?x, tree)") is None
