"""One companion flying one autopilot over loopback UDP, for the conformance tests (no tests here).

:class:`FlightSession` starts an autopilot (the model or ArduCopter SITL, :mod:`autopilot_support`),
a :class:`~companion.node.QuadNode` connected through the wire tap, and its HTTP control surface. It
records what the companion hears (heartbeats, positions) and offers the waits the tests share, in
wall time derived from simulated durations, plus :meth:`ensure_airborne` / :meth:`ensure_on_ground`
so that each test can also run alone. :class:`SessionSpec` is how a test module asks for its session
(the ``flight_session`` fixture of ``tests/conftest.py`` reads the module's ``FLIGHT_SESSION``).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx

from companion.builder import CompanionConfig, build_companion
from companion.flight import Envelope, EventKind, Setpoint
from companion.flight import command_from_dict as cmd
from companion.safety import SafetyConfig
from companion.tst.platform import bundled_platform
from harness.autopilot import AUTOPILOTS, Autopilot, start_autopilot
from harness.observer import GUIDED
from harness.timing import wait_for
from harness.timing import wall as _wall

TAKEOFF = {"vertical": {"mode": "POS", "altitude": 5, "take_off": True}, "end": {"e_v": True}}
LAND_HERE = {"vertical": {"mode": "POS", "altitude": 0.0, "allow_landing": True}, "end": {"e_v": True}}


class FlightSession:
    """Everything one autopilot's conformance tests share (see module docstring)."""

    def __init__(self, kind: str, state_dir: Path, speedup: float, *, behaviors: bool = False,
                 envelope: Envelope | None = None, missions: bool = False, scenario: Any = None,
                 safety: SafetyConfig | None = None) -> None:
        self.speedup = speedup
        self.ap: Autopilot = start_autopilot(kind, state_dir, speedup)
        self.kind = kind
        self.tap, self.gcs = self.ap.tap, self.ap.gcs
        self.companion = build_companion(CompanionConfig(
            self.ap.companion_url, rate_hz=20.0, envelope=envelope, behaviors=behaviors or missions,
            behavior_log=state_dir / "behaviors.jsonl" if behaviors or missions else None, scenario=scenario,
            missions=missions, platform=bundled_platform("indoor"), control_port=0,
            **({"safety": safety} if safety is not None else {})))
        self.node = self.companion.node
        self.layer = self.companion.layer
        self.missions = self.companion.missions
        self.streamed: list[Setpoint] = []
        self.synced_ticks: list[bool] = []
        self.heard: list[tuple[float, bool, float]] = []  # (autopilot s, armed, altitude) per heartbeat
        self._lock = threading.Lock()
        self.node.setpoint_listeners.append(self._on_setpoint)
        self.node.link.listeners.append(self._on_message)
        self.companion.start()
        assert self.companion.server is not None
        self.server = self.companion.server
        self.http = httpx.Client(base_url=self.server.url, timeout=10.0)
        try:
            wait_for(lambda: self.node.link.mirror.snapshot().position is not None, self.wall(60),
                     f"{kind}: LOCAL_POSITION_NED (the EKF origin)")
        except AssertionError as exc:
            why = f"{exc}; {self.ap.describe()}; link {self.node.link.status()}"
            self.close()
            raise AssertionError(why) from None

    # --- recording ---------------------------------------------------------------------------------------
    def _on_setpoint(self, sp: Setpoint, fields: Any, t: float) -> None:
        self.streamed.append(sp)

    def _on_message(self, msg: Any) -> None:
        if msg.get_type() == "HEARTBEAT":
            s = self.node.link.mirror.snapshot()
            alt = -s.position[2] if s.position is not None else 0.0
            with self._lock:
                self.heard.append((self.node.clock.now(), s.armed, alt))

    def heard_since(self, t: float) -> list[tuple[float, bool, float]]:
        with self._lock:
            return [h for h in self.heard if h[0] >= t]

    # --- helpers -----------------------------------------------------------------------------------------
    def wall(self, sim_s: float) -> float:
        return _wall(sim_s, self.speedup)

    def post(self, path: str, body: Any = None) -> httpx.Response:
        return self.http.post(path, json=body) if body is not None else self.http.post(path)

    # --- the executive layer over the control surface ----------------------------------------------------
    def activate(self, text: str, requester: str = "mission") -> dict[str, Any]:
        """``POST /behaviors/activate`` answered 200 (accepted): its answer."""
        r = self.post("/behaviors/activate", {"text": text, "requester": requester})
        assert r.status_code == 200, r.text
        return dict(r.json())

    def ended(self, activation_id: str) -> dict[str, Any] | None:
        """The end of an activation (``GET /behaviors``' ``ended``), None while it runs."""
        ends = self.http.get("/behaviors").json()["ended"]
        return next((e for e in ends if e["activation_id"] == activation_id), None)

    def wait_end(self, activation_id: str, sim_s: float) -> dict[str, Any]:
        """The end of an activation, waited for ``sim_s`` simulated seconds."""
        wait_for(lambda: self.ended(activation_id) is not None, self.wall(sim_s),
                 lambda: f"end of {activation_id} (active: "
                         f"{[a['behavior'] for a in self.http.get('/behaviors').json()['active']]})")
        end = self.ended(activation_id)
        assert end is not None
        return end

    def status(self) -> dict[str, Any]:
        return self.node.queue.status().to_dict()

    def pos(self) -> tuple[float, float, float]:
        p = self.node.link.mirror.snapshot().position
        assert p is not None
        return p

    def alt(self) -> float:
        return -self.pos()[2]

    def speed(self) -> float:
        return math.hypot(*self.node.link.mirror.snapshot().velocity)

    def armed(self) -> bool:
        return self.node.link.mirror.snapshot().armed

    def phase(self) -> str:
        return self.node.supervisor.phase.value

    def sim_time(self) -> float:
        return self.node.clock.now()

    def sim_wait(self, sim_s: float) -> None:
        t = self.sim_time() + sim_s
        wait_for(lambda: self.sim_time() >= t, self.wall(sim_s), f"{sim_s} s of autopilot time", 0.002)

    def add(self, *commands: dict[str, Any]) -> list[int]:
        return self.node.add_commands([cmd(c) for c in commands])

    def wait_finished(self, command_id: int, sim_s: float) -> None:
        event = self.node.queue.events.wait_for(command_id, {EventKind.FINISHED, EventKind.FAILED,
                                                             EventKind.CANCELLED}, self.wall(sim_s))
        assert event is not None, f"command {command_id} did not finish (status {self.status()})"
        assert event.kind is EventKind.FINISHED, f"command {command_id}: {event}"

    def wait_index(self, index: int, sim_s: float) -> None:
        wait_for(lambda: self.status()["current_command_index"] >= index, self.wall(sim_s),
                 f"command index {index} (status {self.status()})")

    def wait_near(self, target: tuple[float, float, float], tol: float, sim_s: float) -> None:
        wait_for(lambda: math.dist(self.pos(), target) < tol, self.wall(sim_s),
                 f"vehicle within {tol} m of {target} (at {self.pos()})")

    def wait_still(self, sim_s: float, below: float = 0.3) -> None:
        wait_for(lambda: self.speed() < below, self.wall(sim_s),
                 f"vehicle at rest (speed {self.speed():.2f})")

    # --- preconditions, so that each test also runs alone --------------------------------------------------
    def ensure_airborne(self) -> None:
        """Flying in GUIDED, engaged, the queue running with nothing left to do."""
        if self.status()["queue_system_status"] == "OVERRIDDEN":
            assert self.gcs.set_mode(GUIDED) == 0
            wait_for(lambda: self.status()["queue_system_status"] == "RUNNING", self.wall(3), "given back")
        if self.phase() == "ENGAGED" and self.alt() > 1.0:
            self.node.reset()
            self.node.run()
            return
        self.node.reset()
        (cid,) = self.add(TAKEOFF if not self.armed() or self.alt() < 1.0 else {"end": {"e_wait": 0.5}})
        self.node.run()
        self.wait_finished(cid, 60)
        wait_for(lambda: self.phase() == "ENGAGED", self.wall(5), "engaged")

    def ensure_on_ground(self) -> None:
        """Landed and disarmed, the queue reset."""
        if not self.armed():
            self.node.reset()
            return
        self.ensure_airborne()
        self.add(LAND_HERE)
        wait_for(lambda: not self.armed(), self.wall(60), "landed and disarmed")
        wait_for(lambda: self.phase() == "IDLE", self.wall(3), "link idle after landing")
        self.node.reset()

    def close(self) -> None:
        self.http.close()
        self.companion.close()
        self.ap.close()


