"""External data streams for the External* flight command modes (seed 000 Sec. IV-C).

A stream carries samples of one kind, each with a *validity time*: after ``t_s + validity_s`` with
no newer sample the stream is stale and the channel using it falls back (Sec. IV-C): a velocity goes
to zero, a position (or heading, or point) holds where the reference is. The streams:

=============  ======================================  =============================================
stream         values                                  used by
=============  ======================================  =============================================
``ext_pos``    north, east, down (m, local NED)        H_ExtPos, H_KeepDistance, V_ExtPos
``ext_vel``    v_north, v_east, v_down (m/s),          H_ExtVel, V_ExtVel, Hd_ExtVel (a joystick
               yaw_rate (deg/s)                        sends all four; each channel takes its part)
``ext_heading`` heading (deg)                          Hd_ExtPos
``ext_point``  north, east (m)                         Hd_ExtPoint
``rc_vel``     as ``ext_vel``                          the RC_VEL modes (see commands.py)
=============  ======================================  =============================================

Every sample names its *source* (:data:`SOURCES`); a stream may be tied to one source
(:meth:`ExternalData.select`, seed 000 Sec. VI-F's external-velocity ``source``): while it is, a sample
from another source is ignored (``push`` returns False) and moves nothing.

A malformed sample (unknown stream, wrong number of values, NaN / infinite values, a validity that
is not > 0 or above the configured maximum, a time that is not finite) raises
:class:`ExternalDataError` and changes nothing. A sample older than the stream's newest one is
ignored (``push`` returns False): UDP may reorder.

A sample stamped where it was made (an operator's stick: ``t_s`` = arrival minus the age it already
had, so its validity counts from the operator's hand, not from its arrival) that is already past its
validity on arrival is dropped (:meth:`ExternalData.offer` says why). A sample may carry a sequence
number per ``source`` (e.g. a stick lease): one not above that source's last is out of order and
dropped, whatever its time stamp says (a clock estimate may jitter; the sender's counter does not).

Thread safety: not locked itself; the :class:`~companion.flight.queue.CommandQueue` owns one and
mutates it only under its own lock (``CommandQueue.push_external``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

#: The longest validity a sample may claim (s) unless configured otherwise: a sample valid for an hour
#: would defeat the stop-on-loss of Sec. IV-C (a dead joystick must stop the vehicle promptly).
DEFAULT_MAX_VALIDITY_S = 5.0
#: Stream name -> number of values.
#: How many (stream, source) sequence counters are remembered (the least recently used forgotten).
MAX_SOURCES = 64
STREAMS: dict[str, int] = {"ext_pos": 3, "ext_vel": 4, "ext_heading": 1, "ext_point": 2, "rc_vel": 4}
#: Source name -> where its samples come from.
SOURCES: dict[str, str] = {"joystick": "the operator's stick (POST /behaviors/joystick)",
                           "external": "any program (POST /external/<stream>, UDP feeds)"}
#: The source of a sample that does not name one.
DEFAULT_SOURCE = "external"


class ExternalDataError(ValueError):
    """A malformed external-data sample; nothing was changed."""


@dataclass(frozen=True)
class Sample:
    """One sample: ``values`` stamped at ``t_s`` (the companion's clock), valid for ``validity_s``."""

    values: tuple[float, ...]
    t_s: float
    validity_s: float
    #: which stream of the vehicle's sources it is (:data:`SOURCES`: the joystick, external data)
    source: str = DEFAULT_SOURCE
    #: who sent it (sequence numbers are per sender, e.g. a stick lease); None: anonymous
    sender: str | None = None

    def fresh(self, now_s: float) -> bool:
        return now_s <= self.t_s + self.validity_s


class ExternalData:
    """The newest sample of each stream; validities above ``max_validity_s`` are refused."""

    def __init__(self, max_validity_s: float = DEFAULT_MAX_VALIDITY_S) -> None:
        if isinstance(max_validity_s, bool) or not isinstance(max_validity_s, int | float) \
                or not math.isfinite(max_validity_s) or max_validity_s <= 0:
            raise ValueError(f"max_validity_s must be a finite number of seconds > 0, got {max_validity_s!r}")
        self.max_validity_s = float(max_validity_s)
        self._latest: dict[str, Sample] = {}
        self._selected: dict[str, str] = {}
        #: (stream, sender) -> the last sequence number taken (the oldest senders forgotten first)
        self._seqs: dict[tuple[str, str | None], int] = {}

    def select(self, stream: str, source: str | None) -> None:
        """Take ``stream``'s samples from ``source`` only (None: from any source again)."""
        if stream not in STREAMS:
            raise ExternalDataError(f"unknown stream {stream!r} (known: {', '.join(sorted(STREAMS))})")
        if source is None:
            self._selected.pop(stream, None)
            return
        if source not in SOURCES:
            raise ExternalDataError(f"unknown source {source!r} (known: {', '.join(sorted(SOURCES))})")
        self._selected[stream] = source

    def selected(self, stream: str) -> str | None:
        """The one source ``stream`` is taken from, or None (any)."""
        return self._selected.get(stream)

    def validate(self, stream: str, values: Sequence[float], validity_s: float, t_s: float) -> Sample:
        """Check a sample without storing it; raise :class:`ExternalDataError` when malformed."""
        if not isinstance(stream, str) or stream not in STREAMS:
            raise ExternalDataError(f"unknown stream {stream!r} (known: {', '.join(sorted(STREAMS))})")
        n = STREAMS[stream]
        try:
            vals = tuple(float(v) for v in values)
        except (TypeError, ValueError) as exc:
            raise ExternalDataError(f"{stream}: expected {n} numbers, got {values!r}") from exc
        if any(isinstance(v, bool) for v in values):
            raise ExternalDataError(f"{stream}: expected {n} numbers, got booleans")
        if len(vals) != n:
            raise ExternalDataError(f"{stream}: expected {n} values, got {len(vals)}")
        if not all(math.isfinite(v) for v in vals):
            raise ExternalDataError(f"{stream}: values must be finite, got {vals}")
        if isinstance(validity_s, bool) or not isinstance(validity_s, int | float) \
                or not math.isfinite(validity_s) or validity_s <= 0:
            raise ExternalDataError(f"{stream}: validity must be a finite number of seconds > 0, "
                                    f"got {validity_s!r}")
        if validity_s > self.max_validity_s:
            raise ExternalDataError(f"{stream}: validity {validity_s:g} s exceeds the maximum of "
                                    f"{self.max_validity_s:g} s (a stale stream must stop the vehicle)")
        if isinstance(t_s, bool) or not isinstance(t_s, int | float) or not math.isfinite(t_s):
            raise ExternalDataError(f"{stream}: sample time must be finite, got {t_s!r}")
        return Sample(vals, float(t_s), float(validity_s))

    def push(self, stream: str, values: Sequence[float], validity_s: float, t_s: float,
             source: str = DEFAULT_SOURCE) -> bool:
        """Store a sample; False when older than the newest one of that stream, or from another source
        than the one the stream is tied to (then ignored)."""
        return self.offer(stream, values, validity_s, t_s, source=source) is None

    def offer(self, stream: str, values: Sequence[float], validity_s: float, t_s: float, *,
              seq: int | None = None, sender: str | None = None, now_s: float | None = None,
              source: str = DEFAULT_SOURCE) -> str | None:
        """Store a sample, or say why it was dropped: from another source than the one the stream is tied
        to, stale at ``now_s`` (past its validity on arrival), out of order (``seq`` not above ``sender``'s
        last), or older than the stream's newest sample. Malformed: :class:`ExternalDataError`, nothing
        changed."""
        sample = self.validate(stream, values, validity_s, t_s)
        if source not in SOURCES:
            raise ExternalDataError(f"{stream}: unknown source {source!r} "
                                    f"(known: {', '.join(sorted(SOURCES))})")
        if seq is not None and (isinstance(seq, bool) or not isinstance(seq, int) or seq < 0):
            raise ExternalDataError(f"{stream}: seq must be an integer >= 0, got {seq!r}")
        if sender is not None and not isinstance(sender, str):
            raise ExternalDataError(f"{stream}: sender must be a string, got {sender!r}")
        if self._selected.get(stream, source) != source:
            return f"{stream} is tied to the {self._selected[stream]} source, not {source}"
        sample = Sample(sample.values, sample.t_s, sample.validity_s, source, sender)
        if now_s is not None and not sample.fresh(now_s):
            return (f"stale: {now_s - sample.t_s:.3f} s old on arrival, valid for {sample.validity_s:g} s")
        key = (stream, sender)
        if seq is not None:
            last = self._seqs.get(key)
            if last is not None and seq <= last:
                return f"out of order: seq {seq} after {last} from {sender or 'this sender'}"
        old = self._latest.get(stream)
        same_sender = seq is not None and old is not None and old.sender == sender
        if old is not None and sample.t_s < old.t_s and not same_sender:
            return "older than the stream's newest sample"
        if seq is not None:
            self._seqs.pop(key, None)
            self._seqs[key] = seq
            while len(self._seqs) > MAX_SOURCES:
                del self._seqs[next(iter(self._seqs))]
        self._latest[stream] = sample
        return None

    def latest(self, stream: str, now_s: float) -> tuple[float, ...] | None:
        """The newest sample's values if still valid at ``now_s``, else None."""
        if stream not in STREAMS:
            raise ExternalDataError(f"unknown stream {stream!r}")
        sample = self._latest.get(stream)
        if sample is None or not sample.fresh(now_s):
            return None
        if self._selected.get(stream, sample.source) != sample.source:
            return None  # stored before the stream was tied to another source
        return sample.values

    def sample(self, stream: str) -> Sample | None:
        """The newest sample of ``stream``, fresh or not (for status and tests)."""
        return self._latest.get(stream)

    def clear(self) -> None:
        self._latest.clear()
        self._seqs.clear()
