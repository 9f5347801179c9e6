"""Control nodes' Fig. 5 status derived from their children (companion/tst/composite.py)."""

from __future__ import annotations

import itertools

import pytest

from companion.tst.composite import derived_status
from companion.tst.status import ExecutorLifecycle, NodeExecutionStatus, execution_info


def leaf_statuses() -> dict[str, NodeExecutionStatus]:
    """One status of each reachable leaf state, produced by a real lifecycle."""
    out: dict[str, NodeExecutionStatus] = {"idle": NodeExecutionStatus()}
    lc = ExecutorLifecycle(execution_info("scan-ground"))
    out["prepared"] = lc.prepare()
    out["waiting"] = lc.start(wait_conditions_met=False)
    out["executing"] = lc.conditions_met()
    out["paused"] = lc.pause_requested()
    out["succeeded"] = lc.enough_requested()
    out["aborted"] = _aborted()
    out["failed"] = ExecutorLifecycle(execution_info("land")).prepare(ready=False, reason="no GPS")
    return out


def _aborted() -> NodeExecutionStatus:
    lc = ExecutorLifecycle(execution_info("fly-to"))
    lc.prepare()
    lc.start()
    return lc.abort("operator")


LEAF = leaf_statuses()


@pytest.mark.parametrize("node_type", ["S", "C", "IF"])
def test_every_combination_of_three_children_is_consistent(node_type: str) -> None:
    for combo in itertools.product(LEAF.values(), repeat=3 if node_type != "IF" else 1):
        s = derived_status(node_type, combo)
        assert s.violations() == [], (node_type, [c.state for c in combo], s)


def test_sequence_walks_through_its_children() -> None:
    L = LEAF
    assert derived_status("S", [L["idle"], L["idle"]]).state == "idle"
    assert derived_status("S", [L["executing"], L["idle"]]).state == "executing"
    assert derived_status("S", [L["paused"], L["idle"]]).state == "paused"
    assert derived_status("S", [L["succeeded"], L["idle"]]).state == "executing"  # between two children
    assert derived_status("S", [L["succeeded"], L["waiting"]]).state == "waiting"
    assert derived_status("S", [L["succeeded"], L["succeeded"]]).state == "succeeded"
    s = derived_status("S", [L["succeeded"], L["aborted"], L["idle"]])
    assert s.state == "aborted" and s.fail_reason == "child 1: aborted: operator"
    assert derived_status("S", [L["failed"], L["idle"]]).fail_reason == "child 0: no GPS"


def test_concurrent_finishes_when_all_children_do() -> None:
    L = LEAF
    assert derived_status("C", [L["succeeded"], L["executing"]]).state == "executing"
    assert derived_status("C", [L["paused"], L["executing"]]).state == "executing"
    assert derived_status("C", [L["paused"], L["paused"]]).state == "paused"
    assert derived_status("C", [L["aborted"], L["executing"]]).state == "executing"
    assert derived_status("C", [L["failed"], L["aborted"]]).state == "aborted"
    assert derived_status("C", [L["failed"], L["succeeded"]]).state == "failed"
    assert derived_status("C", [L["succeeded"], L["succeeded"]]).state == "succeeded"


def test_while_has_no_derived_status() -> None:
    with pytest.raises(ValueError, match="only S, C and IF"):
        derived_status("WHILE", [LEAF["executing"]])
