"""Generated tokens never look like an option (the CI failure of 2026-11-28: ``secrets.token_urlsafe``
drew a companion token starting with ``-``, and ``taskflight ground --companion-token -...`` refused it,
so ``taskflight up`` could not start once in 64 runs)."""

from __future__ import annotations

from pathlib import Path

from taskflight.cli import build_parser
from taskflight.up import VehicleInfo, ground_arguments
from taskflight_common.tokens import new_token, role_tokens


def test_new_tokens_never_start_with_a_dash() -> None:
    tokens = [new_token() for _ in range(2000)]  # P(no '-' start among 2000 token_urlsafe) ~ 1e-14
    assert not any(t.startswith("-") for t in tokens)
    assert len(set(tokens)) == len(tokens) and all(len(t) == 32 for t in tokens)
    assert all(not t.startswith("-") for role in role_tokens().values() for t in role)


def test_the_ground_command_line_of_up_takes_a_token_that_starts_with_a_dash(tmp_path: Path) -> None:
    v = VehicleInfo(index=0, sysid=1, instance=0, tcp=5760, udp=14550, control_url="http://127.0.0.1:9000")
    argv = ground_arguments("udp://239.255.70.1:15000", tmp_path / "g.db", "127.0.0.1", 8000,
                            tmp_path / "tokens.yaml", [v], "-dashing-token")
    args = build_parser().parse_args(argv)
    assert args.companion_token == "-dashing-token"
    assert args.companion == ["1=http://127.0.0.1:9000"]
