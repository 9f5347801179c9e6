"""external-velocity (seed 000 Sec. VI-F): fly with velocities (and yaw rate) from an external source.

All channels ExtVel, ended by E_User; Sec. VI-F lists no parameter, ``source`` (the external feed,
default ``joystick``) is ours: one of :data:`companion.flight.external.SOURCES` (``joystick``: the operator's
stick, ``POST /behaviors/joystick``; ``external``: a program's stream, ``POST /external/ext_vel``). The
executor asks for FOLLOW_EXTERNAL_VELOCITY with that source; while it flies, samples from any other source
are ignored. An unknown source is refused at check, naming the node. Fig. 4 (ours, VI-F is silent): it
"has no inherent end, the finish condition has to be provided by the user" (E_User) = enough; it is
itself the break-in, so no pause.
"""

from __future__ import annotations

from companion.behaviors.activation import format_activation
from companion.flight.external import SOURCES
from companion.tst.executor import TstExecutor
from companion.tst.leaves.base import LeafType
from companion.tst.leaves.common import where
from companion.tst.param_spec import ParamSpec
from companion.tst.platform import Platform
from companion.tst.status import NodeExecutionInfo
from companion.tst.tree import TstNode

DEFAULT_SOURCE = "joystick"


class ExternalVelocityExecutor(TstExecutor):
    def activation(self) -> str:
        return format_activation("FOLLOW_EXTERNAL_VELOCITY",
                                 {"source": str(self.node.params.get("source") or DEFAULT_SOURCE)})


class ExternalVelocity(LeafType):
    name = "external-velocity"
    figure = "Sec. VI-F"
    doc = "Fly with velocities (and yaw rate) from an external source; all channels ExtVel, ended by E_User."
    params = (ParamSpec("source", "string",
                        "The external velocity feed (ours; the paper lists no parameter): "
                        + ", ".join(f"{k} ({v})" for k, v in SOURCES.items()) + ".",
                        default=DEFAULT_SOURCE),)
    info = NodeExecutionInfo(can_be_aborted=True, can_be_paused=False, can_be_enoughed=True)
    executor = ExternalVelocityExecutor

    def check(self, node: TstNode, platform: Platform) -> list[str]:
        out = super().check(node, platform)
        source = node.params.get("source", DEFAULT_SOURCE)
        if source not in SOURCES:
            out.append(f"{where(node)}: bad parameters: source {source!r} is not a velocity source "
                       f"(known: {', '.join(SOURCES)})")
        return out


EXTERNAL_VELOCITY = ExternalVelocity()
