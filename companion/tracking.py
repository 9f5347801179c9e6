"""The tracking figure: what the companion streamed against what the autopilot said the vehicle did.

On one clock and in one frame: each streamed position setpoint (SET_POSITION_TARGET_LOCAL_NED, stamped
with the autopilot time of its tick) against the autopilot's LOCAL_POSITION_NED interpolated to that
time by ``time_boot_ms``, horizontal and vertical RMS and max. Only streamed setpoints count (not the
autopilot's own take-off or LAND). The demo's report and ``bench/bench_companion`` use it.
"""

from __future__ import annotations

import math
import statistics
from bisect import bisect_left
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from collections.abc import Iterable, Sequence

    from companion.flight.setpoint import Setpoint
    from companion.link.setpoints import TargetFields
    from companion.node import QuadNode

#: Telemetry samples further apart than this (autopilot seconds) are not interpolated between.
MAX_SAMPLE_GAP_S = 0.5
#: A gap between streamed setpoints longer than this (autopilot seconds) is a late tick: the companion's
#: queue advances its reference by at most 0.25 s per tick, while the autopilot moves its target on.
LATE_TICK_S = 0.25
Vec3 = tuple[float, float, float]
#: (autopilot time s, north, east, down) of one LOCAL_POSITION_NED
PositionSample = tuple[float, float, float, float]


# --- the tracking figure -------------------------------------------------------------------------------
@dataclass(frozen=True)
class Tracking:
    """Streamed position setpoints against the autopilot-reported position at the same autopilot time."""

    compared: int
    skipped: int  # setpoints without telemetry on both sides of their time
    h_rms: float
    h_max: float
    v_rms: float
    v_max: float


def position_at(samples: Sequence[PositionSample], times: Sequence[float], t_s: float,
                max_gap_s: float = MAX_SAMPLE_GAP_S) -> Vec3 | None:
    """The position at ``t_s``, linear between the two samples around it (``times`` are the samples'
    sorted times); None outside the samples or across a gap longer than ``max_gap_s``."""
    i = bisect_left(times, t_s)
    if i < len(times) and times[i] == t_s:
        return samples[i][1:]
    if i == 0 or i == len(times):
        return None
    a, b = samples[i - 1], samples[i]
    if b[0] - a[0] > max_gap_s:
        return None
    w = (t_s - a[0]) / (b[0] - a[0])
    return (a[1] + w * (b[1] - a[1]), a[2] + w * (b[2] - a[2]), a[3] + w * (b[3] - a[3]))


def tracking_error(setpoints: Iterable[tuple[float, Vec3]], positions: Iterable[PositionSample],
                   max_gap_s: float = MAX_SAMPLE_GAP_S) -> Tracking:
    """Horizontal and vertical distance (m) of each setpoint ``(t_s, (n, e, d))`` from the reported
    position interpolated to ``t_s``; positions are ``(t_s, n, e, d)`` in the same frame, any order."""
    by_time = {s[0]: s for s in positions}  # a repeated time_boot_ms: the last one
    samples = [by_time[t] for t in sorted(by_time)]
    times = [s[0] for s in samples]
    h: list[float] = []
    v: list[float] = []
    skipped = 0
    for t_s, p in setpoints:
        q = position_at(samples, times, t_s, max_gap_s)
        if q is None:
            skipped += 1
            continue
        h.append(math.hypot(p[0] - q[0], p[1] - q[1]))
        v.append(abs(p[2] - q[2]))

    def rms(xs: list[float]) -> float:
        return math.sqrt(sum(x * x for x in xs) / len(xs)) if xs else math.nan

    return Tracking(len(h), skipped, rms(h), max(h, default=math.nan), rms(v), max(v, default=math.nan))


class StreamRecorder:
    """Records, from a :class:`~companion.node.QuadNode`'s own threads, what the tracking figure needs:
    the streamed position setpoints with their autopilot times (tick thread) and the autopilot's
    LOCAL_POSITION_NED by ``time_boot_ms`` (receive thread); also, for the companion's timing, how far
    each setpoint's stamp is ahead of the newest autopilot time received (``leads``)."""

    def __init__(self, node: QuadNode) -> None:
        # lazy: companion.link loads pymavlink, which the offline report (tracking_error) does not need
        from companion.link.setpoints import IGNORE_POS

        self._ignore_pos = IGNORE_POS
        self.setpoints: list[tuple[float, Vec3]] = []  # (autopilot time, position) of position setpoints
        self.stamps: list[float] = []  # autopilot time of every streamed setpoint
        self.leads: list[float] = []  # stamp minus the newest autopilot time received (the extrapolation)
        self.positions: list[PositionSample] = []
        self._clock = node.clock
        node.setpoint_listeners.append(self._on_setpoint)
        node.link.listeners.append(self._on_message)

    def _on_setpoint(self, _sp: Setpoint, fields: TargetFields, t_ap: float) -> None:
        self.stamps.append(t_ap)
        self.leads.append(t_ap - self._clock.last_sample_s)
        if not fields.type_mask & self._ignore_pos:
            self.setpoints.append((t_ap, fields.p))

    def _on_message(self, msg: Any) -> None:
        if msg.get_type() == "LOCAL_POSITION_NED":
            self.positions.append((msg.time_boot_ms * 1e-3, msg.x, msg.y, msg.z))

    def tracking(self) -> Tracking:
        return tracking_error(self.setpoints, self.positions)

    def report_lines(self) -> list[str]:
        """The report's tracking lines: what is compared, the figures, what they include."""
        tr = self.tracking()
        skipped = f" ({tr.skipped} more without telemetry around them)" if tr.skipped else ""
        gaps = [b - a for a, b in zip(self.stamps, self.stamps[1:], strict=False)]
        span = self.stamps[-1] - self.stamps[0] if self.stamps else 0.0
        rate = f"{len(gaps) / span:.1f} Hz" if span > 0 else "-"
        lines = [
            f"  tracking: {tr.compared} streamed position setpoints{skipped} vs the position the autopilot "
            "reported",
            "    (LOCAL_POSITION_NED, same local NED frame) at each setpoint's autopilot time (interpolated",
            "    by time_boot_ms), only while streaming (not the autopilot's own take-off or LAND):",
            f"    horizontal RMS {tr.h_rms:.2f} m, max {tr.h_max:.2f} m; "
            f"vertical RMS {tr.v_rms:.2f} m, max {tr.v_max:.2f} m",
            "    = the vehicle's lag/lead on the reference + the companion's timing (late/early setpoints):",
            f"    setpoints at {rate} of autopilot time over {span:.1f} s, longest gap "
            f"{max(gaps, default=0.0):.2f} s ({sum(g > LATE_TICK_S for g in gaps)} over {LATE_TICK_S:g} s)",
        ]
        if self.leads:
            lead = statistics.median(self.leads)
            lines.append(f"    setpoint stamps ahead of the newest autopilot time: median {lead:+.2f} s,"
                         f" range {min(self.leads):+.2f}..{max(self.leads):+.2f} s")
        return lines
