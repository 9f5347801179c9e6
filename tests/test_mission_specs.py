"""Every YAML file shipped in mission_specs/ loads and validates."""

from __future__ import annotations

from pathlib import Path

import pytest

from companion.flight.codec import load_commands

SPECS = Path(__file__).resolve().parents[1] / "mission_specs"


@pytest.mark.parametrize("path", sorted(SPECS.glob("flight_commands_*.yaml")), ids=lambda p: p.name)
def test_flight_command_files_load(path: Path) -> None:
    commands = load_commands(path)
    assert commands, f"{path} has no commands"


def test_there_is_at_least_one_spec() -> None:
    assert list(SPECS.glob("*.yaml"))
