"""Flight commands (seed 000 Fig. 7, Fig. 8): validation and serialisation to dict / JSON / YAML."""

from __future__ import annotations

import math

import pytest

from companion.flight import (
    CommandError,
    EndCondition,
    FlightCommand,
    Frame,
    HeadingChannel,
    HeadingMode,
    HorizontalChannel,
    HorizontalMode,
    SpeedModifier,
    VerticalChannel,
    VerticalMode,
    command_from_dict,
    command_from_json,
    command_to_dict,
    command_to_json,
    commands_from_json,
    commands_from_yaml,
    commands_to_json,
    commands_to_yaml,
    load_commands,
)
from companion.flight.pause_routines import catalog_from_yaml
from taskflight_common.yamlio import ConfigError


def _refused(field: str, **parts) -> CommandError:
    with pytest.raises(CommandError) as info:
        FlightCommand(**parts)
    assert info.value.field == field, str(info.value)
    return info.value


# --- validation ---------------------------------------------------------------------------------------
def test_take_off_command_of_fig_11_is_valid() -> None:
    c = FlightCommand(
        vertical=VerticalChannel(VerticalMode.POS, altitude=5, take_off=True), end=EndCondition(e_v=True)
    )
    assert c.horizontal.mode is HorizontalMode.DNU and c.heading.mode is HeadingMode.DNU
    assert c.vertical.take_off and not c.is_pause


def test_wait_only_command_is_a_pause() -> None:
    assert FlightCommand(end=EndCondition(e_wait=3.0)).is_pause
    assert not FlightCommand(end=EndCondition(e_wait=3.0, e_user=True)).is_pause


def test_modes_accept_their_names_as_strings() -> None:
    c = FlightCommand(
        HorizontalChannel("pos", north=1, east=2, frame="body_relative"), end=EndCondition(e_h=True)
    )
    assert c.horizontal.mode is HorizontalMode.POS and c.horizontal.frame is Frame.BODY_RELATIVE


@pytest.mark.parametrize(
    ("field", "parts", "why"),
    [
        ("end.e_h", dict(end=EndCondition(e_h=True)), "never raises"),
        (
            "end.e_v",
            dict(vertical=VerticalChannel(VerticalMode.EXT_VEL), end=EndCondition(e_v=True, e_user=True)),
            "never raises",
        ),
        (
            "end.e_hd",
            dict(heading=HeadingChannel(HeadingMode.FLIGHT_DIR), end=EndCondition(e_hd=True)),
            "never raises",
        ),
        (
            "end.e_any",
            dict(horizontal=HorizontalChannel(HorizontalMode.EXT_VEL), end=EndCondition(e_any=True)),
            "none of the channels",
        ),
        (
            "vertical.mode",
            dict(vertical=VerticalChannel(VerticalMode.WITH_HOR, altitude=5), end=EndCondition(e_v=True)),
            "WITH_HOR",
        ),
        (
            "horizontal.speed_modified_by",
            dict(
                horizontal=HorizontalChannel(
                    HorizontalMode.POS, north=1, east=1, speed_modified_by=["vertical"]
                ),
                end=EndCondition(e_h=True),
            ),
            "gives no speed modifier",
        ),
    ],
)
def test_commands_that_can_never_end_or_contradict_are_refused(field: str, parts: dict, why: str) -> None:
    err = _refused(field, **parts)
    assert why in err.reason


def test_no_end_condition_at_all_is_refused() -> None:
    with pytest.raises(CommandError) as info:
        EndCondition()
    assert info.value.field == "end" and "never end" in info.value.reason


