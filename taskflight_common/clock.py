"""One clock object per process: every loop takes its time from here, never from ``time.time()``.

:class:`SimClock` is owned by the autopilot model. Simulated time is an integer count of
microseconds advanced by the main loop (so 500 Hz steps never drift). It is paced against the wall:

* ``speedup=1``: real time (the default; what a real autopilot does),
* ``speedup=K``: K simulated seconds per wall second,
* ``speedup=0`` (lockstep, as fast as possible): never waits.

Behind its pacing (a loaded machine, a stall), the clock runs periods back to back to catch up, but
never more than ``max_lag_s`` of wall time (0.1 s, as ArduPilot's SITL bounds its sleep debt in
``SIM_Aircraft::sync_frame_time``): a longer stall is given up (counted in ``slips``), so a starved
simulation runs slower than its speed-up instead of racing through seconds of simulated time in a
burst that its companions, pacing themselves on its clock, could not follow.

Other layers (the companion) follow the autopilot's reported time instead
(``companion.link.clock.AutopilotClock``): against a real autopilot that is the autopilot's own clock.
"""

from __future__ import annotations

import logging
import time
from typing import Protocol

log = logging.getLogger(__name__)

#: Wall seconds a paced clock may be behind before it gives the lost time up (ArduPilot's SITL: 0.1 s).
MAX_LAG_S = 0.1
#: Wall seconds between two warnings about given-up time.
SLIP_WARNING_EVERY_S = 10.0


class Clock(Protocol):
    """What every loop needs of a clock."""

    def now(self) -> float:
        """Seconds since the clock's epoch (boot)."""
        ...


class SimClock:
    """Simulated time in microseconds, advanced by the owner of the main loop and paced on the wall."""

    def __init__(self, speedup: float = 1.0, spin_s: float = 0.001, max_lag_s: float = MAX_LAG_S) -> None:
        if speedup < 0:
            raise ValueError(f"speedup must be >= 0 (0 = as fast as possible), got {speedup}")
        if not 0.0 <= spin_s <= 0.01:
            raise ValueError(f"spin_s must be within 0..0.01 s, got {spin_s}")
        if not max_lag_s > 0.0:
            raise ValueError(f"max_lag_s must be > 0 s, got {max_lag_s}")
        self.max_lag_s = float(max_lag_s)
        """Wall seconds the clock may fall behind its pacing before it gives the lost time up."""
        self.slips = 0
        """Times :meth:`pace` found the clock more than ``max_lag_s`` behind and gave time up."""
        self.given_up_s = 0.0
        """Wall seconds given up so far (each slip keeps ``max_lag_s`` to catch up)."""
        self.sleeps = 0
        """Times :meth:`pace` slept (one sleep a period when ahead; again if woken early)."""
        self.spins = 0
        """Times :meth:`pace` looked at the wall again without sleeping (busy-waits); 0 with ``spin_s=0``."""
        self._warned_wall = -SLIP_WARNING_EVERY_S
        self.speedup = float(speedup)
        self.spin_s = float(spin_s)
        """Wall seconds :meth:`pace` spins (busy-waits) before a deadline instead of sleeping: 1 ms by
        default (one vehicle, tens of microseconds of jitter, half a core); 0 = sleep only (the fleet,
        :mod:`autopilot_model.fleet`: the OS's wake-up jitter, a few percent of a core)."""
        self.now_us = 0
        self._wall0 = time.perf_counter()
        self._sim0_us = 0

    # --- reading -------------------------------------------------------------------------------
    def now(self) -> float:
        return self.now_us * 1e-6

    @property
    def time_boot_ms(self) -> int:
        return self.now_us // 1000

    @property
    def time_usec(self) -> int:
        return self.now_us

    # --- writing (only the main loop owner calls these) -----------------------------------------
    def advance(self, dt_us: int) -> None:
        self.now_us += dt_us

    def set_speedup(self, speedup: float) -> None:
        if speedup < 0:
            raise ValueError(f"speedup must be >= 0, got {speedup}")
        self.speedup = float(speedup)
        self._wall0 = time.perf_counter()
        self._sim0_us = self.now_us

    def wall_lag(self) -> float:
        """Seconds of wall time by which the simulation is behind its pacing (<= 0 when ahead)."""
        if self.speedup <= 0:
            return 0.0
        target_wall = (self.now_us - self._sim0_us) * 1e-6 / self.speedup
        return (time.perf_counter() - self._wall0) - target_wall

    def _slip(self, behind: float) -> None:
        lost = behind - self.max_lag_s
        self._wall0 += lost
        self.slips += 1
        self.given_up_s += lost
        now = time.perf_counter()
        if now - self._warned_wall >= SLIP_WARNING_EVERY_S:
            self._warned_wall = now
            log.warning("simulation %.2f s behind real time x%g: giving the lost time up (%d slips, %.1f s "
                        "in all)", behind, self.speedup, self.slips, self.given_up_s)

    def pace(self) -> float:
        """Wait until the wall has caught up with simulated time; returns the seconds slept.

        More than ``max_lag_s`` behind, the pacing is moved so that the clock is ``max_lag_s`` behind
        (a slip; the module docstring) and it returns at once.

        Sleeps in one call when ahead by more than ``spin_s`` + 0.5 ms and spins for the remainder: with
        the default ``spin_s`` (1 ms) a 500 Hz real-time loop stays within tens of microseconds of its
        period. With ``spin_s=0`` it only sleeps (late by the OS's wake-up jitter, ~0.1 ms).
        """
        if self.speedup <= 0:
            return 0.0
        target_wall = self._wall0 + (self.now_us - self._sim0_us) * 1e-6 / self.speedup
        remaining = target_wall - time.perf_counter()
        if remaining < -self.max_lag_s:
            self._slip(-remaining)
            return 0.0
        spin = self.spin_s
        slept = 0.0
        while True:
            if remaining <= 0:
                return slept
            if spin == 0.0:
                time.sleep(remaining)
                self.sleeps += 1
            elif remaining > spin + 0.0005:
                time.sleep(remaining - spin)
                self.sleeps += 1
            else:
                self.spins += 1
            after = target_wall - time.perf_counter()
            slept += max(0.0, remaining - max(0.0, after))
            remaining = after
