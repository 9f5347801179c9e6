"""external-velocity (seed 000 Sec. VI-F): fly with velocities (and yaw rate) from an external source.

All channels ExtVel, ended by E_User; Sec. VI-F lists no parameter, ``source`` (the external feed,
default ``joystick``) is ours. The executor asks for FOLLOW_EXTERNAL_VELOCITY. Fig. 4 (ours, VI-F is
silent): it "has no inherent end, the finish condition has to be provided by the user" (E_User) = enough;
it is itself the break-in, so no pause.
"""

from __future__ import annotations

from companion.tst.executor import TstExecutor
from companion.tst.leaves.base import LeafType
from companion.tst.param_spec import ParamSpec
from companion.tst.status import NodeExecutionInfo


class ExternalVelocityExecutor(TstExecutor):
    def activation(self) -> str:
        return "FOLLOW_EXTERNAL_VELOCITY"


class ExternalVelocity(LeafType):
    name = "external-velocity"
    figure = "Sec. VI-F"
    doc = "Fly with velocities (and yaw rate) from an external source; all channels ExtVel, ended by E_User."
    params = (ParamSpec("source", "string",
                        "The external velocity feed (ours; the paper lists no parameter).",
                        default="joystick"),)
    info = NodeExecutionInfo(can_be_aborted=True, can_be_paused=False, can_be_enoughed=True)
    executor = ExternalVelocityExecutor


EXTERNAL_VELOCITY = ExternalVelocity()
