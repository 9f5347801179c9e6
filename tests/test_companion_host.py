"""The companion host's configuration (:mod:`companion.host`): every companion's options through
``taskflight companion``'s own parser and ``config_from_args``; a bad one is refused naming the companion,
before any is built. And the mirror's fast copy (:func:`companion.link.mirror._replaced`) makes the state
``dataclasses.replace`` makes."""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import pytest

from companion.host import HostConfigError, argument_sets, configs_from_sets
from companion.link.mirror import MirrorState, _replaced


def host_args(*companions: str, config: Path | None = None, common: str = "") -> argparse.Namespace:
    return argparse.Namespace(config=str(config) if config else None, companion=list(companions),
                              common=common)


def test_each_companion_gets_its_own_options_and_the_common_ones() -> None:
    sets = argument_sets(host_args("--autopilot udpout:127.0.0.1:14550 --control-port 0",
                                   "--autopilot udpout:127.0.0.1:14560 --control-port -1",
                                   common="--name 'uav x' --rate 10"))
    configs = configs_from_sets(sets)
    assert [c.autopilot for c in configs] == ["udpout:127.0.0.1:14550", "udpout:127.0.0.1:14560"]
    assert [c.control_port for c in configs] == [0, None]
    assert {c.name for c in configs} == {"uav x"} and {c.rate_hz for c in configs} == {10.0}


def test_a_config_file_lists_the_companions(tmp_path: Path) -> None:
    f = tmp_path / "host.yaml"
    f.write_text("common: [--rate, 5, --control-port, 0]\n"
                 "companions:\n  - [--autopilot, 'udpout:127.0.0.1:14550']\n"
                 "  - --autopilot udpout:127.0.0.1:14560 --name two\n")
    configs = configs_from_sets(argument_sets(host_args(config=f)))
    assert [(c.autopilot, c.rate_hz, c.name) for c in configs] == [
        ("udpout:127.0.0.1:14550", 5.0, ""), ("udpout:127.0.0.1:14560", 5.0, "two")]


@pytest.mark.parametrize(("companions", "says"), [
    (["--autopilot udpout:127.0.0.1:14550", "--autopilot udpout:127.0.0.1:14560 --platform /no/such.yaml"],
     "companion 2 (--autopilot udpout:127.0.0.1:14560): "),
    (["--autopilot udpout:127.0.0.1:14550 --rate fast"],
     "companion 1 (--autopilot udpout:127.0.0.1:14550): "),
    (["--autopilot a:1", "--autopilot b:2"], "two companions on one control port: [8765, 8765]"),
    (["--control-port 0"], "companion 1 (--control-port 0): missing a required option"),
    (["--autopilot a:1 --control-port 9001", "--autopilot b:2 --control-port 9001"], "one control port"),
])
def test_a_bad_companion_is_named(companions: list[str], says: str) -> None:
    with pytest.raises(HostConfigError) as err:
        configs_from_sets(argument_sets(host_args(*companions)))
    assert says in str(err.value)


def test_no_companion_or_a_bad_file_is_refused(tmp_path: Path) -> None:
    with pytest.raises(HostConfigError, match="no companion"):
        argument_sets(host_args())
    f = tmp_path / "host.yaml"
    f.write_text("companions: [[--autopilot, x]]\nextra: 1\n")
    with pytest.raises(HostConfigError, match=r"unknown field\(s\) \['extra'\]"):
        argument_sets(host_args(config=f))
    f.write_text("companions: [{autopilot: x}]\n")
    with pytest.raises(HostConfigError, match=r"companions\[0\]: expected a list"):
        argument_sets(host_args(config=f))


def test_the_mirror_copy_is_the_state_replace_makes() -> None:
    s = replace(MirrorState(), heartbeats=3, mode=4)
    changes = {"position": (1.0, 2.0, -3.0), "velocity": (0.0, 0.5, 0.0), "time_boot_ms": 1200, "messages": 9}
    new = _replaced(s, changes)
    assert new == replace(s, **changes) and type(new) is MirrorState
    assert s.position is None and s.messages == 0  # the old state is untouched
    with pytest.raises(AttributeError):
        new.mode = 5  # type: ignore[misc]  # still frozen