@pytest.mark.parametrize(
    ("build", "field"),
    [
        (lambda: HorizontalChannel(HorizontalMode.POS, north=1, east=1, speed=-2), "horizontal.speed"),
        (lambda: HorizontalChannel(HorizontalMode.POS, north=math.nan, east=1), "horizontal.north"),
        (
            lambda: HorizontalChannel(HorizontalMode.POS, north=1, east=1, speed=2, end_speed=3),
            "horizontal.end_speed",
        ),
        (lambda: HorizontalChannel(HorizontalMode.POS, north=1), "horizontal.east"),
        (lambda: HorizontalChannel(HorizontalMode.EXT_VEL, speed=2), "horizontal.speed"),
        (lambda: HorizontalChannel(HorizontalMode.KEEP_DISTANCE, distance=0), "horizontal.distance"),
        (lambda: HorizontalChannel("FLY"), "horizontal.mode"),
        (lambda: VerticalChannel(VerticalMode.POS, altitude=math.inf), "vertical.altitude"),
        (lambda: VerticalChannel(VerticalMode.EXT_VEL, take_off=True), "vertical.take_off"),
        (lambda: VerticalChannel(VerticalMode.DNU, allow_landing=True), "vertical.allow_landing"),
        (
            lambda: VerticalChannel(VerticalMode.POS, altitude=-3, frame="relative", take_off=True),
            "vertical.altitude",
        ),
        (
            lambda: VerticalChannel(VerticalMode.POS, altitude=3, take_off=True, allow_landing=True),
            "vertical.take_off",
        ),
        (lambda: VerticalChannel(VerticalMode.POS, altitude=3, frame="body_relative"), "vertical.frame"),
        (lambda: HeadingChannel(HeadingMode.POS, heading=90, rate=0), "heading.rate"),
        (lambda: HeadingChannel(HeadingMode.POINT, north=1), "heading.east"),
        (lambda: HeadingChannel(HeadingMode.POS, heading=90, use_sign="yes"), "heading.use_sign"),
        (lambda: EndCondition(e_wait=-1.0), "end.e_wait"),
        (lambda: EndCondition(e_wait=math.nan), "end.e_wait"),
        (lambda: EndCondition(e_user=1), "end.e_user"),
    ],
)
def test_bad_parameters_are_refused_naming_the_field(build, field: str) -> None:
    with pytest.raises(CommandError) as info:
        build()
    assert info.value.field == field
    assert str(info.value).startswith(field + ":")


def test_speed_modifiers_follow_fig_7() -> None:
    ok = FlightCommand(
        HorizontalChannel(HorizontalMode.POS, north=10, east=0, speed_modified_by=("vertical", "heading")),
        VerticalChannel(VerticalMode.POS, altitude=5, speed_modified_by=["heading"]),
        HeadingChannel(HeadingMode.POS, heading=90),
        EndCondition(e_h=True, e_v=True, e_hd=True),
    )
    assert ok.horizontal.speed_modified_by == (SpeedModifier.HEADING, SpeedModifier.VERTICAL)
    # a heading that yaws forever gives no "arrive together" modifier
    _refused(
        "horizontal.speed_modified_by",
        horizontal=HorizontalChannel(HorizontalMode.POS, north=10, east=0, speed_modified_by=["heading"]),
        heading=HeadingChannel(HeadingMode.POS, heading=90, stop_at_heading=False),
        end=EndCondition(e_h=True),
    )
    # FlightDir modifies only the horizontal speed
    _refused(
        "vertical.speed_modified_by",
        vertical=VerticalChannel(VerticalMode.POS, altitude=5, speed_modified_by=["heading"]),
        heading=HeadingChannel(HeadingMode.FLIGHT_DIR),
        end=EndCondition(e_v=True),
    )


def test_e_any_accepts_a_channel_that_cannot_end_if_another_can() -> None:
    c = FlightCommand(
        HorizontalChannel(HorizontalMode.POS, north=1, east=1),
        VerticalChannel(VerticalMode.EXT_VEL),
        end=EndCondition(e_h=True, e_v=True, e_any=True),
    )
    assert c.end.e_any


def test_rc_velocity_is_accepted() -> None:
    c = FlightCommand(
        HorizontalChannel(HorizontalMode.RC_VEL),
        VerticalChannel(VerticalMode.RC_VEL),
        HeadingChannel(HeadingMode.RC_VEL),
        EndCondition(e_user=True),
    )
    assert c.velocity_only


# --- serialisation ------------------------------------------------------------------------------------
def _mission() -> list[FlightCommand]:
    return [
        FlightCommand(
            vertical=VerticalChannel(VerticalMode.POS, altitude=5, take_off=True), end=EndCondition(e_v=True)
        ),
        FlightCommand(
            HorizontalChannel(HorizontalMode.POS, north=10, east=-5, speed=3, end_speed=1),
            VerticalChannel(VerticalMode.WITH_HOR, altitude=8),
            HeadingChannel(HeadingMode.FLIGHT_DIR, offset=180),
            EndCondition(e_h=True, e_v=True),
        ),
        FlightCommand(
            HorizontalChannel(
                HorizontalMode.POS, north=2, east=0, frame="body_relative", speed_modified_by=["vertical"]
            ),
            VerticalChannel(VerticalMode.POS, altitude=-1, frame="relative", end_speed=0.5),
            HeadingChannel(
                HeadingMode.POS, heading=-90, frame="relative", rate=-30, use_sign=True, stop_at_heading=True
            ),
            EndCondition(e_h=True, e_v=True, e_hd=True, e_any=True),
        ),
        FlightCommand(
            HorizontalChannel(HorizontalMode.EXT_POS, offset_north=2, speed=4),
            VerticalChannel(VerticalMode.EXT_POS, offset=3),
            HeadingChannel(HeadingMode.EXT_POINT, offset=10),
            EndCondition(e_h=True, e_user=True, e_wait=2.5),
        ),
        FlightCommand(
            HorizontalChannel(HorizontalMode.KEEP_DISTANCE, distance=5),
            VerticalChannel(VerticalMode.DNU),
            HeadingChannel(HeadingMode.POINT, north=3, east=4),
            EndCondition(e_hd=True),
        ),
        FlightCommand(end=EndCondition(e_wait=4)),
        FlightCommand(
            vertical=VerticalChannel(VerticalMode.POS, altitude=0, allow_landing=True, speed=1),
            end=EndCondition(e_v=True),
        ),
    ]


