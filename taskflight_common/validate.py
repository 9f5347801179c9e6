"""Input checks shared by the layers: numbers and 3-vectors that must be finite.

Both raise :class:`ValueError` (never TypeError) naming what was being checked, before anything is
written, so a caller's state stays unchanged on bad input.
"""

from __future__ import annotations

import math
from typing import Any

Vec3 = tuple[float, float, float]


def finite3(v: Any, what: str) -> Vec3:
    """``v`` as a tuple of three finite floats."""
    try:
        x, y, z = v
        x = float(x)
        y = float(y)
        z = float(z)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{what}: expected 3 numbers, got {v!r}") from exc
    if x * 0.0 + y * 0.0 + z * 0.0 != 0.0:  # NaN or +-inf in any component
        raise ValueError(f"{what}: non-finite value {v!r}")
    return (x, y, z)


def finite(x: Any, what: str) -> float:
    """``x`` as a finite float."""
    try:
        f = float(x)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{what}: expected a number, got {x!r}") from exc
    if not math.isfinite(f):
        raise ValueError(f"{what}: non-finite value {x!r}")
    return f
