"""The QuadNode (seed 000 Sec. V, Fig. 10): the command queue, the external data and the link together.

In the paper a ROS QuadNode implements the QAPI service calls and keeps the platform's firmware
executing the queue. Here :class:`QuadNode` owns

* the :class:`~companion.flight.queue.CommandQueue` (QAPI verbs, status, external-data streams),
* the :class:`~companion.link.connection.MavlinkLink` (receive thread, mirror, clock),
* the :class:`~companion.link.guided.GuidedSupervisor` (take-off, streaming, landing, override),

and runs the *tick thread*: at ``rate_hz`` of **autopilot time** (the link's
:class:`~companion.link.clock.AutopilotClock`) it ticks the queue with the mirrored vehicle state and
streams the setpoint as SET_POSITION_TARGET_LOCAL_NED when the supervisor says so. Tick times are
multiples of the period on the autopilot's clock; a loop that falls more than three periods behind
resynchronises instead of bursting.

The queue's time is the autopilot's minus the time the node held it still: during an autopilot
take-off (GUIDED, arm, MAV_CMD_NAV_TAKEOFF, lift-off) the queue does not advance, so the reference
leaves the ground together with the vehicle. External-data samples are stamped on the queue's time.

Threads: the receive thread writes the mirror; the tick thread ticks the queue and sends; callers
(the HTTP surface, pause_routines) use the verbs, which take the queue's own lock.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, replace
from enum import StrEnum
from typing import Any

from companion.flight import (
    CommandQueue,
    Envelope,
    FlightCommand,
    Limits,
    PauseRoutineCatalog,
    QueueStatus,
    Retarget,
    Setpoint,
    VehicleState,
)
from companion.flight.external import DEFAULT_MAX_VALIDITY_S
from companion.link import AutopilotClock, GuidedSupervisor, MavlinkLink, Phase
from companion.link.fence import FenceClient as AutopilotFence
from companion.link.fence import FenceError as FenceError  # re-exported, as ParamError
from companion.link.mirror import LAND, M, MirrorState
from companion.link.params import ParamClient as AutopilotParams
from companion.link.params import ParamError as ParamError  # re-exported: upper layers read no link module
from companion.link.rc import RcMapping, rc_velocity
from companion.link.setpoints import TargetFields

log = logging.getLogger(__name__)

MIN_RATE_HZ = 1.0
MAX_RATE_HZ = 50.0
#: (setpoint, the fields sent, autopilot time of the tick) for each streamed setpoint
SetpointListener = Callable[[Setpoint, TargetFields, float], None]


#: height above home (m) above which an armed vehicle without a landed_state report is flying
AIRBORNE_HEIGHT_M = 0.3


class FlightState(StrEnum):
    """Where the vehicle is in its flight (the ``flight_state`` belief of seed 001 Sec. 6.2.5)."""

    LANDED = "landed"
    TAKING_OFF = "taking_off"
    FLYING = "flying"
    LANDING = "landing"


@dataclass(frozen=True)
class RangeStatus:
    """The downward range finder as the upper layers read it (the autopilot's DISTANCE_SENSOR, rotation
    PITCH_270): ``distance_m`` the reading, ``age_s`` its age on the autopilot's clock, ``in_range`` inside
    the sensor's min/max distances, ``ground_alt`` the ground's altitude under the vehicle (m up, local
    frame; None out of range), ``vertical_m`` the reading made vertical (times cos roll x cos pitch)."""

    distance_m: float
    age_s: float
    in_range: bool
    min_m: float
    max_m: float
    ground_alt: float | None
    vertical_m: float = 0.0


def range_status(s: MirrorState, t_ap: float) -> RangeStatus | None:
    """The downward range of mirror state ``s`` at autopilot time ``t_ap`` (None: never reported)."""
    r = s.range_down
    if r is None:
        return None
    return RangeStatus(r.distance_m, max(0.0, t_ap - r.time_boot_ms / 1000.0), r.in_range, r.min_m, r.max_m,
                       r.ground_altitude, r.distance_m * r.cos_tilt)


@dataclass(frozen=True)
class VehicleStatus:
    """What the upper layers (behaviors, missions, team) read of the vehicle: one consistent snapshot.

    ``position`` and ``velocity`` are NED metres (m/s) from home (None before the first estimate);
    ``position_time_ms`` the estimate's autopilot time; ``global_position`` (lat, lon, alt AMSL, alt above
    home); ``home`` (lat, lon, alt AMSL); ``mode`` the ArduCopter mode's name; ``on_ground``: disarmed or
    reported on the ground; ``overridden``: a ground station took the vehicle out of GUIDED;
    ``battery_remaining`` percent (None when unknown); ``time_s`` the autopilot's clock at the snapshot.
    For the safety monitor: ``battery_voltage`` (V), ``battery_current`` (A) and ``battery_consumed_mah``
    (None when unknown); ``estimate_healthy`` SYS_STATUS's AHRS health bit (the autopilot's EKF; None
    before a SYS_STATUS); ``fence_breached`` the autopilot reports its geofence breached (SYS_STATUS);
    ``link_connected`` the autopilot heard within the link's time-out;
    ``range_down`` the downward range finder, age-stamped (None: the autopilot reports none).
    """

    time_s: float
    armed: bool
    mode: str | None
    flight: FlightState
    on_ground: bool
    overridden: bool
    position: tuple[float, float, float] | None
    position_time_ms: int | None
    velocity: tuple[float, float, float]
    yaw: float
    global_position: tuple[float, float, float, float] | None
    home: tuple[float, float, float] | None
    battery_remaining: int | None
    #: what the command queue's tick wants (None before a position)
    state: VehicleState | None
    battery_voltage: float | None = None
    battery_current: float | None = None
    battery_consumed_mah: float | None = None
    estimate_healthy: bool | None = None
    fence_breached: bool = False
    link_connected: bool = True
    range_down: RangeStatus | None = None

    @classmethod
    def of(cls, s: MirrorState, time_s: float = 0.0, overridden: bool = False,
           connected: bool = True) -> VehicleStatus:
        """The status of a link's mirror state ``s``."""
        ahrs, fence = M.MAV_SYS_STATUS_AHRS, M.MAV_SYS_STATUS_GEOFENCE
        return cls(time_s=time_s, armed=s.armed, mode=s.mode_name, flight=flight_state(s),
                   on_ground=s.landed_state == M.MAV_LANDED_STATE_ON_GROUND or not s.armed,
                   overridden=overridden, position=s.position, position_time_ms=s.position_time_ms,
                   velocity=(float(s.velocity[0]), float(s.velocity[1]), float(s.velocity[2])),
                   yaw=s.yaw, global_position=s.global_position, home=s.home,
                   battery_remaining=s.battery_remaining, state=with_ground(s, time_s),
                   battery_voltage=s.battery_voltage, battery_current=s.battery_current,
                   battery_consumed_mah=s.battery_consumed_mah,
                   estimate_healthy=bool(s.sensors_health & ahrs) if s.sensors_present & ahrs else None,
                   fence_breached=bool(s.sensors_present & fence) and not s.sensors_health & fence,
                   link_connected=connected, range_down=range_status(s, time_s))


