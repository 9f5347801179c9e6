"""external-velocity's ``source`` selects the stream it flies (seed 000 Sec. VI-F; the parameter is ours):
a sample from another source does not move the vehicle; an unknown source is refused at check, naming
the node. The real queue, executive layer and TST executor on the kinematic vehicle."""

from __future__ import annotations

import pytest

from companion.behaviors.catalog import load_catalog
from companion.flight.external import SOURCES, ExternalData, ExternalDataError
from companion.tst.delegation import delegate
from companion.tst.execution import TstExecutionSystem
from companion.tst.plan import NodePlan
from companion.tst.platform import bundled_platform
from companion.tst.spec import mission_from_dict, mission_from_yaml
from harness.behaviors import World


def test_a_stream_tied_to_a_source_ignores_every_other_source() -> None:
    ext = ExternalData()
    assert ext.push("ext_vel", (1.0, 0, 0, 0), 1.0, 0.0, source="external")
    ext.select("ext_vel", "joystick")
    assert ext.latest("ext_vel", 0.1) is None  # stored before the selection, from another source
    assert not ext.push("ext_vel", (2.0, 0, 0, 0), 1.0, 0.2, source="external")
    assert ext.latest("ext_vel", 0.3) is None
    assert ext.push("ext_vel", (3.0, 0, 0, 0), 1.0, 0.4, source="joystick")
    assert ext.latest("ext_vel", 0.5) == (3.0, 0.0, 0.0, 0.0)
    ext.select("ext_vel", None)  # any source again
    assert ext.push("ext_vel", (4.0, 0, 0, 0), 1.0, 0.6)
    with pytest.raises(ExternalDataError, match="unknown source 'radio'"):
        ext.select("ext_vel", "radio")
    with pytest.raises(ExternalDataError, match="unknown source 'radio'"):
        ext.push("ext_vel", (1.0, 0, 0, 0), 1.0, 0.7, source="radio")


def test_the_catalog_offers_the_sources_the_queue_knows() -> None:
    p = load_catalog().get("FOLLOW_EXTERNAL_VELOCITY").parameter("source")
    assert p is not None and set(p.allowed_values or ()) == set(SOURCES) and p.default == "joystick"


def fly_external_velocity(source: str) -> tuple[World, TstExecutionSystem]:
    w = World()
    w.take_off(3.0)
    text = f"mission: m\ntree: {{type: external-velocity, id: stick, params: {{source: {source}}}}}\n"
    ts = TstExecutionSystem(w.layer, mark=lambda *a, **k: None)
    w.layer.cycle_listeners.append(ts.tick)
    ts.load(mission_from_yaml(text, "m.yaml"), {"stick": NodePlan("stick", "external-velocity")})
    ts.start()
    w.run_until(lambda: "FOLLOW_EXTERNAL_VELOCITY" in w.active(), 5.0, "FOLLOW_EXTERNAL_VELOCITY")
    return w, ts


def east_after(w: World, push: object, seconds: float = 3.0) -> float:
    """How far east the vehicle went while ``push`` sent 2 m/s east every 0.1 s."""
    e0 = w.sim.state().p[1]
    for _ in range(round(seconds / 0.1)):
        push()  # type: ignore[operator]
        w.run(0.1)
    return w.sim.state().p[1] - e0


@pytest.mark.parametrize(("source", "other"), [("external", "joystick"), ("joystick", "external")])
def test_only_the_selected_source_moves_the_vehicle(source: str, other: str) -> None:
    w, ts = fly_external_velocity(source)
    sample = (0.0, 2.0, 0.0, 0.0)
    pushes = {"joystick": lambda: w.layer.joystick.push(sample),
              "external": lambda: w.queue.push_external("ext_vel", sample, 0.5)}
    assert east_after(w, pushes[other]) == pytest.approx(0.0, abs=0.01)  # ignored: not moved
    assert pushes[other]() is False
    assert east_after(w, pushes[source]) > 3.0  # flown
    w.queue.user_confirm()
    w.run_until(lambda: not ts.running, 5.0, "the node's end")
    assert w.queue.external_sample("ext_vel") is not None
    # the behavior ended: the stream takes any source again (a later break-in's joystick)
    assert w.queue.push_external("ext_vel", sample, 0.5, source=other)


def test_an_unknown_source_is_refused_at_check_naming_the_node() -> None:
    m = mission_from_dict({"mission": "m", "tree": {"type": "S", "children": [
        {"type": "take-off", "id": "up"},
        {"type": "external-velocity", "id": "stick", "params": {"source": "radio"}}]}})
    d = delegate(m, bundled_platform("indoor"))
    want = "node stick (external-velocity): bad parameters: source 'radio' is not a velocity source"
    assert any(r.startswith(want) for r in d.reasons), d.reasons
