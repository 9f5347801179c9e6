"""The companion's one clock: the autopilot's time, estimated between telemetry samples.

ARCHITECTURE.md "Time": the companion paces itself on the autopilot's clock so that a
model running ``--speedup K`` still sees setpoints at 20 Hz of *its* time. Every message carrying
``time_boot_ms`` (LOCAL_POSITION_NED, ATTITUDE, SYSTEM_TIME ...) is fed to :meth:`AutopilotClock.observe`
by the link's receive thread; :meth:`AutopilotClock.now` extrapolates between samples:

* ``rate``: autopilot seconds per wall second, the slope over the last ``rate_window_s`` of wall
  time (samples kept every 50 ms; 1 against a real autopilot, K against a sped-up model), or over
  the window's newer half when that is lower, and none from the first ``settle_s`` after the first
  sample: a paced simulator that stalled catches up in a burst (the model does on first contact),
  and a burst in the window would otherwise inflate the rate, run the estimate into its
  extrapolation cap and stamp setpoints ahead of the autopilot;
* the mapping ``ap = anchor_ap + rate * (wall - anchor_wall)`` is anchored on the *least delayed*
  recent sample (network and thread delays only ever make samples late): a sample replaces the
  anchor when it is ahead of the anchor's prediction slowed by ``leak``, so a rate error cannot
  make the estimate drift away;
* ``now()`` never runs more than ``max_extrapolation_s`` ahead of the newest sample (a stalled or
  dead autopilot stops the companion's time instead of letting it run on) and never goes backwards;
* a jump back of more than a second (the autopilot rebooted) restarts the estimate.

Before the first sample the clock is the wall clock since construction (``synced`` False). The wall
is read through one injectable function (``time.monotonic`` by default), never ``time.time()``.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable


class AutopilotClock:
    """Estimated autopilot time in seconds since its boot (see module docstring)."""

    def __init__(self, wall: Callable[[], float] = time.monotonic, rate_window_s: float = 2.0,
                 max_extrapolation_s: float = 0.25, leak: float = 0.02, settle_s: float = 0.2) -> None:
        self._wall = wall
        self._settle_s = settle_s
        self._rate_window_s = rate_window_s
        self._max_extra = max_extrapolation_s
        self._leak = leak
        self._lock = threading.Lock()
        self._wall0 = wall()
        self._reset()

    def _reset(self) -> None:
        self._synced = False
        self._rate = 1.0
        self._rate_measured = False
        self._anchor_ap = 0.0
        self._anchor_wall = 0.0
        self._last_ap = 0.0
        self._last_wall = 0.0
        self._window: deque[tuple[float, float]] = deque()
        self._sync_wall = 0.0
        self._returned = 0.0
        self.resets = 0

    # --- writer (the receive thread) -----------------------------------------------------------------
    def observe(self, time_boot_ms: int, wall: float | None = None) -> None:
        """One autopilot time stamp, received now (or at ``wall``)."""
        w = self._wall() if wall is None else wall
        ap = time_boot_ms * 1e-3
        with self._lock:
            if self._synced and ap < self._last_ap - 1.0:  # the autopilot rebooted
                resets = self.resets + 1
                self._reset()
                self.resets = resets
            if not self._synced:
                self._synced = True
                self._sync_wall = w
                self._anchor_ap, self._anchor_wall = ap, w
                self._last_ap, self._last_wall = ap, w
                self._returned = ap
                return
            if ap < self._last_ap:  # reordered sample: ignore
                return
            if w - self._sync_wall < self._settle_s:
                pass  # the first samples may be a catch-up burst: no rate from them
            elif not self._window or w - self._window[-1][0] >= 0.05:
                self._window.append((w, ap))
                while len(self._window) > 2 and w - self._window[1][0] >= self._rate_window_s:
                    self._window.popleft()
                self._update_rate(w, ap)
            predicted = self._anchor_ap + self._rate * (1.0 - self._leak) * (w - self._anchor_wall)
            if ap >= predicted:
                self._anchor_ap, self._anchor_wall = ap, w
            self._last_ap, self._last_wall = ap, w

    def _update_rate(self, w: float, ap: float) -> None:
        """The slope over the window, or over its newer half when that is lower (a stall and its
        catch-up burst inside the window would otherwise inflate the rate for ``rate_window_s``)."""
        w0, ap0 = self._window[0]
        if w - w0 < min(0.25, self._rate_window_s) or ap <= ap0:
            return
        rate = (ap - ap0) / (w - w0)
        half = (w - w0) / 2.0
        mid = next(((wi, api) for wi, api in self._window if w - wi <= half), None)
        if mid is not None and w - mid[0] >= 0.1 and ap > mid[1]:
            rate = min(rate, (ap - mid[1]) / (w - mid[0]))
        self._rate = rate
        self._rate_measured = True

    # --- readers ---------------------------------------------------------------------------------------
    @property
    def synced(self) -> bool:
        """True once an autopilot time stamp has been seen."""
        with self._lock:
            return self._synced

    @property
    def rate(self) -> float:
        """Autopilot seconds per wall second (1.0 until measured)."""
        with self._lock:
            return self._rate

    @property
    def last_sample_s(self) -> float:
        """The newest autopilot time received."""
        with self._lock:
            return self._last_ap

    def now(self) -> float:
        """The autopilot's time now (seconds since its boot); wall time since start before any sample."""
        w = self._wall()
        with self._lock:
            if not self._synced:
                return w - self._wall0
            est = self._anchor_ap + self._rate * (w - self._anchor_wall)
            est = min(est, self._last_ap + self._max_extra)
            est = max(est, self._returned)
            self._returned = est
            return est

    def wall_until(self, t_s: float) -> float:
        """Wall seconds until the autopilot reaches ``t_s`` at the current rate (0 if passed)."""
        now = self.now()
        with self._lock:
            rate = self._rate if self._synced else 1.0
        return max(0.0, (t_s - now) / max(rate, 1e-6))
