"""Fig. 4 execution information, Fig. 5 status and the Fig. 3 lifecycle (companion/tst/status.py)."""

from __future__ import annotations

import itertools
from collections.abc import Callable

import pytest

from companion.tst.registry import leaf_type_names
from companion.tst.status import (
    IDLE_CONTROL_INFO,
    ExecutionRequestError,
    ExecutorLifecycle,
    NodeExecutionInfo,
    NodeExecutionStatus,
    control_execution_info,
    execution_info,
)

Action = Callable[[ExecutorLifecycle], object]
ACTIONS: dict[str, Action] = {
    "prepare": lambda lc: lc.prepare(),
    "prepare_not_ready": lambda lc: lc.prepare(ready=False, reason="no position estimate"),
    "start": lambda lc: lc.start(),
    "start_waiting": lambda lc: lc.start(wait_conditions_met=False),
    "conditions_met": lambda lc: lc.conditions_met(),
    "succeed": lambda lc: lc.succeed(),
    "fail": lambda lc: lc.fail("lost the link"),
    "abort": lambda lc: lc.abort(),
    "pause": lambda lc: lc.pause_requested(),
    "continue": lambda lc: lc.continue_requested(),
    "enough": lambda lc: lc.enough_requested(),
}


def expected(state: str, action: str, info: NodeExecutionInfo) -> str | None:
    """The state ``action`` leads to from ``state``, or None when it must be refused (from Fig. 3-5)."""
    running = state in ("executing", "paused")
    table: dict[str, str | None] = {
        "prepare": "prepared" if state == "idle" else None,
        "prepare_not_ready": "failed" if state == "idle" else None,
        "start": "executing" if state == "prepared" else None,
        "start_waiting": "waiting" if state == "prepared" else None,
        "conditions_met": "executing" if state == "waiting" else None,
        "succeed": "succeeded" if state == "executing" else None,
        "fail": "failed" if state in ("prepared", "waiting", "executing", "paused") else None,
        "abort": "aborted" if state in ("prepared", "waiting") or (running and info.can_be_aborted) else None,
        "pause": "paused" if state == "executing" and info.can_be_paused else None,
        "continue": "executing" if state == "paused" else None,
        "enough": "succeeded" if running and info.can_be_enoughed else None,
    }
    return table[action]


def check_invariants(s: NodeExecutionStatus) -> None:
    assert s.violations() == []
    if s.finished:
        assert not s.executing and not s.waiting and not s.paused
    if s.succeeded:
        assert s.finished and not s.aborted and s.fail_reason == ""
    if s.paused:
        assert s.executing and s.active
    if s.aborted:
        assert s.finished and not s.succeeded and s.fail_reason.startswith("aborted")
    if s.waiting or s.executing:
        assert s.active
    if s.finished and not s.succeeded:
        assert s.fail_reason


def explore(info: NodeExecutionInfo, depth: int = 6) -> tuple[set[str], int]:
    """Every request sequence up to ``depth`` from a fresh executor.

    The lifecycle's answer depends only on its status (and the fixed info), so sequences reaching the same
    status with the same remaining length are explored once; this covers all 11**6 sequences exactly.
    Returns the reached states and the number of (status, action) steps checked.
    """
    reached: set[str] = set()
    seen: set[tuple[NodeExecutionStatus, int]] = set()
    steps = 0

    def walk(status: NodeExecutionStatus, left: int) -> None:
        nonlocal steps
        reached.add(status.state)
        if left == 0 or (status, left) in seen:
            return
        seen.add((status, left))
        for name, act in ACTIONS.items():
            lc = ExecutorLifecycle(info, "node")
            lc.status = status
            want = expected(status.state, name, info)
            steps += 1
            if want is None:
                with pytest.raises(ExecutionRequestError):
                    act(lc)
                assert lc.status == status, f"{name} refused in {status.state} but changed the status"
                continue
            act(lc)
            check_invariants(lc.status)
            assert lc.status.state == want, f"{name} from {status.state}: {lc.status.state}, expected {want}"
            walk(lc.status, left - 1)

    walk(NodeExecutionStatus(), depth)
    return reached, steps


@pytest.mark.parametrize("task_type", sorted(leaf_type_names()))
def test_every_request_sequence_up_to_six(task_type: str) -> None:
    info = execution_info(task_type)
    reached, steps = explore(info)
    assert steps > 50
    assert {"idle", "prepared", "waiting", "executing", "succeeded", "aborted", "failed"} <= reached
    assert ("paused" in reached) == info.can_be_paused


@pytest.mark.parametrize("task_type", sorted(leaf_type_names()))
def test_every_literal_request_sequence_after_start(task_type: str) -> None:
    """No memo: each of the 5**k sequences (k <= 6) of the execution system's requests and the executor's
    natural end, replayed from a started executor, keeps a consistent status and refuses exactly as Fig. 4
    and the state say."""
    info = execution_info(task_type)
    names = ("abort", "pause", "continue", "enough", "succeed")
    count = 0
    for k in range(1, 7):
        for seq in itertools.product(names, repeat=k):
            lc = ExecutorLifecycle(info)
            lc.prepare()
            lc.start()
            for name in seq:
                before = lc.status
                want = expected(before.state, name, info)
                try:
                    ACTIONS[name](lc)
                except ExecutionRequestError:
                    assert want is None and lc.status == before
                else:
                    assert lc.status.state == want
                check_invariants(lc.status)
            count += 1
    assert count == sum(5**k for k in range(1, 7))


