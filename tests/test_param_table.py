"""The tables guarding parameter writes (mission_specs/param_table.py): ArduCopter's documented ranges, the
model's own metadata (the bundled file is what the model declares now), and the one rule both the ground
service and the companion apply, each refusal naming the request's field."""

from __future__ import annotations

import pytest

from mission_specs.param_table import MAX_IN_FLIGHT_CHANGE, ParamWriteError, known, table


def test_arducopter_table_has_the_documented_ranges_of_the_tunable_parameters() -> None:
    t = table("arducopter")
    rll = t.spec("ATC_RAT_RLL_P")
    assert (rll.min, rll.max) == (0.01, 0.5)  # ArduPilot: @Range: 0.01 0.5
    for name in ("ATC_RAT_PIT_I", "ATC_RAT_YAW_D", "PSC_VELXY_P", "WPNAV_SPEED", "WPNAV_ACCEL", "ANGLE_MAX",
                 "LOIT_SPEED", "RTL_ALT", "FENCE_RADIUS", "FENCE_ACTION", "BATT_FS_LOW_ACT", "BATT_LOW_VOLT"):
        assert name in t, name
    assert t.spec("WPNAV_SPEED").units == "cm/s"
    assert t.spec("FENCE_ACTION").values and t.spec("FENCE_ACTION").integer
    assert all(s.min <= s.max for s in t.params.values())


def test_the_model_table_is_what_the_model_declares() -> None:
    from autopilot_model.param_table import OUT, render

    assert OUT.read_text(encoding="utf-8") == render(), "stale: run python -m autopilot_model.param_table"
    m = table("model")
    assert (m.spec("ATC_RAT_RLL_P").min, m.spec("ATC_RAT_RLL_P").max) == (0.0, 200.0)
    assert (m.spec("BATT_MONITOR").min, m.spec("BATT_MONITOR").max) == (4.0, 4.0)  # the only value it flies


@pytest.mark.parametrize(("name", "value", "field", "words"), [
    ("NO_SUCH_PARAM", 1.0, "name", "not a parameter"),
    ("ATC_RAT_RLL_P", "", "value", "empty"),
    ("ATC_RAT_RLL_P", "  ", "value", "empty"),
    ("ATC_RAT_RLL_P", None, "value", "empty"),
    ("ATC_RAT_RLL_P", "high", "value", "not a number"),
    ("ATC_RAT_RLL_P", float("nan"), "value", "finite"),
    ("ATC_RAT_RLL_P", 0.0, "value", "out of range [0.01, 0.5]"),
    ("ATC_RAT_RLL_P", 7.0, "value", "out of range"),
    ("FENCE_ACTION", 1.5, "value", "whole numbers"),
    ("FS_EKF_THRESH", 0.7, "value", "not one of its values"),
])
def test_refusals_name_the_field(name: str, value: object, field: str, words: str) -> None:
    with pytest.raises(ParamWriteError) as e:
        table("arducopter").check(name, value)
    assert e.value.field == field and str(e.value).startswith(f"{field}: ") and words in str(e.value)


def test_in_flight_changes_are_bounded_unless_forced() -> None:
    t = table("arducopter")
    assert MAX_IN_FLIGHT_CHANGE == 0.5
    assert t.check("ATC_RAT_RLL_P", 0.2, old=0.135, in_flight=True) == 0.2  # +48 %
    with pytest.raises(ParamWriteError) as e:
        t.check("ATC_RAT_RLL_P", 0.3, old=0.135, in_flight=True)  # +122 %
    assert e.value.field == "force" and "122%" in str(e.value)
    assert t.check("ATC_RAT_RLL_P", 0.3, old=0.135, in_flight=True, force=True) == 0.3
    assert t.check("ATC_RAT_RLL_P", 0.3, old=0.135, in_flight=False) == 0.3  # on the ground
    with pytest.raises(ParamWriteError, match="unbounded"):
        t.check("ATC_RAT_RLL_D", 0.01, old=0.0, in_flight=True)
    with pytest.raises(ParamWriteError, match="out of range"):  # force never widens the range
        t.check("ATC_RAT_RLL_P", 0.9, old=0.135, in_flight=True, force=True)


def test_known_looks_in_every_table() -> None:
    assert {s.max for s in known("ATC_RAT_RLL_P")} == {0.5, 200.0}
    assert known("SIM_BATT_CAP_AH") and not known("NO_SUCH_PARAM")
