"""The companion's composition root (companion.builder) and the tokens file read once
(taskflight_common.tokens), without an autopilot."""

from __future__ import annotations

import argparse
from pathlib import Path

import httpx
import pytest

from companion.builder import CompanionConfig, build_companion
from companion.main import add_companion_arguments, config_from_args, run_companion
from harness.fake_autopilot import unanswered_url
from taskflight_common.tokens import load_tokens
from taskflight_common.yamlio import ConfigError


def _args(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    add_companion_arguments(parser)
    return parser.parse_args(["--autopilot", unanswered_url(), *argv])


def test_the_options_become_one_config() -> None:
    c = config_from_args(_args("--rate", "10", "--control-port", "-1", "--no-behaviors", "--run"))
    assert c.rate_hz == 10.0 and c.control_port is None and not c.behaviors and c.run
    assert c.behavior_catalog is None and c.max_validity_s == 5.0
    c = config_from_args(_args())
    assert c.behaviors and c.behavior_catalog is not None and c.control_port == 8765


def test_a_mission_or_a_team_needs_the_executive_layer() -> None:
    with pytest.raises(ValueError, match="--team needs the executive layer"):
        CompanionConfig("udpout:127.0.0.1:9", behaviors=False, team="udp://239.255.70.1:14650")


def test_bad_options_exit_2(tmp_path: Path) -> None:
    bad = tmp_path / "limits.yaml"
    bad.write_text("limits: [\n")
    assert run_companion(_args("--flight-config", str(bad))) == 2
    assert run_companion(_args("--rate", "500")) == 2


def test_built_parts_start_and_close_in_order(tmp_path: Path) -> None:
    companion = build_companion(CompanionConfig(unanswered_url(), control_port=0,
                                                behavior_log=tmp_path / "b.jsonl"))
    assert companion.layer is not None and companion.missions is not None and companion.server is None
    companion.start()
    try:
        assert companion.server is not None
        with httpx.Client(base_url=companion.server.url, timeout=10.0) as http:
            assert http.get("/status").status_code == 200
            assert http.get("/behaviors").status_code == 200  # the executive layer is served
            assert http.get("/mission").status_code == 200  # and the mission layer
    finally:
        companion.close()
    with pytest.raises(httpx.HTTPError):
        httpx.get(companion.server.url + "/status", timeout=2.0)
    bare = build_companion(CompanionConfig(unanswered_url(), behaviors=False,
                                           control_port=None))
    assert bare.layer is None and bare.missions is None
    bare.start()
    bare.close()
    assert bare.server is None


def test_tokens_file_errors_name_file_line_and_field(tmp_path: Path) -> None:
    f = tmp_path / "tokens.yaml"
    f.write_text("operator: [a]\nobserver: [' b ']\n")
    assert load_tokens(f) == {"operator": ["a"], "observer": ["b"]}
    f.write_text("operator: [a]\nobserver: [a]\n")
    with pytest.raises(ConfigError, match=r"tokens\.yaml:2: observer: a token is listed twice"):
        load_tokens(f)
    f.write_text("operator: [a]\nboss: [b]\n")
    with pytest.raises(ConfigError, match=r"tokens\.yaml:2: boss: unknown role"):
        load_tokens(f)
    f.write_text("observer: [b]\n")
    with pytest.raises(ConfigError, match="operator: at least one operator token"):
        load_tokens(f)
    with pytest.raises(ConfigError, match="tokens file: cannot read"):
        load_tokens(tmp_path / "missing.yaml")
