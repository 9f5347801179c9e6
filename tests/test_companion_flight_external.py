"""External data streams (seed 000 Sec. IV-C): validity, staleness, malformed samples."""

from __future__ import annotations

import math

import pytest

from companion.flight import STREAMS, ExternalData, ExternalDataError


def test_sample_is_fresh_within_its_validity_only() -> None:
    ext = ExternalData()
    assert ext.push("ext_vel", [1.0, 2.0, 0.5, 10.0], validity_s=0.5, t_s=10.0)
    assert ext.latest("ext_vel", 10.0) == (1.0, 2.0, 0.5, 10.0)
    assert ext.latest("ext_vel", 10.5) == (1.0, 2.0, 0.5, 10.0)
    assert ext.latest("ext_vel", 10.51) is None
    assert ext.latest("ext_pos", 10.0) is None


def test_older_sample_is_ignored() -> None:
    ext = ExternalData()
    ext.push("ext_point", (1, 2), 1.0, 5.0)
    assert not ext.push("ext_point", (9, 9), 1.0, 4.0)
    assert ext.latest("ext_point", 5.0) == (1.0, 2.0)


@pytest.mark.parametrize(
    ("stream", "values", "validity", "t", "message"),
    [
        ("ext_velocity", (1, 2, 3, 4), 1.0, 0.0, "unknown stream"),
        ("ext_vel", (1, 2, 3), 1.0, 0.0, "expected 4 values"),
        ("ext_vel", (1, 2, math.nan, 0), 1.0, 0.0, "finite"),
        ("ext_pos", (1, 2, math.inf), 1.0, 0.0, "finite"),
        ("ext_pos", (1, 2, 3), -0.5, 0.0, "validity"),
        ("ext_pos", (1, 2, 3), 0.0, 0.0, "validity"),
        ("ext_pos", (1, 2, 3), math.nan, 0.0, "validity"),
        ("ext_pos", (1, 2, 3), 1.0, math.nan, "time"),
        ("ext_heading", "90", 1.0, 0.0, "expected 1 values"),
        ("ext_heading", None, 1.0, 0.0, "expected 1 numbers"),
        ("ext_point", (True, 2), 1.0, 0.0, "booleans"),
        ("ext_vel", (1, 0, 0, 0), 1e9, 0.0, "exceeds the maximum"),
        ("ext_vel", (1, 0, 0, 0), 5.01, 0.0, "exceeds the maximum of 5 s"),
    ],
)
def test_malformed_sample_raises_and_changes_nothing(stream, values, validity, t, message) -> None:
    ext = ExternalData()
    for name, n in STREAMS.items():
        ext.push(name, [0.5] * n, 5.0, 0.0)
    before = {name: ext.sample(name) for name in STREAMS}
    with pytest.raises(ExternalDataError) as info:
        ext.push(stream, values, validity, t)
    assert message in str(info.value)
    assert {name: ext.sample(name) for name in STREAMS} == before


def test_the_maximum_validity_is_configurable() -> None:
    ext = ExternalData(max_validity_s=30.0)
    assert ext.push("ext_vel", (1, 0, 0, 0), 30.0, 0.0)
    assert ext.latest("ext_vel", 29.9) is not None and ext.latest("ext_vel", 30.1) is None
    with pytest.raises(ExternalDataError, match="maximum of 30 s"):
        ext.push("ext_vel", (1, 0, 0, 0), 31.0, 1.0)
    for bad in (0.0, -1.0, math.inf, math.nan):
        with pytest.raises(ValueError, match="max_validity_s"):
            ExternalData(max_validity_s=bad)
