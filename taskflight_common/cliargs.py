"""Command-line arguments every ``taskflight`` parser reads the same way.

ArduPilot's own SITL takes ``--home -35.363261,149.165230,584,353`` (its default home, CMAC, is south of
the equator); argparse reads a value that starts with ``-`` and is not a bare number as an option and fails
with "expected one argument". :func:`join_signed_values` joins such an option with its value before
argparse sees them, so both forms work everywhere a home is taken.
"""

from __future__ import annotations

import re
import sys
from collections.abc import Sequence

#: options whose value may start with a minus sign (a home south of the equator or west of Greenwich)
SIGNED_VALUE_OPTIONS: tuple[str, ...] = ("--home",)
_SIGNED_VALUE = re.compile(r"^-[0-9.]")


def join_signed_values(argv: Sequence[str] | None = None,
                       options: Sequence[str] = SIGNED_VALUE_OPTIONS) -> list[str]:
    """``argv`` (default ``sys.argv[1:]``) with ``--home -35.36,149.16,584,353`` joined into
    ``--home=-35.36,149.16,584,353``. Only a value that starts with a minus and a digit or a dot is joined,
    so ``--home --help`` still asks for help; ``--home=...`` and a positive value are left as they are."""
    args = list(sys.argv[1:] if argv is None else argv)
    out: list[str] = []
    i = 0
    while i < len(args):
        arg = args[i]
        if arg == "--":  # everything after is positional: leave it alone
            out.extend(args[i:])
            break
        if arg in options and i + 1 < len(args) and _SIGNED_VALUE.match(args[i + 1]):
            out.append(f"{arg}={args[i + 1]}")
            i += 2
            continue
        out.append(arg)
        i += 1
    return out