def test_dict_json_yaml_round_trips_are_exact() -> None:
    mission = _mission()
    for c in mission:
        assert command_from_dict(command_to_dict(c)) == c
        assert command_from_json(command_to_json(c)) == c
    assert commands_from_json(commands_to_json(mission)) == mission
    text = commands_to_yaml(mission)
    assert commands_from_yaml(text) == mission
    assert "take_off: true" in text and "mode: WITH_HOR" in text


def test_unused_parameters_are_not_written() -> None:
    d = command_to_dict(FlightCommand(end=EndCondition(e_wait=1)))
    assert d == {
        "horizontal": {"mode": "DNU"},
        "vertical": {"mode": "DNU"},
        "heading": {"mode": "DNU"},
        "end": {"e_wait": 1},
    }


def test_yaml_file_errors_name_file_line_and_field(tmp_path) -> None:
    path = tmp_path / "mission.yaml"
    path.write_text(
        "commands:\n"
        "  - vertical: {mode: POS, altitude: 5, take_off: true}\n"
        "    end: {e_v: true}\n"
        "  - horizontal:\n"
        "      mode: POS\n"
        "      north: 10\n"
        "      east: 0\n"
        "      speed: -3\n"
        "    end: {e_h: true}\n"
    )
    with pytest.raises(ConfigError) as info:
        load_commands(path)
    err = info.value
    assert err.file == str(path) and err.line == 8 and err.field == "commands[1].horizontal.speed"
    assert f"{path}:8: commands[1].horizontal.speed: must be > 0" in str(err)


def test_yaml_semantic_error_names_the_line_of_the_field(tmp_path) -> None:
    path = tmp_path / "m.yaml"
    path.write_text("- horizontal: {mode: DNU}\n  end:\n    e_h: true\n")
    with pytest.raises(ConfigError) as info:
        load_commands(path)
    assert info.value.line == 3 and info.value.field == "[0].end.e_h" and "never raises" in info.value.reason


@pytest.mark.parametrize(
    ("text", "field", "reason"),
    [
        ('{"horizontal": {"mode": "POS", "north": 1}, "end": {"e_h": true}}', "horizontal.east", "required"),
        (
            '{"horizontal": {"mode": "POS", "north": NaN, "east": 0}, "end": {"e_h": true}}',
            "horizontal.north",
            "finite",
        ),
        (
            '{"horizontal": {"mode": "DNU", "wings": 2}, "end": {"e_wait": 1}}',
            "horizontal.wings",
            "unknown field",
        ),
        (
            '{"vertical": {"mode": "POS", "altitude": "high"}, "end": {"e_v": true}}',
            "vertical.altitude",
            "number",
        ),
        ('{"heading": {"mode": "DNU"}}', None, "missing required field 'end'"),
    ],
)
def test_json_errors_name_the_field(text: str, field: str | None, reason: str) -> None:
    with pytest.raises(ConfigError) as info:
        command_from_json(text)
    assert info.value.field == field
    assert reason in str(info.value)


def test_json_syntax_error_has_a_line() -> None:
    with pytest.raises(ConfigError) as info:
        command_from_json('{\n "end": {\n "e_wait": 1,,\n}}')
    assert info.value.line == 3 and "JSON syntax error" in str(info.value)


def test_routine_catalog_from_yaml() -> None:
    cat = catalog_from_yaml(
        "pause_routines:\n"
        "  - id: spin\n"
        "    commands:\n"
        "      - {heading: {mode: POS, heading: 180, frame: relative}, end: {e_hd: true}}\n"
    )
    assert set(cat.ids()) == {"hover", "joystick", "spin"}
    with pytest.raises(ConfigError) as info:
        catalog_from_yaml("pause_routines:\n  - id: bad\n    commands:\n      - {end: {e_h: true}}\n",
                          "cat.yaml")
    assert info.value.line == 4 and info.value.field == "pause_routines[0].commands[0].end.e_h"
