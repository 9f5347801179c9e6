"""V_GROUND: hold a height above the ground the downward range finder measures (Fig. 12a / 14a's
``follow_ground_flag`` and ``follow_ground_altitude``; the mode is ours: seed 000 names no channel mode
for it).

The outer loop is on the measured range: every tick the vertical goal is the ground under the vehicle
(:attr:`~companion.flight.setpoint.VehicleState.ground_alt`: the altitude when the reading came minus
the distance read times the cosine of the tilt, so the altitude estimate's own error cancels) plus the
wanted height; the reference generator flies it as a moving vertical position target (ruckig within
the vertical speed, acceleration and jerk limits, clamped to the envelope's floor and ceiling) whose
velocity is the ground's rate of climb under the vehicle: an alpha-beta filter (:data:`ALPHA`,
:data:`BETA`) of the readings' ground altitude and its rate, carried forward from the reading's time to
now plus :data:`LEAD_S` (the autopilot's own lag), so a slope is followed, not chased in steps, and the
altitude estimate's noise in each reading is smoothed. A goal that moved less than
:data:`GOAL_DEADBAND_M` is kept (the sensor's noise does not replan every tick).

Loss of the range finder: a reading older than :data:`STALE_S` (or none, or out of the sensor's range)
holds the altitude (the vertical channel comes to rest); no fresh reading for :data:`TIMEOUT_S` of the
command's running time fails the command with the reason (the queue's FAILED event; a behavior flying it
ends ``wrong_progress`` with that reason).
"""

from __future__ import annotations

from .setpoint import VehicleState

#: a reading older than this (autopilot s) is not used: the altitude holds
STALE_S = 1.0
#: no fresh reading for this long (s of the command's running time): the command fails
TIMEOUT_S = 3.0
#: a new goal closer than this (m) to the current one is not taken
GOAL_DEADBAND_M = 0.05
#: the alpha-beta filter of the ground under the vehicle (per reading: position and rate gains)
ALPHA = 0.35
BETA = 0.08
#: the goal leads the ground by this (s): the autopilot's own lag in tracking the setpoint
LEAD_S = 0.5


class GroundFollow:
    """The moving vertical goal of one V_GROUND command (see module docstring)."""

    def __init__(self, height_m: float) -> None:
        self.height_m = float(height_m)
        self.goal_down: float | None = None
        self.without_s = 0.0
        self.failure: str | None = None
        self.last_age_s: float | None = None
        self._reading: tuple[float, float] | None = None  # (time, ground altitude) of the last reading
        self.ground = 0.0
        self.rate = 0.0

    def resume(self) -> None:
        """A (re)start: the goal is measured afresh; the time without a reading counts from now."""
        self.goal_down = None
        self.without_s = 0.0
        self._reading = None
        self.rate = 0.0

    def _track(self, reading_t: float, ground: float) -> None:
        """An alpha-beta filter of the ground's altitude and rate of climb under the vehicle, one update per
        new reading (the altitude estimate's noise at each reading enters the ground it gives)."""
        last = self._reading
        if last is None:
            self._reading, self.ground, self.rate = (reading_t, ground), ground, 0.0
            return
        dt = reading_t - last[0]
        if dt <= 1e-3:
            return
        predicted = self.ground + self.rate * dt
        residual = ground - predicted
        self.ground = predicted + ALPHA * residual
        self.rate += BETA * residual / dt
        self._reading = (reading_t, ground)

    def step(self, vehicle: VehicleState | None, dt: float, now_s: float = 0.0) -> tuple[float, float] | None:
        """This tick's goal (m down) and the goal's velocity (m/s down), or None: hold (no fresh reading).
        Sets :attr:`failure` after :data:`TIMEOUT_S` without one."""
        fresh = (vehicle is not None and vehicle.ground_alt is not None and vehicle.ground_age_s is not None
                 and vehicle.ground_age_s <= STALE_S)
        if not fresh:
            self.without_s += dt
            self.last_age_s = vehicle.ground_age_s if vehicle is not None else None
            if self.without_s >= TIMEOUT_S and self.failure is None:
                age = f"the last in-range one is {self.last_age_s:.1f} s old" if self.last_age_s is not None \
                    else "none in range received"
                self.failure = (f"follow-ground: no fresh downward range-finder reading for "
                                f"{self.without_s:.1f} s ({age}); altitude held")
            self.goal_down = None
            self._reading = None
            self.rate = 0.0
            return None
        assert vehicle is not None and vehicle.ground_alt is not None and vehicle.ground_age_s is not None
        self.without_s = 0.0
        self._track(now_s - vehicle.ground_age_s, vehicle.ground_alt)
        assert self._reading is not None
        # the ground now: the filtered ground carried forward from its reading at the ground's rate
        goal = -(self.ground + self.rate * (now_s - self._reading[0] + LEAD_S) + self.height_m)
        if self.goal_down is None or abs(goal - self.goal_down) >= GOAL_DEADBAND_M:
            self.goal_down = goal
        return self.goal_down, -self.rate
