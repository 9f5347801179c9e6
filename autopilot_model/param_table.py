"""Writes the model's parameter metadata to ``mission_specs/params_model.yaml`` (the table the ground
service and the companion guard parameter writes with, :mod:`mission_specs.param_table`).

``python -m autopilot_model.param_table [--check]``: builds a model instance (parameters not kept, on a
free loopback port), reads every parameter's range from its :class:`~autopilot_model.params.ParamStore`
and rewrites the file (``--check``: exit 1 when the file is stale).
"""

from __future__ import annotations

import argparse
import socket
import sys
import tempfile
from pathlib import Path
from typing import Any

import yaml

#: the file, from the repository root (a source checkout)
OUT = Path(__file__).resolve().parent.parent / "mission_specs" / "params_model.yaml"
HEADER = """# Every parameter of the Taskflight autopilot model with the range the model enforces, made by
# `python -m autopilot_model.param_table` from ParamStore.metadata() (do not edit by hand).
# The guard of parameter writes (mission_specs/param_table.py) uses it when the autopilot is the model.
"""


def metadata() -> dict[str, dict[str, Any]]:
    """The model's parameters (every piece of a vehicle declared) with their metadata."""
    from autopilot_model.sitl import Sitl  # the whole model: every module declares its parameters
    from taskflight_common.ports import free_ports

    port = free_ports(1, socket.SOCK_DGRAM)[0]
    with tempfile.TemporaryDirectory() as tmp:
        s = Sitl(urls=[f"udpin:127.0.0.1:{port}"], state_dir=Path(tmp), persist=False)
        try:
            return s.vehicle.params.metadata()
        finally:
            s.close()


def render() -> str:
    return HEADER + yaml.safe_dump({"autopilot": "model", "params": metadata()}, sort_keys=True, width=110)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--check", action="store_true", help="only compare; exit 1 when stale")
    args = ap.parse_args(argv)
    text = render()
    if args.check:
        current = OUT.read_text(encoding="utf-8") if OUT.exists() else ""
        if current != text:
            print(f"{OUT} is stale: run python -m autopilot_model.param_table", file=sys.stderr)
            return 1
        return 0
    OUT.write_text(text, encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
