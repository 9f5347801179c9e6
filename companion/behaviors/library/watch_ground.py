"""WATCH_GROUND: the recurrent behavior that keeps the downward camera running (seed 001 Sec. 5.1.2)."""

from __future__ import annotations

from ..controller import BehaviorExecutionController, register


@register
class WatchGround(BehaviorExecutionController):
    """Recurrent and active by default, like seed 001's attention behaviors (PAY_ATTENTION_TO_...):
    its process, the ``camera`` (:class:`companion.sensing.camera.DownwardCamera`), reports what it
    sees below the vehicle as beliefs (``object(7, person)``, ``visible(7)``) for the missions' IF and
    WHILE conditions and the operator. No situation condition (the camera sees nothing on the ground
    anyway) and no end of its own."""

    behavior = "WATCH_GROUND"
