"""One envelope: the platform file bounds the queue as it bounds delegation; a flight config only narrows it.

Seed 000 Sec. IV-D's P_env (:mod:`companion.flight.limits`) and Sec. III-A's platform
(:mod:`companion.tst.platform`): with the mission layer served, the queue flies the platform's fence,
ceiling, floor, speed and acceleration limits (:func:`companion.builder.queue_envelope`);
``--flight-config`` may narrow them and a wider field is refused, naming it.
tests/test_envelope_stick.py flies the stick into the fence on the model.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from companion.builder import CompanionConfig, queue_envelope
from companion.flight import Limits
from companion.flight.limits import load_flight_config_fields
from companion.main import add_companion_arguments, config_from_args, run_companion
from companion.tst.platform import bundled_platform
from harness.fake_autopilot import unanswered_url


def _args(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    add_companion_arguments(parser)
    return parser.parse_args(["--autopilot", unanswered_url(), *argv])


def test_the_queue_flies_the_platforms_envelope_by_default() -> None:
    limits, env = queue_envelope(CompanionConfig(unanswered_url()))
    assert limits is not None and env is not None
    indoor = bundled_platform("indoor")
    assert limits.horizontal_speed == indoor.max_speed[0] == 2.0
    assert env.altitude_ceiling == 10.0 and env.altitude_floor == 1.0
    assert env.contains_ne((19.9, -19.9)) and not env.contains_ne((20.5, 0.0))
    outdoor = bundled_platform("outdoor")
    limits, env = queue_envelope(CompanionConfig(unanswered_url(), platform=outdoor))
    assert limits is not None and env is not None
    assert limits.horizontal_speed == 10.0 and limits.vertical_speed == 1.5  # WPNAV_SPEED_DN 150 cm/s
    assert env.altitude_ceiling == 60.0 and not env.contains_ne((201.0, 0.0))


def test_a_flight_config_narrows_the_platform(tmp_path: Path) -> None:
    f = tmp_path / "narrow.yaml"
    f.write_text("limits: {horizontal_speed: 1.5}\n"
                 "envelope:\n  box: {north_min: -5, north_max: 5, east_min: -5, east_max: 5}\n"
                 "  altitude_ceiling: 6\n")
    limits, env = queue_envelope(config_from_args(_args("--flight-config", str(f))))
    assert limits is not None and env is not None
    assert limits.horizontal_speed == 1.5 and limits.vertical_speed == 1.0  # the rest: the platform's
    assert env.altitude_ceiling == 6.0 and env.altitude_floor == 1.0 and not env.contains_ne((6.0, 0.0))


@pytest.mark.parametrize(("text", "field"), [
    ("limits: {horizontal_speed: 5}\n", "limits.horizontal_speed"),
    ("envelope: {altitude_ceiling: 30}\n", "envelope.altitude_ceiling"),
    ("envelope: {altitude_floor: 0.2}\n", "envelope.altitude_floor"),
    ("envelope:\n  box: {north_min: -50, north_max: 5, east_min: -5, east_max: 5}\n", "envelope.box"),
])
def test_a_flight_config_that_widens_the_platform_is_refused(tmp_path: Path, text: str, field: str,
                                                             caplog: pytest.LogCaptureFixture) -> None:
    f = tmp_path / "wide.yaml"
    f.write_text(text)
    config = config_from_args(_args("--flight-config", str(f)))
    with pytest.raises(ValueError, match=field.replace(".", r"\.")) as exc:
        queue_envelope(config)
    assert "never widen" in str(exc.value)
    assert run_companion(_args("--flight-config", str(f), "--control-port", "-1")) == 2
    assert field in caplog.text


def test_without_the_mission_layer_the_flight_config_stands_alone(tmp_path: Path) -> None:
    f = tmp_path / "fast.yaml"
    f.write_text("limits: {horizontal_speed: 8}\n")
    assert load_flight_config_fields(f).limits == {"horizontal_speed": 8.0}
    limits, env = queue_envelope(config_from_args(_args("--flight-config", str(f), "--no-behaviors")))
    assert limits is not None and limits.horizontal_speed == 8.0
    assert limits.vertical_speed == Limits().vertical_speed and env is not None
    assert not env.bounded_horizontally
