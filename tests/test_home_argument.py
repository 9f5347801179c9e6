"""Every command that takes a home accepts ArduPilot's own form, ``--home -35.363261,149.165230,584,353``
(a negative first number), as well as ``--home=...``: argparse alone reads the negative latitude as an
option ("expected one argument")."""

from __future__ import annotations

import socket
from pathlib import Path

import pytest

from harness.observer import Gcs
from harness.timing import SPEEDUP
from taskflight.cli import build_parser
from taskflight.sitlproc import ModelProcess
from taskflight_common.cliargs import join_signed_values
from taskflight_common.ports import free_ports

CMAC = "-35.363261,149.165230,584,353"


def test_a_negative_value_is_joined_to_its_option_and_nothing_else_is() -> None:
    assert join_signed_values(["--home", CMAC, "-n", "3"]) == [f"--home={CMAC}", "-n", "3"]
    assert join_signed_values(["--home", "-.5,2,3"]) == ["--home=-.5,2,3"]
    kept = [["--home", "35.1,2,3"], [f"--home={CMAC}"], ["--home", "--help"], ["--", "--home", CMAC],
            ["--speed", "-3"]]
    for argv in kept:
        assert join_signed_values(argv) == argv


@pytest.mark.parametrize("form", [["--home", CMAC], [f"--home={CMAC}"]])
@pytest.mark.parametrize("command", [["autopilot"], ["fleet", "-n", "3", "-I", "5", "--speedup", "5",
                                                     "--spacing", "10"]])
def test_autopilot_and_fleet_parse_both_forms(command: list[str], form: list[str]) -> None:
    args = build_parser().parse_args(join_signed_values([*command, *form]))
    assert args.home == (-35.363261, 149.165230, 584.0, 353.0)


def test_the_readme_fleet_example_parses() -> None:
    import argparse

    from autopilot_model.fleet import add_fleet_arguments

    parser = argparse.ArgumentParser()
    add_fleet_arguments(parser)
    argv = ["-n", "3", "-I", "5", "--speedup", "5", "--spacing", "10", "--home", "-35.36,149.16,584,0"]
    args = parser.parse_args(join_signed_values(argv))
    assert (args.vehicles, args.base_instance, args.spacing, args.home) == (3, 5, 10.0,
                                                                            (-35.36, 149.16, 584.0, 0.0))


@pytest.mark.integration
def test_taskflight_autopilot_started_with_a_southern_home_reports_it(tmp_path: Path) -> None:
    """``taskflight autopilot --home -33.86,...`` (the real entry point, in its own process; not the
    default home, CMAC) starts, and pymavlink hears the vehicle at that home."""
    port = free_ports(1, socket.SOCK_DGRAM)[0]
    proc = ModelProcess(["autopilot", "--home", "-33.856785,151.215297,20,90",
                         "--mavlink", f"udpin:127.0.0.1:{port}", "--state-dir", str(tmp_path),
                         "--no-persist", "--speedup", str(SPEEDUP)],
                        name="taskflight autopilot", module="taskflight.cli")
    with proc.start(60.0):  # stopped when the block ends
        gcs = Gcs(port, SPEEDUP)
        try:
            gcs.wait(lambda: "GLOBAL_POSITION_INT" in gcs.last, 60, "GLOBAL_POSITION_INT")
            pos = gcs.last["GLOBAL_POSITION_INT"]
            assert pos.lat / 1e7 == pytest.approx(-33.856785, abs=1e-4)
            assert pos.lon / 1e7 == pytest.approx(151.215297, abs=1e-4)
        finally:
            gcs.close()
