"""Shared bits of the bench scripts: the machine they ran on, and plain-text tables."""

from __future__ import annotations

import argparse
import os
import platform
import sys
from collections.abc import Sequence


def machine() -> str:
    """One line naming the CPU, the core count and Python."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} cores, Python {sys.version.split()[0]}, {platform.system()}"


def table(headers: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    """A Markdown table (readable as text, pasteable into the README)."""
    cells = [[_fmt(c) for c in r] for r in rows]
    widths = [max(len(h), *(len(r[i]) for r in cells)) if cells else len(h) for i, h in enumerate(headers)]
    out = ["| " + " | ".join(h.ljust(w) for h, w in zip(headers, widths, strict=True)) + " |",
           "|" + "|".join("-" * (w + 2) for w in widths) + "|"]
    out += ["| " + " | ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)) + " |" for r in cells]
    return "\n".join(out)


def pct(values: Sequence[float], q: float) -> float:
    """The ``q`` quantile (0..1) of ``values``, nearest rank (NaN when empty)."""
    s = sorted(values)
    return s[min(len(s) - 1, int(q * (len(s) - 1) + 0.5))] if s else float("nan")


def add_autopilot_argument(p: argparse.ArgumentParser) -> None:
    """``--autopilot model,arducopter`` (ArduCopter SITL by default when ``TASKFLIGHT_ARDUCOPTER`` is set)."""
    from harness.arducopter import arducopter_missing

    default = "model" if arducopter_missing() else "model,arducopter"
    p.add_argument("--autopilot", default=default,
                   help=f"comma-separated: model, arducopter (default {default}; ArduCopter SITL needs "
                        "TASKFLIGHT_ARDUCOPTER)")


def chosen_autopilots(p: argparse.ArgumentParser, args: argparse.Namespace) -> list[str]:
    """The autopilots ``--autopilot`` names (an error if ArduCopter SITL is asked for but missing)."""
    from harness.arducopter import arducopter_missing

    kinds = [k.strip() for k in args.autopilot.split(",") if k.strip()]
    if "arducopter" in kinds and arducopter_missing():
        p.error(str(arducopter_missing()))
    return kinds


def _fmt(c: object) -> str:
    if isinstance(c, float):
        return f"{c:.3g}" if abs(c) < 1000 else f"{c:.0f}"
    return str(c)
