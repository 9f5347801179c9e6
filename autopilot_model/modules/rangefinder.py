"""The downward range finder (sensors, seed 002 Sec. 2), configured as ArduCopter's first range finder.

ArduCopter's parameters (``AP_RangeFinder_Params``, current names: distances in metres):

* ``RNGFND1_TYPE``: 0 none (the default, as ArduCopter), 100 SITL (the model's simulated sensor); the
  model has no other driver, so another type is refused saying so;
* ``RNGFND1_ORIENT``: 25 (MAV_SENSOR_ROTATION_PITCH_270, down), the only orientation the model simulates;
* ``RNGFND1_MIN`` / ``RNGFND1_MAX``: the distances (m) the sensor reads reliably (ArduPilot's defaults 0.2
  and 7 m); a reading outside them is reported, as ArduPilot does, and is not *in range*;
* ``RNGFND1_GNDCLR``: the distance (m) it reads on the ground (ArduPilot's default 0.1 m), the height of
  the sensor above the skids.

A reading is the distance along the body's down axis to the terrain under the vehicle
(:mod:`autopilot_model.terrain`): ``(height above ground + GNDCLR) / cos(tilt)``, as ArduPilot SITL's
``Aircraft::rangefinder_range``, plus white noise (2 cm; none with the ``perfect`` sensor profile); no
reading beyond 60 degrees of tilt. It is sampled when telemetry asks for it (DISTANCE_SENSOR,
RANGEFINDER: :mod:`autopilot_model.mavlink.rangefinder_link`), so it costs nothing when not streamed.
A change of the parameters takes effect at once (ArduCopter needs a reboot for ``RNGFND1_TYPE``).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from autopilot_model.physics.quadrotor import PX, PY, PZ, QX, QY, Quadrotor
from autopilot_model.terrain import Terrain

if TYPE_CHECKING:
    from autopilot_model.params import ParamStore

TYPE_NONE = 0
TYPE_SITL = 100
ORIENT_DOWN = 25  # MAV_SENSOR_ROTATION_PITCH_270
MAX_TILT_COS = math.cos(math.radians(60.0))


def define_rangefinder_params(params: ParamStore) -> None:
    """Declare RNGFND1_* with ArduCopter's names, units and defaults (see module docstring)."""
    params.define("RNGFND1_TYPE", TYPE_NONE, 0, TYPE_SITL, "int",
                  "0 none, 100 SITL: the model simulates no other range finder driver",
                  values=(TYPE_NONE, TYPE_SITL))
    params.define("RNGFND1_ORIENT", ORIENT_DOWN, ORIENT_DOWN, ORIENT_DOWN, "int",
                  "25 (down): the model simulates a downward range finder only")
    params.define("RNGFND1_MIN", 0.2, 0.0, 1000.0, "float", "minimum distance read reliably (m)")
    params.define("RNGFND1_MAX", 7.0, 0.0, 10000.0, "float", "maximum distance read reliably (m)")
    params.define("RNGFND1_GNDCLR", 0.1, 0.0, 1.27, "float", "distance read on the ground (m)")


class RangeFinder:
    """Samples the distance to the terrain along the body's down axis (see module docstring)."""

    NOISE_M = 0.02

    def __init__(self, world: Quadrotor, terrain: Terrain, params: ParamStore, noisy: bool,
                 seed: int | None) -> None:
        self.world = world
        self.terrain = terrain
        self.params = params
        self.noise_m = self.NOISE_M if noisy else 0.0
        self.rng = np.random.default_rng(seed)
        define_rangefinder_params(params)

    @property
    def enabled(self) -> bool:
        return self.params.get("RNGFND1_TYPE") != TYPE_NONE

    @property
    def min_m(self) -> float:
        return self.params.get("RNGFND1_MIN")

    @property
    def max_m(self) -> float:
        return self.params.get("RNGFND1_MAX")

    def height_above_ground(self) -> float:
        """The vehicle's true height above the terrain under it (m; the world's truth, for tests)."""
        x = self.world.x
        return float(-x[PZ] - self.terrain.height(float(x[PX]), float(x[PY])))

    def sample(self) -> float | None:
        """One reading (m), or None: no range finder configured, or tilted beyond 60 degrees."""
        if not self.enabled:
            return None
        qx, qy = float(self.world.x[QX]), float(self.world.x[QY])
        cos_tilt = 1.0 - 2.0 * (qx * qx + qy * qy)  # the body z axis against the vertical
        if cos_tilt < MAX_TILT_COS:
            return None
        d = (self.height_above_ground() + self.params.get("RNGFND1_GNDCLR")) / cos_tilt
        if self.noise_m:
            d += self.noise_m * float(self.rng.standard_normal())
        return max(0.0, d)
