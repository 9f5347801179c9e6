"""What the flight modes, missions and failsafes use of a vehicle: a narrow, typed interface.

:class:`autopilot_model.vehicle.Vehicle` provides it; the modules name only this protocol, so they never
import the vehicle that assembles them (seed 002 Fig. 2: the modules are functions the vehicle's
scheduler calls, below it).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    from autopilot_model.airframe import Airframe
    from autopilot_model.modules.control import CascadedController
    from autopilot_model.modules.estimation import Estimator
    from autopilot_model.modules.guidance import SetpointGenerator
    from autopilot_model.modules.navigation import Navigator
    from autopilot_model.modules.sensors import PositionSensor
    from autopilot_model.params import ParamStore
    from autopilot_model.physics.battery import Battery
    from autopilot_model.physics.quadrotor import Quadrotor
    from autopilot_model.state import StateInterface
    from taskflight_common.clock import SimClock

#: A pilot's lean request (roll, pitch rad; yaw rate rad/s or None), see ``Vehicle.lean``.
Lean = tuple[float, float, float | None]


class VehicleApi(Protocol):
    """The parts of one simulated vehicle the modules read and drive."""

    airframe: Airframe
    clock: SimClock
    params: ParamStore
    state: StateInterface
    world: Quadrotor
    battery: Battery
    gps: PositionSensor
    estimator: Estimator
    guidance: SetpointGenerator
    control: CascadedController
    nav: Navigator
    home: tuple[float, float, float]
    battery_voltage: float
    lean: Lean | None

    def register(self, name: str, fn: Callable[[], object]) -> None:
        """Make ``fn`` the scheduler function ``name`` (seed 002 Sec. 3.2)."""

    def step_of(self, name: str) -> float:
        """Period (s) at which the scheduler calls function ``name``."""
        ...

    def guidance_reset_here(self) -> None:
        """Restart the setpoint generator from where the vehicle is."""

    def state_alt_estimate(self) -> float:
        """Estimated down position (m, NED)."""
        ...


class GroundLink(Protocol):
    """What the missions and failsafes use of the vehicle's MAVLink endpoint: announcements, one
    message to every ground station, and when the ground station's heartbeat was last heard."""

    mav: Any
    last_gcs_heartbeat_s: float | None

    def send(self, msg: Any) -> None:
        """Send ``msg`` on every link."""

    def statustext(self, severity: int, text: str) -> None:
        """Announce ``text`` (STATUSTEXT) on every link."""
