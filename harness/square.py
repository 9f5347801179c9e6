"""The model's 50 m square, judged one way wherever it is flown (no tests here)."""

from __future__ import annotations

import math
from typing import Any

from autopilot_model.flights import fly_square
from autopilot_model.modules.navigation import LANDED_ON_GROUND
from autopilot_model.vehicle import Vehicle


def fly_and_check_square(v: Vehicle) -> dict[str, Any]:
    """Fly the 50 m square at 5 m/s, 10 m up, then land; assert the tracking bounds of the 500 Hz flight
    (h max 0.2 m, v max 0.1 m), the landing and the return home (within 0.3 m); the summary."""
    rec = fly_square(v, side=50.0, speed=5.0, alt=10.0)
    s = rec.summary()
    assert s["samples"] > 1000
    assert s["h_max"] < 0.2, s
    assert s["v_max"] < 0.1, s
    assert v.nav.landed_state == LANDED_ON_GROUND and not v.nav.armed
    assert v.world.position[2] == 0.0
    # back where it started, within a hand's width
    assert math.hypot(*v.world.position[:2]) < 0.3
    return s
