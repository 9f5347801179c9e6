"""A vehicle world for the executive layer's unit tests (no tests here).

:class:`World` flies a real :class:`~companion.flight.queue.CommandQueue` with the kinematic
:class:`~companion.flight.simulate.FlightSim` (a stand-in for the autopilot, not under test) and
drives a real :class:`~companion.behaviors.system.ExecutiveLayer` on the simulated clock, one
monitor cycle per tick, without threads.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from companion.behaviors.beliefs import BeliefMemory
from companion.behaviors.catalog import BehaviorCatalog, catalog_from_yaml, load_catalog
from companion.behaviors.system import ExecutiveLayer
from companion.behaviors.updaters import BeliefUpdater
from companion.flight import CommandQueue, Envelope, Limits
from companion.flight.simulate import FlightSim


class SimBeliefs(BeliefUpdater):
    """flight_state and localization from the kinematic vehicle."""

    name = "sim"
    period_s = 0.1

    def __init__(self, world: World) -> None:
        self.world = world

    def update(self, memory: BeliefMemory, now_s: float) -> None:
        w = self.world
        if w.sim.landed and not w.queue.executing_take_off():
            state = "landed"
        elif w.queue.executing_take_off():
            state = "taking_off"
        else:
            state = "flying"
        memory.add(f"flight_state(self, {state})")
        memory.add(f"localization(self, {'healthy' if w.localized else 'unhealthy'})")


class World:
    def __init__(self, catalog: BehaviorCatalog | str | None = None, envelope: Envelope | None = None,
                 frozen: bool = False, scenario: Any = None, limits: Limits | None = None) -> None:
        if isinstance(catalog, str):
            catalog = catalog_from_yaml(catalog, "test_catalog.yaml")
        self.queue = CommandQueue(limits or Limits(), envelope)
        self.sim = FlightSim(self.queue, dt=0.05)
        self.localized = True
        self.frozen = frozen  # the vehicle does not follow (measured state stays where it was)
        self._frozen_state = None
        self.layer = ExecutiveLayer(self.queue, lambda: self.sim.t, self.vehicle,
                                    catalog=catalog or load_catalog(), updaters=[SimBeliefs(self)],
                                    scenario=scenario)
        self.coordinator = self.layer.coordinator
        self.beliefs = self.layer.beliefs
        self.cycle()

    def vehicle(self) -> Any:
        if self.frozen:
            if self._frozen_state is None:
                self._frozen_state = self.sim.state()
            return self._frozen_state
        return self.sim.state()

    def cycle(self) -> None:
        """The updaters and the monitor cycle due now (one runner, as in the companion)."""
        self.layer.updaters.run_once(self.sim.t)

    def run(self, seconds: float) -> None:
        for _ in range(round(seconds / self.sim.dt)):
            self.sim.tick()
            self.cycle()

    def run_until(self, predicate: Callable[[], bool], timeout_s: float, what: str = "condition") -> float:
        end = self.sim.t + timeout_s
        while self.sim.t <= end:
            self.sim.tick()
            self.cycle()
            if predicate():
                return self.sim.t
        raise AssertionError(f"{what} not reached within {timeout_s} s (active: {self.active()}, "
                             f"ended: {[e.to_dict() for e in self.coordinator.ended]})")

    def active(self) -> dict[str, str]:
        return {a.behavior: a.requester for a in self.coordinator.active()}

    def ended(self, behavior: str) -> Any:
        return next((e for e in reversed(self.coordinator.ended) if e.behavior == behavior), None)

    def wait_ended(self, behavior: str, timeout_s: float) -> Any:
        n = len([e for e in self.coordinator.ended if e.behavior == behavior])
        self.run_until(lambda: len([e for e in self.coordinator.ended if e.behavior == behavior]) > n,
                       timeout_s, f"end of {behavior}")
        return self.ended(behavior)

    def activate(self, text: str, requester: str = "mission") -> Any:
        return self.coordinator.activate(text, requester)

    def take_off(self, altitude: float = 5.0) -> None:
        r = self.activate(f"TAKE_OFF altitude: {altitude}")
        assert r.accepted, r.reason
        assert self.wait_ended("TAKE_OFF", 30).cause.value == "goal_achieved"
        self.run_until(lambda: "KEEP_HOVERING" in self.active(), 2.0, "KEEP_HOVERING by default")

    @property
    def pos_neu(self) -> tuple[float, float, float]:
        p = self.sim.p
        return (p[0], p[1], -p[2])


def catalog_with(replace: dict[str, str]) -> str:
    """The bundled catalog's text with some lines replaced (e.g. a shorter time-out)."""
    from companion.behaviors.catalog import BUNDLED_CATALOG

    text = BUNDLED_CATALOG.read_text()
    for old, new in replace.items():
        assert old in text, old
        text = text.replace(old, new, 1)
    return text