def test_every_flag_combination_is_explored() -> None:
    """The state machine is right for all 8 Fig. 4 combinations, not only the LinkQuad ones."""
    for bits in range(8):
        info = NodeExecutionInfo(bool(bits & 1), bool(bits & 2), bool(bits & 4))
        reached, _ = explore(info, depth=5)
        assert ("paused" in reached) == info.can_be_paused


def test_linkquad_flags_as_the_paper_sets_them() -> None:
    assert execution_info("take-off") == NodeExecutionInfo(False, False, False)  # VI-A
    assert execution_info("fly-to") == NodeExecutionInfo(True, True, False)  # VI-B
    assert execution_info("scan-ground") == NodeExecutionInfo(True, True, True)  # VI-E
    assert execution_info("external-velocity").can_be_enoughed  # VI-F: E_User, no inherent end
    assert all(isinstance(execution_info(t), NodeExecutionInfo) for t in leaf_type_names())


def test_enough_on_take_off_is_refused_with_the_reason() -> None:
    lc = ExecutorLifecycle(execution_info("take-off"), "n2")
    lc.prepare()
    lc.start()
    before = lc.status
    with pytest.raises(ExecutionRequestError, match="n2: enough refused: can_be_enoughed is false"):
        lc.enough_requested()
    with pytest.raises(ExecutionRequestError, match="abort refused: can_be_aborted is false"):
        lc.abort()
    with pytest.raises(ExecutionRequestError, match="pause refused: can_be_paused is false"):
        lc.pause_requested()
    assert lc.status == before and lc.status.executing


def test_state_refusals_have_reasons() -> None:
    lc = ExecutorLifecycle(execution_info("scan-ground"))
    with pytest.raises(ExecutionRequestError, match="start refused: not prepared"):
        lc.start()
    lc.prepare()
    with pytest.raises(ExecutionRequestError, match="pause refused: not executing"):
        lc.pause_requested()
    lc.start()
    with pytest.raises(ExecutionRequestError, match="continue refused: not paused"):
        lc.continue_requested()
    lc.enough_requested()
    with pytest.raises(ExecutionRequestError, match="abort refused: already finished"):
        lc.abort()


def test_scan_ground_break_in_resume_then_enough_fig_16() -> None:
    """Sec. VII: pause at p5, continue at p6, pause at p9, enough at p10 (while paused)."""
    lc = ExecutorLifecycle(execution_info("scan-ground"), "scan")
    lc.prepare()
    lc.start()
    assert lc.pause_requested().paused
    assert not lc.continue_requested().paused
    lc.pause_requested()
    s = lc.enough_requested()
    assert (s.finished, s.succeeded, s.aborted, s.paused, s.executing) == (True, True, False, False, False)
    assert s.state == "succeeded"


def test_prepare_not_ready_is_a_failure_not_active() -> None:
    lc = ExecutorLifecycle(execution_info("fly-to"))
    s = lc.prepare(ready=False, reason="follow_ground_flag without a range sensor")
    assert not s.active and s.finished and not s.succeeded
    assert s.fail_reason == "follow_ground_flag without a range sensor" and s.state == "failed"


def test_abort_before_execution_even_for_take_off() -> None:
    lc = ExecutorLifecycle(execution_info("take-off"))
    lc.prepare()
    lc.start(wait_conditions_met=False)
    s = lc.abort("operator")
    assert s.aborted and s.finished and s.fail_reason == "aborted: operator"


def test_control_info_from_running_children() -> None:
    fly, scan, take_off = (execution_info(t) for t in ("fly-to", "scan-ground", "take-off"))
    assert control_execution_info([]) == IDLE_CONTROL_INFO
    assert control_execution_info([scan]) == scan  # S: the running child's flags
    assert control_execution_info([scan, fly]) == NodeExecutionInfo(True, True, False)  # C: conjunction
    assert control_execution_info([scan, take_off]) == NodeExecutionInfo(False, False, False)


def test_lifecycle_follows_a_changing_info() -> None:
    running = [execution_info("take-off")]
    lc = ExecutorLifecycle(lambda: control_execution_info(running), "S")
    lc.prepare()
    lc.start()
    with pytest.raises(ExecutionRequestError, match="can_be_enoughed is false"):
        lc.enough_requested()
    running[:] = [execution_info("scan-ground")]
    assert lc.enough_requested().succeeded


def test_status_and_info_to_dict() -> None:
    assert NodeExecutionStatus(active=True).to_dict() == {
        "active": True, "waiting": False, "executing": False, "finished": False, "aborted": False,
        "succeeded": False, "paused": False, "fail_reason": ""}
    assert execution_info("fly-to").to_dict() == {"can_be_aborted": True, "can_be_paused": True,
                                                  "can_be_enoughed": False}
    assert NodeExecutionStatus(paused=True).violations() == ["paused => executing"]