def with_ground(s: MirrorState, t_ap: float) -> VehicleState | None:
    """``s.vehicle_state()`` with the ground under the vehicle from the downward range finder (age-stamped
    at autopilot time ``t_ap``), for the queue's V_GROUND mode."""
    vs = s.vehicle_state()
    r = range_status(s, t_ap)
    if vs is None or r is None or r.ground_alt is None:
        return vs
    return replace(vs, ground_alt=r.ground_alt, ground_age_s=r.age_s)


def flight_state(state: MirrorState) -> FlightState:
    """The flight state of a mirror state.

    Disarmed is landed. Armed: EXTENDED_SYS_STATE's landed_state decides (ON_GROUND -> landed,
    TAKEOFF -> taking_off, LANDING -> landing, IN_AIR -> flying, or landing in mode LAND); when the
    autopilot does not report it (UNDEFINED), mode LAND is landing and otherwise the vehicle counts as
    flying once it is :data:`AIRBORNE_HEIGHT_M` up.
    """
    if not state.armed:
        return FlightState.LANDED
    ls = state.landed_state
    if ls == M.MAV_LANDED_STATE_ON_GROUND:
        return FlightState.LANDED
    if ls == M.MAV_LANDED_STATE_TAKEOFF:
        return FlightState.TAKING_OFF
    if ls == M.MAV_LANDED_STATE_LANDING:
        return FlightState.LANDING
    if ls == M.MAV_LANDED_STATE_IN_AIR:
        return FlightState.LANDING if state.mode == LAND else FlightState.FLYING
    up = -state.position[2] if state.position is not None else 0.0
    if up < AIRBORNE_HEIGHT_M:
        return FlightState.LANDED
    return FlightState.LANDING if state.mode == LAND else FlightState.FLYING