@dataclass(frozen=True)
class SessionSpec:
    """A test module's flight session: its state directory's prefix, the models' speedup, the autopilots it
    is flown on (each a module-scoped session; none: the model only, not parametrised), whether the
    executive layer must have localized first (home known, SELF_LOCALIZE active: the motion behaviors
    need it), and :class:`FlightSession`'s options."""

    name: str
    speedup: float
    autopilots: Sequence[Any] = tuple(AUTOPILOTS)
    localized: bool = False
    behaviors: bool = False
    envelope: Envelope | None = None
    missions: bool = False
    scenario: Any = None
    #: the safety monitor's configuration (None: the companion's default, on)
    safety: SafetyConfig | None = None

    @contextmanager
    def open(self, kind: str, state_dir: Path) -> Iterator[FlightSession]:
        """A session on autopilot ``kind``, closed after."""
        session = FlightSession(kind, state_dir, self.speedup, behaviors=self.behaviors,
                                envelope=self.envelope, missions=self.missions, scenario=self.scenario,
                                safety=self.safety)
        try:
            if self.localized:
                wait_for(lambda: session.node.link.mirror.snapshot().home is not None, session.wall(30),
                         "home")
                layer = session.layer
                assert layer is not None  # a healthy estimate: the motion behaviors need SELF_LOCALIZE
                wait_for(lambda: layer.coordinator.is_active("SELF_LOCALIZE"), session.wall(60), "localized")
            yield session
        finally:
            session.close()
