"""The pilot's radio: RC channels from RC_CHANNELS_OVERRIDE and MANUAL_CONTROL, and the RC failsafe.

The model has no RC receiver; its radio is the ground station's override, as an ArduCopter whose only
RC is MAVLink (``SIM_RC_FAIL=1`` in ArduPilot SITL). Everything follows ArduPilot's ``RC_Channel`` /
``RC_Channels`` and ArduCopter's ``radio.cpp``:

* RC_CHANNELS_OVERRIDE (``GCS_MAVLINK::handle_rc_channels_override``): channels 1-8 take any value but
  65535 (ignore); 0 releases the channel. Channels 9-16 ignore 0 and 65535; 65534 releases.
* MANUAL_CONTROL (``GCS_MAVLINK_Copter::handle_manual_control_axes``): y -> roll, x -> pitch (reversed:
  x forward = low PWM), r -> yaw over RCn_MIN..RCn_MAX from -1000..1000, z -> throttle from 0..1000;
  a negative z is ignored; 32767 (INT16_MAX) releases the axis.
* An override lasts RC_OVERRIDE_TIME seconds (3); after it the channel keeps its last value (no receiver
  to fall back to, as ArduCopter's ``RC_Channel::update`` without a receiver).
* ``control_in``: roll, pitch and yaw are angles -4500..4500 around RCn_TRIM with the dead zone RCn_DZ
  (``pwm_to_angle_dz_trim``); throttle is 0..1000 above RCn_MIN + RC3_DZ (``pwm_to_range_dz``).
  Channel map RCMAP: roll 1, pitch 2, throttle 3, yaw 4.
* RC failsafe (``Copter::read_radio``, ``set_throttle_and_failsafe``): no new RC input for RC_FS_TIMEOUT
  (1 s), or the throttle PWM below FS_THR_VALUE (975), while FS_THR_ENABLE is set. It arms only once RC
  has been seen (ArduCopter also fails safe armed with no RC at all; the model never has a receiver, so
  the companion's GUIDED flights would end). The action is in :mod:`.pilot_modes` (``radio_failsafe``).

Time is simulated time (the vehicle clock), as ``AP_HAL::millis()`` in ArduCopter SITL.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from autopilot_model.modules.vehicle_api import VehicleApi
    from autopilot_model.params import ParamStore

log = logging.getLogger(__name__)

NUM_CHANNELS = 16
ROLL, PITCH, THROTTLE, YAW = 0, 1, 2, 3  # RCMAP defaults, 0-based
ANGLE_INPUT_MAX = 4500.0  # ROLL_PITCH_YAW_INPUT_MAX (centidegrees)
UINT16_MAX = 65535
INT16_MAX = 32767


def define_rc_params(params: ParamStore) -> None:
    for ch in range(1, 5):
        params.define(f"RC{ch}_MIN", 1100.0, 800.0, 2200.0, "int", f"RC channel {ch} minimum PWM (us)")
        params.define(f"RC{ch}_MAX", 1900.0, 800.0, 2200.0, "int", f"RC channel {ch} maximum PWM (us)")
        params.define(f"RC{ch}_TRIM", 1500.0, 800.0, 2200.0, "int", f"RC channel {ch} trim PWM (us)")
        params.define(f"RC{ch}_DZ", 30.0 if ch == 3 else 20.0, 0.0, 200.0, "int",
                      f"RC channel {ch} dead zone (us)")
    params.define("RC_OVERRIDE_TIME", 3.0, -1.0, 120.0, doc="an RC override lasts this long (s); -1 forever")
    params.define("RC_FS_TIMEOUT", 1.0, 0.1, 10.0, doc="RC failsafe after no RC input for this long (s)")
    params.define("FS_THR_ENABLE", 1, 0, 7, "int",
                  "RC failsafe: 0 off, 1 RTL, 3 LAND, 4 SmartRTL/RTL, 5 SmartRTL/LAND, 6 DO_LAND_START/RTL, "
                  "7 BRAKE/LAND")
    params.define("FS_THR_VALUE", 975, 910, 1100, "int", "RC failsafe when the throttle PWM is below (us)")
    params.define("FS_OPTIONS", 16, 0, 127, "int",
                  "failsafe options: 1 RC continue in AUTO, 4 RC continue in GUIDED, 8 continue landing")


class RcInput:
    """The RC channels of one vehicle (the one writer of ``radio_in``) and the RC failsafe's state."""

    def __init__(self, vehicle: VehicleApi) -> None:
        self.v = vehicle
        self.params = vehicle.params
        define_rc_params(self.params)
        self.radio_in = [0] * NUM_CHANNELS
        self._override = [0] * NUM_CHANNELS
        self._override_t = [0.0] * NUM_CHANNELS
        self.chancount = 0
        self.seen = False
        """RC (an override) has been seen at least once."""
        self.last_input_s: float | None = None
        self.failsafe = False
        self._low_count = 0
        self.on_failsafe: list[Callable[[bool], None]] = []
        """``callback(on)`` when the RC failsafe starts or ends."""

    # --- input ---------------------------------------------------------------------------------
    def _set(self, ch: int, value: int, now: float) -> None:
        self._override[ch] = value
        self._override_t[ch] = now

    def _new_input(self, now: float) -> None:
        self.seen = True
        self.last_input_s = now
        self._update_channels(now)
        self._check_throttle()

    def override(self, values: list[int]) -> None:
        """RC_CHANNELS_OVERRIDE's chan1_raw.. (up to 16 values used)."""
        now = self.v.clock.now()
        for i, val in enumerate(values[:NUM_CHANNELS]):
            val = int(val)
            if i < 8:
                if val != UINT16_MAX:
                    self._set(i, val, now)
            elif val not in (0, UINT16_MAX):
                self._set(i, 0 if val == UINT16_MAX - 1 else val, now)
        self._new_input(now)

    def manual_control(self, x: int, y: int, z: int, r: int) -> None:
        """MANUAL_CONTROL's axes, as ArduCopter maps them onto channels 1-4."""
        if z < 0:  # Copter doesn't do negative thrust
            return
        now = self.v.clock.now()
        for ch, value, offset, scaler, reverse in ((ROLL, y, 1000, 2000.0, False),
                                                   (PITCH, x, 1000, 2000.0, True),
                                                   (THROTTLE, z, 0, 1000.0, False),
                                                   (YAW, r, 1000, 2000.0, False)):
            out = 0
            if value != INT16_MAX:
                lo, hi = self._min(ch), self._max(ch)
                value = -value if reverse else value
                out = int(lo + (hi - lo) * (value + offset) / scaler)
            self._set(ch, out, now)
        self._new_input(now)

    def _update_channels(self, now: float) -> None:
        timeout = self.params.get("RC_OVERRIDE_TIME")
        for i in range(NUM_CHANNELS):
            val = self._override[i]
            if val == 0:
                continue
            if timeout >= 0 and now - self._override_t[i] >= timeout:
                continue  # expired: the channel keeps its last value (no receiver behind it)
            self.radio_in[i] = val
            self.chancount = max(self.chancount, i + 1)

    def _check_throttle(self) -> None:
        """``set_throttle_and_failsafe``: 3 frames below FS_THR_VALUE set it, one above clears it."""
        if int(self.params.get("FS_THR_ENABLE")) == 0:
            self._set_failsafe(False)
            return
        if self.radio_in[THROTTLE] < self.params.get("FS_THR_VALUE"):
            if self.failsafe or not (self.seen or self.v.nav.armed):
                return
            self._low_count += 1
            if self._low_count >= 3:
                self._set_failsafe(True)
        else:
            self._low_count = max(0, self._low_count - 1)
            if self._low_count == 0:
                self._set_failsafe(False)

    def _set_failsafe(self, on: bool) -> None:
        if on != self.failsafe:
            self.failsafe = on
            for cb in self.on_failsafe:
                cb(on)

    def periodic(self) -> None:
        """``read_radio`` without new input: the timeout side of the failsafe (10 Hz or faster)."""
        if self.failsafe or not self.seen or self.last_input_s is None:
            return
        if self.v.clock.now() - self.last_input_s < self.params.get("RC_FS_TIMEOUT"):
            return
        if int(self.params.get("FS_THR_ENABLE")) == 0:
            return
        self._set_failsafe(True)

    # --- read-outs -----------------------------------------------------------------------------
    def _min(self, ch: int) -> int:
        return int(self.params.get(f"RC{ch + 1}_MIN")) if ch < 4 else 1100

    def _max(self, ch: int) -> int:
        return int(self.params.get(f"RC{ch + 1}_MAX")) if ch < 4 else 1900

    def angle(self, ch: int) -> float:
        """``pwm_to_angle_dz_trim``: -4500..4500 (roll right, pitch back, yaw right positive)."""
        pwm: float = self.radio_in[ch]
        if pwm == 0:
            return 0.0
        n = ch + 1
        trim = self.params.get(f"RC{n}_TRIM")
        dz = self.params.get(f"RC{n}_DZ")
        lo, hi = self.params.get(f"RC{n}_MIN"), self.params.get(f"RC{n}_MAX")
        pwm = min(max(pwm, lo), hi)
        if pwm > trim + dz and hi > trim + dz:
            return ANGLE_INPUT_MAX * (pwm - (trim + dz)) / (hi - (trim + dz))
        if pwm < trim - dz and trim - dz > lo:
            return ANGLE_INPUT_MAX * (pwm - (trim - dz)) / ((trim - dz) - lo)
        return 0.0

    def stick(self, ch: int) -> float:
        """Roll, pitch or yaw stick in -1..1 (after trim and dead zone)."""
        return self.angle(ch) / ANGLE_INPUT_MAX

    def throttle(self) -> float:
        """``pwm_to_range_dz``: the throttle stick 0..1000 (500 with no RC: mid-stick)."""
        pwm: float = self.radio_in[THROTTLE]
        if pwm == 0:
            return 500.0
        lo, hi = self.params.get("RC3_MIN"), self.params.get("RC3_MAX")
        low = lo + self.params.get("RC3_DZ")
        pwm = min(max(pwm, lo), hi)
        if pwm <= low or hi <= low:
            return 0.0
        return 1000.0 * (pwm - low) / (hi - low)