class QueueTime:
    """The queue's clock: autopilot time minus the spans it was held still."""

    def __init__(self, clock: AutopilotClock) -> None:
        self._clock = clock
        self._lock = threading.Lock()
        self._offset = 0.0
        self._held_at: float | None = None

    def of(self, t_ap: float) -> float:
        with self._lock:
            if self._held_at is not None:
                t_ap = min(t_ap, self._held_at)
            return t_ap - self._offset

    def now(self) -> float:
        return self.of(self._clock.now())

    @property
    def held(self) -> bool:
        with self._lock:
            return self._held_at is not None

    def hold(self, t_ap: float) -> None:
        with self._lock:
            if self._held_at is None:
                self._held_at = t_ap

    def release(self, t_ap: float) -> None:
        with self._lock:
            if self._held_at is not None:
                self._offset += max(0.0, t_ap - self._held_at)
                self._held_at = None


class QuadNode:
    """One vehicle's companion: QAPI verbs and status over a MAVLink autopilot (see module docstring)."""

    def __init__(self, autopilot_url: str, *, rate_hz: float = 20.0, limits: Limits | None = None,
                 envelope: Envelope | None = None, catalog: PauseRoutineCatalog | None = None,
                 baud: int = 57600,
                 source_system: int | None = None, max_validity_s: float = DEFAULT_MAX_VALIDITY_S,
                 rc_mapping: RcMapping | None = None) -> None:
        if not MIN_RATE_HZ <= rate_hz <= MAX_RATE_HZ:
            raise ValueError(f"rate: {rate_hz:g} Hz is outside {MIN_RATE_HZ:g}..{MAX_RATE_HZ:g} Hz")
        self.rate_hz = float(rate_hz)
        self.period_s = 1.0 / self.rate_hz
        self.clock = AutopilotClock()
        self.link = MavlinkLink(autopilot_url, baud=baud, rate_hz=rate_hz, source_system=source_system,
                                clock=self.clock)
        self.queue_time = QueueTime(self.clock)
        self.queue = CommandQueue(limits, envelope, catalog, clock=self.queue_time,
                                  max_validity_s=max_validity_s)
        self.supervisor = GuidedSupervisor(self.link)
        self.setpoint_listeners: list[SetpointListener] = []
        self.rc_mapping = rc_mapping or RcMapping()
        self._rc_seen_ms: int | None = None
        self.ticks = 0
        self.streamed = 0
        self.resyncs = 0
        self.last_setpoint: Setpoint | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # --- lifecycle ---------------------------------------------------------------------------------------
    def start(self) -> QuadNode:
        self.link.start()
        self._thread = threading.Thread(target=self._loop, name="quadnode-tick", daemon=True)
        self._thread.start()
        return self

    def close(self) -> None:
        """Stop ticking and streaming and close the link (the autopilot's GUID_TIMEOUT takes over)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        self.link.close()

    def __enter__(self) -> QuadNode:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- QAPI (Sec. V) -----------------------------------------------------------------------------------
    def add_command(self, command: FlightCommand) -> int:
        """Append one command; its id (unique for the life of the process)."""
        return self.queue.add_command(command)

    def add_commands(self, commands: Iterable[FlightCommand]) -> list[int]:
        """Append commands atomically (all checked first; all or none); their ids."""
        return self.queue.add_commands(list(commands))

    def retarget(self, command_id: int, change: Retarget) -> FlightCommand:
        """Change the running command's target in flight (seed 000 Sec. IV-D)."""
        return self.queue.retarget(command_id, change)

    def run(self) -> None:
        self.queue.run()

    def stop(self) -> None:
        self.queue.stop()

    def pause_direct(self, routine_id: str | None = None) -> None:
        self.queue.pause_direct(routine_id)

    def pause_after_current(self, routine_id: str | None = None) -> None:
        self.queue.pause_after_current(routine_id)

    def reset(self) -> None:
        self.queue.reset()

    def user_confirm(self) -> None:
        self.queue.user_confirm()

    def push_external(self, stream: str, values: Sequence[float], validity_s: float) -> bool:
        """An external-data sample (Sec. IV-C), stamped now on the queue's clock."""
        return self.queue.push_external(stream, values, validity_s)

    def offer_external(self, stream: str, values: Sequence[float], validity_s: float, *, age_s: float = 0.0,
                       seq: int | None = None, sender: str | None = None) -> str | None:
        """An external-data sample made ``age_s`` ago (Sec. IV-C): None when taken, else why it was
        dropped (stale on arrival, out of order)."""
        return self.queue.offer_external(stream, values, validity_s, age_s=age_s, seq=seq, sender=sender)

    def vehicle_status(self) -> VehicleStatus:
        """The vehicle as the upper layers see it (a frozen snapshot; see :class:`VehicleStatus`)."""
        return VehicleStatus.of(self.link.mirror.snapshot(), self.clock.now(),
                                self.supervisor.phase is Phase.OVERRIDDEN, self.link.connected)

    def vehicle_state(self) -> VehicleState | None:
        """``vehicle_status().state`` without the rest of the status (for 20 Hz readers)."""
        return with_ground(self.link.mirror.snapshot(), self.clock.now())

    def qapi_status(self) -> QueueStatus:
        return self.queue.status()

    def param_client(self) -> AutopilotParams:
        """A new client of the autopilot's parameters over this node's link (read; set with read-back)."""
        return AutopilotParams(self.link)

    def fence_client(self) -> AutopilotFence:
        """A new client of the autopilot's polygon fence over this node's link (upload, enable)."""
        return AutopilotFence(self.link)

    def status(self) -> dict[str, Any]:
        """QAPI status plus what the node, the link and the vehicle are doing."""
        sp = self.last_setpoint
        return {
            "queue": self.queue.status().to_dict(),
            "commands": len(self.queue.commands),
            "routine_id": self.queue.routine_id,
            "flight": self.supervisor.status(),
            "link": self.link.status(),
            "vehicle": self.link.mirror.snapshot().to_dict(),
            "node": {"rate_hz": self.rate_hz, "ticks": self.ticks, "streamed": self.streamed,
                     "resyncs": self.resyncs, "queue_time_s": round(self.queue_time.now(), 3),
                     "last_setpoint": sp.to_dict() if sp is not None else None},
        }

    # --- the tick thread ----------------------------------------------------------------------------------
    def _loop(self) -> None:
        next_t: float | None = None
        while not self._stop.is_set():
            now = self.clock.now()
            try:
                self.link.periodic(now)
            except OSError as exc:
                log.warning("send failed: %s", exc)
            if not self.clock.synced:
                self._stop.wait(0.05)
                continue
            if next_t is None or now - next_t > 3 * self.period_s:
                if next_t is not None:
                    self.resyncs += 1
                next_t = now
            if now < next_t:
                self._stop.wait(min(self.clock.wall_until(next_t), 0.05))
                continue
            try:
                self._tick(next_t)
            except OSError as exc:
                log.warning("send failed: %s", exc)
            except Exception:
                log.exception("tick failed")
            next_t += self.period_s

    def _feed_rc(self, s: MirrorState) -> None:
        """A new RC_CHANNELS report becomes an ``rc_vel`` sample (RC_VEL modes; :mod:`companion.link.rc`)."""
        rc = s.rc
        if rc is None or rc.time_boot_ms == self._rc_seen_ms:
            return
        self._rc_seen_ms = rc.time_boot_ms
        sample = rc_velocity(rc.channels, s.yaw, self.queue.limits, self.rc_mapping, rc.rssi)
        if sample is not None:
            self.queue.push_external("rc_vel", sample, self.rc_mapping.validity_s)

    def _tick(self, t_ap: float) -> None:
        """One tick at autopilot time ``t_ap``."""
        self.ticks += 1
        sup, queue = self.supervisor, self.queue
        s = self.link.mirror.snapshot()
        sup.observe(s)
        if sup.overridden != (queue.status().queue_system_status.name == "OVERRIDDEN"):
            queue.set_overridden(sup.overridden)
        if sup.abandoned is not None:
            reason, sup.abandoned = sup.abandoned, None
            queue.fail_current(reason)
            self.queue_time.release(t_ap)
        if sup.holds_queue:
            airborne = sup.step_takeoff(queue.executing_take_off(), s, t_ap)
            if airborne and not queue.mark_takeoff_airborne(s.vehicle_state()):
                sup.takeoff_abandoned_in_the_air()  # stopped at the very moment of lift-off
                airborne = False
            if not airborne:
                if not sup.holds_queue:  # cancelled: the queue's time runs again
                    self.queue_time.release(t_ap)
                return
            self.queue_time.release(t_ap)  # airborne: the queue runs on from where it was held
        self._feed_rc(s)
        vs = with_ground(s, t_ap)
        if self.last_setpoint is None and vs is None:
            return
        # not streaming: an idle reference stays on the vehicle, so the next command starts from it
        follow = sup.phase in (Phase.IDLE, Phase.CANCELLING)
        sp = queue.tick(self.queue_time.of(t_ap), vs, follow_vehicle=follow)
        if sp is None:
            queue.set_synced(False)
            return
        self.last_setpoint = sp
        send = sup.step(sp, s, t_ap)
        if sup.holds_queue:
            self.queue_time.hold(t_ap)
        if send:
            fields = self.link.send_setpoint(sp, t_ap)
            self.streamed += 1
            for fn in self.setpoint_listeners:
                fn(sp, fields, t_ap)
        queue.set_synced(send and self.link.sync.synced(t_ap))
