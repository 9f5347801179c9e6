"""What a downward sensor sees (seed 000 Sec. VI-E, Fig. 14a ``sensor_type``): field of view, footprint.

The scan planner (:mod:`companion.tst.planning.coverage`) spaces its lines by the footprint and the camera
(:mod:`companion.sensing.camera`) decides what it sees with the same field of view, so both read it here,
below the TST layer.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["Fov", "Sensor", "footprint", "footprint_size", "fov_pair", "line_spacing"]

#: A field of view: one angle (square) or ``(h_fov, v_fov)``, degrees.
Fov = float | tuple[float, float]


def fov_pair(fov_deg: Fov) -> tuple[float, float]:
    """(h_fov, v_fov) in degrees from one angle (square field of view) or a pair; ValueError if bad."""
    pair = (fov_deg, fov_deg) if isinstance(fov_deg, int | float) else tuple(fov_deg)
    if len(pair) != 2:
        raise ValueError(f"fov_deg: expected an angle or (h_fov, v_fov), got {fov_deg!r}")
    for f in pair:
        if not (isinstance(f, int | float) and 0.0 < f < 180.0):
            raise ValueError(f"fov_deg: each angle must be in (0, 180) degrees, got {f!r}")
    return float(pair[0]), float(pair[1])


def footprint_size(altitude_m: float, fov_deg: Fov) -> tuple[float, float]:
    """(across-track width, along-track length) in metres seen by a nadir camera at ``altitude_m``.

    ``fov_deg`` is one angle (square field of view) or ``(h_fov, v_fov)``: h across the direction of
    flight, v along it (a camera mounted with its image rows across the track).
    """
    if not (math.isfinite(altitude_m) and altitude_m > 0.0):
        raise ValueError(f"altitude_m: must be > 0, got {altitude_m!r}")
    h, v = fov_pair(fov_deg)
    return (2.0 * altitude_m * math.tan(math.radians(h) / 2.0),
            2.0 * altitude_m * math.tan(math.radians(v) / 2.0))


def footprint(altitude_m: float, fov_deg: Fov) -> float:
    """Across-track width (m) of a downward camera's footprint: ``2 h tan(h_fov / 2)``."""
    return footprint_size(altitude_m, fov_deg)[0]


def line_spacing(altitude_m: float, fov_deg: Fov, overlap: float = 0.2) -> float:
    """Distance between scan lines so that neighbouring footprints overlap by ``overlap`` (0 <= o < 1)."""
    if not (0.0 <= overlap < 1.0):
        raise ValueError(f"overlap: must be in [0, 1), got {overlap!r}")
    return footprint(altitude_m, fov_deg) * (1.0 - overlap)



@dataclass(frozen=True)
class Sensor:
    """The scanning sensor (Fig. 14a ``sensor_type``: "camera", "laser", "artva") and its field of view."""

    type: str = "camera"
    fov_deg: Fov = 60.0
    overlap: float = 0.2
