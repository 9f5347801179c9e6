"""TST parameters (seed 000 Sec. III): values and constraints, geopoints and their local frame."""

from __future__ import annotations

import math

import pytest

from companion.tst.params import (
    Interval,
    LinearRelation,
    ParamError,
    Qualitative,
    area_to_local,
    check_area,
    check_geopoint,
    check_geopoints,
    constraint_to_json,
    geopoint_to_ned,
    is_free,
    parse_constraint,
)
from taskflight_common.geo import ned_to_geodetic

HOME = (58.3950, 15.5730)


def test_interval_bounds_and_membership() -> None:
    iv = Interval(1, 3)
    assert (iv.lo, iv.hi) == (1.0, 3.0)
    assert iv.contains(1.0) and iv.contains(3.0) and not iv.contains(3.01)
    with pytest.raises(ParamError, match="empty interval"):
        Interval(4, 3)
    with pytest.raises(ParamError, match="finite"):
        Interval(0, math.inf)


def test_qualitative_from_text_and_list() -> None:
    assert Qualitative.parse("slow | standard | fast").options == ("slow", "standard", "fast")
    assert Qualitative.parse(["slow", "fast"]) == Qualitative(("slow", "fast"))
    assert str(Qualitative.parse("slow|fast")) == "slow | fast"
    with pytest.raises(ParamError, match="repeated"):
        Qualitative.parse("slow | slow")
    with pytest.raises(ParamError, match="not a word"):
        Qualitative.parse("slow | ")


def test_relation_simple() -> None:
    rel = LinearRelation.parse("duration <= endurance_left")
    assert rel.text == "duration <= endurance_left"
    assert dict(rel.coefficients) == {"duration": 1.0, "endurance_left": -1.0}
    assert rel.op == "<=" and rel.constant == 0.0
    assert rel.evaluate({"duration": 100, "endurance_left": 120})
    assert not rel.evaluate({"duration": 130, "endurance_left": 120})


def test_relation_coefficients_and_constants_move_sides() -> None:
    rel = LinearRelation.parse("altitude >= 2 * min_altitude + 1")
    assert dict(rel.coefficients) == {"altitude": 1.0, "min_altitude": -2.0}
    assert rel.constant == 1.0 and rel.op == ">="
    assert rel.evaluate({"altitude": 5.0, "min_altitude": 2.0})
    assert not rel.evaluate({"altitude": 4.9, "min_altitude": 2.0})
    rel2 = LinearRelation.parse("2*a + 3 - b/2 == 10 - a")
    assert dict(rel2.coefficients) == {"a": 3.0, "b": -0.5}
    assert rel2.constant == 7.0


def test_relation_names_may_be_dotted_node_parameters() -> None:
    rel = LinearRelation.parse("n3.altitude - n5.altitude >= 1.5")
    assert rel.names == ("n3.altitude", "n5.altitude")


@pytest.mark.parametrize("text, reason", [
    ("x * y <= 1", "non-linear term 'x \\* y'"),
    ("3 <= 4", "no variables"),
    ("a < b", "use <=, >= or =="),
    ("a <= b <= c", "a second comparison"),
    ("a + b", "no comparison operator"),
    ("a <= ", "ends too early"),
    ("a <= b $", "column 8"),
    ("a / 0 <= 1", "division by zero"),
    ("a / b <= 1", "division by a variable"),
    ("a b <= 1", "expected an operator but found 'b'"),
])
def test_relation_errors(text: str, reason: str) -> None:
    with pytest.raises(ParamError, match=reason):
        LinearRelation.parse(text)


def test_relation_uses_the_solvers_grammar_with_parentheses() -> None:
    """A mission may write what the constraint solver reads (one grammar: companion.tst.linear)."""
    rel = LinearRelation.parse("altitude - 0.5 * (ceiling + floor) >= -(1 + 1)")
    assert dict(rel.coefficients) == {"altitude": 1.0, "ceiling": -0.5, "floor": -0.5}
    assert rel.op == ">=" and rel.constant == -2.0
    assert rel.evaluate({"altitude": 4.0, "ceiling": 10.0, "floor": 2.0})
    assert not rel.evaluate({"altitude": 0.9, "ceiling": 10.0, "floor": 2.0})


