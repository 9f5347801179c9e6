"""DISTANCE_SENSOR and RANGEFINDER: the downward range finder as ArduCopter reports it.

ArduPilot's ``GCS_MAVLINK::send_distance_sensor``: time since boot (ms), RNGFND1_MIN / MAX and the reading
in centimetres (each capped at 65535), the MAV_DISTANCE_SENSOR type (LASER for the SITL driver), the
instance as id (0), the orientation (25, MAV_SENSOR_ROTATION_PITCH_270), covariance 0 (unknown), no field
of view, signal quality 0 (unknown). RANGEFINDER (ardupilotmega): the distance in metres and the
voltage (0: the simulated sensor has none). Both are in ArduCopter's EXTRA3 stream group and are not sent
while no range finder is configured (RNGFND1_TYPE 0), as ArduPilot sends none for a missing sensor.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

if TYPE_CHECKING:
    from autopilot_model.modules.rangefinder import RangeFinder
    from taskflight_common.clock import SimClock

    from .endpoint import MavlinkEndpoint
    from .streams import StreamScheduler

M = mavlink2


def _cm(m: float) -> int:
    return int(max(0, min(65535, round(m * 100.0))))


class RangeFinderLink:
    """Registers the range finder's builders on the stream scheduler."""

    def __init__(self, endpoint: MavlinkEndpoint, streams: StreamScheduler, sensor: RangeFinder,
                 clock: SimClock) -> None:
        self.ep = endpoint
        self.sensor = sensor
        self.clock = clock
        streams.add_builder("DISTANCE_SENSOR", self.distance_sensor)
        streams.add_builder("RANGEFINDER", self.rangefinder)

    def distance_sensor(self) -> Any:
        d = self.sensor.sample()
        if d is None:
            return None
        s = self.sensor
        return self.ep.mav.distance_sensor_encode(
            self.clock.time_boot_ms, _cm(s.min_m), _cm(s.max_m), _cm(d), M.MAV_DISTANCE_SENSOR_LASER, 0,
            int(s.params.get("RNGFND1_ORIENT")), 0, 0.0, 0.0, [0.0, 0.0, 0.0, 0.0], 0)

    def rangefinder(self) -> Any:
        d = self.sensor.sample()
        if d is None:
            return None
        return self.ep.mav.rangefinder_encode(d, 0.0)
