"""Which vehicles the operator is asked to confirm: a command waiting on E_User (QAPI
confirmation_required_status) that someone asked for, not an idle vehicle's default hover
(companion.behaviors.system.ExecutiveLayer.awaits_operator, read by
groundstation.fleet.waits_for_operator)."""

from __future__ import annotations

from groundstation.fleet import waits_for_operator
from harness.behaviors import World


def test_an_idle_vehicles_default_hover_asks_nothing() -> None:
    w = World()
    w.take_off()
    w.run_until(lambda: w.active().get("KEEP_HOVERING") == "default", 2.0, "the default hover")
    assert w.queue.status().confirmation_required_status  # the hold ends on E_User ...
    assert not w.layer.awaits_operator()  # ... but nobody asked the operator anything


def test_a_real_wait_is_shown() -> None:
    w = World()
    w.take_off()
    assert w.activate("KEEP_HOVERING", "operator").accepted  # the operator asked it to hold: confirm ends it
    w.run(0.5)
    assert w.layer.awaits_operator()
    assert w.activate("GO_TO_POINT coordinate: (10, 0, 5)", "operator").accepted
    w.run(0.5)
    assert not w.layer.awaits_operator()  # flying to a point waits for nobody


def test_the_ground_service_reads_the_companions_answer() -> None:
    assert not waits_for_operator({"queue": {"confirmation_required_status": True}, "awaits_operator": False})
    assert waits_for_operator({"queue": {"confirmation_required_status": True}, "awaits_operator": True})
    # a companion without the executive layer (commands alone): the QAPI flag
    assert waits_for_operator({"queue": {"confirmation_required_status": True}, "awaits_operator": None})
    assert not waits_for_operator({"queue": {"confirmation_required_status": False}})
    assert not waits_for_operator(None)
    assert not waits_for_operator({})
