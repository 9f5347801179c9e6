"""request-operator-assistance (ours, for the behaviors layer): ask the operator and wait for the answer.

Not in seed 000: the executor asks for the REQUEST_OPERATOR_ASSISTANCE behavior with the node's
``message``. Fig. 4 (ours): the operator's answer is an enough; it may be aborted, not paused.
"""

from __future__ import annotations

from companion.behaviors.activation import format_activation
from companion.tst.executor import TstExecutor
from companion.tst.leaves.base import LeafType
from companion.tst.param_spec import ParamSpec
from companion.tst.status import NodeExecutionInfo


class OperatorAssistanceExecutor(TstExecutor):
    def activation(self) -> str:
        return format_activation("REQUEST_OPERATOR_ASSISTANCE",
                                 {"message": str(self.node.params.get("message", ""))})


class RequestOperatorAssistance(LeafType):
    name = "request-operator-assistance"
    figure = "ours (behaviors layer)"
    doc = "Ask the operator for assistance (REQUEST_OPERATOR_ASSISTANCE) and wait for the answer."
    params = (ParamSpec("message", "string", "What the operator is asked.", required=True),)
    info = NodeExecutionInfo(can_be_aborted=True, can_be_paused=False, can_be_enoughed=True)
    executor = OperatorAssistanceExecutor


REQUEST_OPERATOR_ASSISTANCE = RequestOperatorAssistance()
