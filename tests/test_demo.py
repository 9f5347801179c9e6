"""The README's main job works: ``taskflight demo`` (model + companion over MAVLink) and ``--model-only``."""

from __future__ import annotations

import pytest

from taskflight.cli import main


def test_stack_demo_lands_and_reports_ok(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["demo", "--speedup", "10", "--sensors", "indoor"]) == 0
    out = capsys.readouterr().out
    assert "result: OK" in out
    assert "landed and disarmed: True" in out


def test_model_only_demo(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["demo", "--model-only", "--side", "20", "--sensors", "perfect"]) == 0
    out = capsys.readouterr().out
    assert "landed and disarmed: True" in out


def test_demo_with_a_bad_command_file_is_a_clear_error(tmp_path, caplog: pytest.LogCaptureFixture) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("commands:\n  - horizontal: {mode: FLY}\n", encoding="utf-8")
    assert main(["demo", "--commands", str(bad)]) == 2
    assert "bad.yaml:2" in caplog.text
