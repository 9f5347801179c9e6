"""Limits and operational envelope configuration (seed 000 Sec. IV-D: P_env), read through yamlio."""

from __future__ import annotations

import pytest

from companion.flight import Envelope, Limits, load_flight_config
from taskflight_common.yamlio import ConfigError


def test_limits_and_polygon_envelope_load(tmp_path) -> None:
    path = tmp_path / "flight.yaml"
    path.write_text(
        "limits:\n"
        "  horizontal_speed: 8\n"
        "  yaw_rate: 45\n"
        "envelope:\n"
        "  polygon: [[0, 0], [0, 50], [40, 50], [40, 20], [20, 20], [20, 0]]\n"
        "  altitude_floor: 1.5\n"
        "  altitude_ceiling: 40\n"
    )
    limits, env = load_flight_config(path)
    assert (
        limits.horizontal_speed == 8
        and limits.yaw_rate == 45
        and limits.vertical_speed == Limits().vertical_speed
    )
    assert env.contains((10.0, 10.0, -2.0)) and not env.contains((30.0, 10.0, -2.0))  # the notch of the L
    assert not env.contains((10.0, 10.0, -1.0)) and env.contains((10.0, 10.0, -1.0), floor_exempt=True)


@pytest.mark.parametrize(
    ("text", "line", "field", "reason"),
    [
        ("limits:\n  horizontal_speed: -1\n", 2, "limits.horizontal_speed", "must be > 0"),
        ("limits:\n  horizontal_sped: 3\n", 2, "limits.horizontal_sped", "unknown field"),
        (
            "envelope:\n  polygon:\n    - [0, 0]\n    - [0, 1]\n    - [1, .nan]\n",
            5,
            "envelope.polygon[2]",
            "numbers",
        ),
        (
            "envelope:\n  polygon: [[0, 0], [1, 1], [0, 1], [1, 0]]\n",
            2,
            "envelope.polygon",
            "not a simple polygon",
        ),
        ("envelope:\n  altitude_floor: 10\n  altitude_ceiling: 5\n", 2, "envelope.altitude_floor", "below"),
        (
            "envelope:\n  box: {north_min: 5, north_max: 1, east_min: 0, east_max: 1}\n",
            2,
            "envelope.box",
            "north_min",
        ),
    ],
)
def test_bad_configuration_names_file_line_and_field(tmp_path, text, line, field, reason) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_flight_config(path)
    err = info.value
    assert (err.file, err.line, err.field) == (str(path), line, field)
    assert reason in err.reason


def test_limits_refuse_nonsense_in_code() -> None:
    with pytest.raises(ValueError, match=r"limits\.vertical_jerk"):
        Limits(vertical_jerk=0)
    with pytest.raises(ValueError, match="altitude_floor"):
        Envelope(altitude_floor=5, altitude_ceiling=5)
