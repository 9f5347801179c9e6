"""Airframe YAML validation: errors name the file, the line and the field."""

from __future__ import annotations

from pathlib import Path

import pytest

from autopilot_model.airframe import DEFAULT_AIRFRAME, load_airframe
from taskflight_common.yamlio import ConfigError


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "frame.yaml"
    p.write_text(text, encoding="utf-8")
    return p


def _edit(tmp_path: Path, old: str, new: str) -> Path:
    text = DEFAULT_AIRFRAME.read_text(encoding="utf-8")
    assert old in text
    return _write(tmp_path, text.replace(old, new, 1))


def test_bundled_airframe_loads() -> None:
    af = load_airframe()
    assert af.mass == 1.5
    assert af.envelope["box"] == (-2000.0, 2000.0, -2000.0, 2000.0)


@pytest.mark.parametrize(
    ("old", "new", "field", "reason"),
    [
        ("mass: 1.5 ", "mass: -1 ", "mass", "> 0"),
        ("mass: 1.5 ", "mass: heavy ", "mass", "expected a number"),
        ("  time_constant: 0.02 ", "  time_constant: 5 ", "motors.time_constant", "<= 1"),
        ("inertia: [0.015, 0.015, 0.027]", "inertia: [0.015, 0.015]", "inertia", "list of 3"),
        ("sensors: outdoor", "sensors: underwater", "sensors", "must be one of"),
        ("  max_speed_h: 10.0 ", "  max_sped_h: 10.0 ", "envelope.max_sped_h", "unknown field"),
        ("  thrust_max: 7.5 ", "  thrust_max: 1.0 ", "motors", "cannot lift"),
    ],
)
def test_malformed_airframe_names_file_line_field(tmp_path: Path, old: str, new: str, field: str,
                                                  reason: str) -> None:
    p = _edit(tmp_path, old, new)
    line = 1 + p.read_text(encoding="utf-8").splitlines().index(
        next(ln for ln in p.read_text(encoding="utf-8").splitlines() if ln.startswith(new)))
    with pytest.raises(ConfigError) as err:
        load_airframe(p)
    msg = str(err.value)
    assert str(p) in msg
    assert err.value.field == field
    assert reason in msg
    if field != "motors":
        assert err.value.line == line, msg


def test_yaml_syntax_error_has_line(tmp_path: Path) -> None:
    p = _write(tmp_path, "name: x\nmass: [1.5\ninertia: 3\n")
    with pytest.raises(ConfigError) as err:
        load_airframe(p)
    assert err.value.line is not None
    assert "YAML syntax error" in str(err.value)


def test_missing_file_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="cannot read file"):
        load_airframe(tmp_path / "nope.yaml")