def test_relation_evaluate_needs_every_name() -> None:
    with pytest.raises(ParamError, match="no value for endurance_left"):
        LinearRelation.parse("duration <= endurance_left").evaluate({"duration": 1})


def test_parse_constraint_forms_and_round_trip() -> None:
    assert parse_constraint("standard") is None
    assert parse_constraint(3.0) is None
    assert parse_constraint("slow | fast") == Qualitative(("slow", "fast"))
    assert parse_constraint({"one_of": ["slow"]}) == Qualitative(("slow",))
    assert parse_constraint({"interval": [1, 2]}) == Interval(1.0, 2.0)
    rel = parse_constraint("duration <= endurance_left")
    assert isinstance(rel, LinearRelation)
    assert parse_constraint({"relation": "duration <= endurance_left"}) == rel
    for c in (Interval(1, 2), Qualitative(("a", "b")), rel):
        assert is_free(c)
        assert parse_constraint(constraint_to_json(c)) == c
    assert not is_free(3.0) and not is_free("fast")
    with pytest.raises(ParamError, match="unknown constraint 'range'"):
        parse_constraint({"range": [1, 2]})
    with pytest.raises(ParamError, match=r"interval: expected \[lo, hi\]"):
        parse_constraint({"interval": [1, 2, 3]})


@pytest.mark.parametrize("value, reason", [
    ([58.0, 15.0], r"expected a geopoint \[lat, lon, alt\]"),
    ([58.0, 15.0, 1.0, 2.0], "expected a geopoint"),
    ([91.0, 15.0, 1.0], "latitude 91 out of range"),
    ([58.0, -181.0, 1.0], "longitude -181 out of range"),
    ([58.0, 15.0, "high"], "altitude: expected a finite number"),
    ("58, 15, 1", "expected a geopoint"),
    ([True, 15.0, 1.0], "latitude"),
])
def test_bad_geopoints(value: object, reason: str) -> None:
    with pytest.raises(ParamError, match=reason):
        check_geopoint(value)


def test_geopoints_same_length_and_index_of_bad_item() -> None:
    assert check_geopoints([[1, 2], [3, 4]]) == ((1.0, 2.0), (3.0, 4.0))
    with pytest.raises(ParamError) as exc:
        check_geopoints([[1, 2, 3], [1, 2]])
    assert exc.value.index == 1
    with pytest.raises(ParamError) as exc:
        check_geopoints([[1, 2], [1, 200]])
    assert exc.value.index == 1 and "longitude 200" in exc.value.reason


def test_area_polygon_checks() -> None:
    square = [[58.0, 15.0], [58.0, 15.001], [58.001, 15.001], [58.001, 15.0]]
    assert len(check_area(square)) == 4
    with pytest.raises(ParamError, match="at least 3"):
        check_area(square[:2])
    with pytest.raises(ParamError, match="crosses itself"):
        check_area([[58.0, 15.0], [58.001, 15.001], [58.0, 15.001], [58.001, 15.0]])
    with pytest.raises(ParamError, match="no area"):
        check_area([[58.0, 15.0], [58.001, 15.0], [58.002, 15.0]])


def test_geopoint_to_ned_inverts_ardupilot_geodesy() -> None:
    """A point placed n, e metres from home with taskflight_common.geo comes back as (n, e, alt)."""
    lat, lon, _ = ned_to_geodetic((HOME[0], HOME[1], 0.0), 30.0, -12.0, 0.0)
    n, e, down = geopoint_to_ned((lat, lon, 4.5), HOME)
    up = -down
    assert n == pytest.approx(30.0, abs=1e-6)
    assert e == pytest.approx(-12.0, abs=1e-6)
    assert up == 4.5


def test_area_to_local_square_of_10_m() -> None:
    corners = [ned_to_geodetic((HOME[0], HOME[1], 0.0), n, e, 0.0)[:2] for n, e in
               [(0, 0), (0, 10), (10, 10), (10, 0)]]
    local = area_to_local(corners, HOME)
    for (n, e), (en, ee) in zip(local, [(0, 0), (0, 10), (10, 10), (10, 0)], strict=True):
        assert n == pytest.approx(en, abs=1e-6) and e == pytest.approx(ee, abs=1e-6)
