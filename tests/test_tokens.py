"""Generated tokens never look like an option (the CI failure of 2026-11-28: ``secrets.token_urlsafe``
drew a companion token starting with ``-``, and ``taskflight ground --companion-token -...`` refused it,
so ``taskflight up`` could not start once in 64 runs)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from groundstation.main import companion_token
from taskflight.cli import build_parser
from taskflight.up import VehicleInfo, ground_arguments
from taskflight_common.tokens import TOKEN_ENV, new_token, role_tokens


def test_new_tokens_never_start_with_a_dash() -> None:
    tokens = [new_token() for _ in range(2000)]  # P(no '-' start among 2000 token_urlsafe) ~ 1e-14
    assert not any(t.startswith("-") for t in tokens)
    assert len(set(tokens)) == len(tokens) and all(len(t) == 32 for t in tokens)
    assert all(not t.startswith("-") for role in role_tokens().values() for t in role)


def test_the_ground_command_line_of_up_carries_no_token(tmp_path: Path, monkeypatch: Any) -> None:
    """The companion token goes to the ground service in its environment (``ps`` shows every argument to
    every user of the machine); a token starting with a dash is read as it is."""
    v = VehicleInfo(index=0, sysid=1, instance=0, tcp=5760, udp=14550, control_url="http://127.0.0.1:9000")
    argv = ground_arguments("udp://239.255.70.1:15000", tmp_path / "g.db", "127.0.0.1", 8000,
                            tmp_path / "tokens.yaml", [v])
    assert not any("token=" in a or a == "--companion-token" for a in argv)
    args = build_parser().parse_args(argv)
    assert args.companion_token is None and not args.resume_tasks
    assert args.companion == ["1=http://127.0.0.1:9000"]
    monkeypatch.setenv(TOKEN_ENV, "-dashing-token")
    assert companion_token(args) == "-dashing-token"
    (tmp_path / "tok").write_text("-from-a-file\n")
    with_file = build_parser().parse_args([*argv, "--companion-token-file", str(tmp_path / "tok")])
    assert companion_token(with_file) == "-from-a-file"
    assert "--resume-tasks" in ground_arguments("udp://239.255.70.1:15000", tmp_path / "g.db", "127.0.0.1",
                                                8000, tmp_path / "tokens.yaml", [v], resume_tasks=True)
