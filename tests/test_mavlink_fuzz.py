"""A small run of the fuzz bench: random and mutated datagrams never crash, never change state."""

from __future__ import annotations

import importlib.util
from pathlib import Path

BENCH = Path(__file__).resolve().parents[1] / "bench" / "bench_mavlink_fuzz.py"


def test_fuzz_small(tmp_path: Path) -> None:
    spec = importlib.util.spec_from_file_location("bench_mavlink_fuzz", BENCH)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    r = mod.run_fuzz(20_000, seed=3, state_dir=str(tmp_path))
    assert r["state_unchanged"], r
    assert r["answered"], r
    s = r["stats"]
    assert s.get("handler_error", 0) == 0
    for k in ("garbage", "bad_crc", "truncated", "wrong_target", "invalid_field"):
        assert s.get(k, 0) > 0, k
