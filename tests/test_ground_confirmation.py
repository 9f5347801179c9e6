"""Which vehicles the operator is asked to confirm (groundstation.fleet.waits_for_operator): a command
waiting on E_User (QAPI confirmation_required_status), except the default hover of an idle vehicle."""

from __future__ import annotations

from groundstation.fleet import waits_for_operator


def _status(flag: bool, *active: tuple[str, str]) -> dict[str, object]:
    return {"queue": {"confirmation_required_status": flag},
            "behaviors": [{"behavior": b, "requester": r} for b, r in active]}


def test_an_idle_vehicles_default_hover_asks_nothing() -> None:
    assert not waits_for_operator(_status(True, ("KEEP_HOVERING", "default"), ("SELF_LOCALIZE", "default")))


def test_a_real_wait_is_shown() -> None:
    assert waits_for_operator(_status(True, ("REQUEST_OPERATOR_ASSISTANCE", "mission")))
    assert waits_for_operator(_status(True, ("KEEP_HOVERING", "operator")))  # asked to hover: confirm ends it
    assert waits_for_operator(_status(True))  # a companion without the executive layer (commands alone)
    assert waits_for_operator({"queue": {"confirmation_required_status": True}})


def test_nothing_to_confirm() -> None:
    assert not waits_for_operator(_status(False, ("REQUEST_OPERATOR_ASSISTANCE", "mission")))
    assert not waits_for_operator(None)
    assert not waits_for_operator({})
