"""The operator's fence, held by the autopilot (seed 003 Sec. II; the MAVLink geofence service).

========================================  ============================================================
``POST /fence``                           ``{"points": [[lat, lon], ...], "enable": true}``: the
                                          autopilot's polygon fence replaced through the mission protocol
                                          (MAV_MISSION_TYPE_FENCE, as ArduCopter stores it) and enabled;
                                          400 bad points, 409 refused by the autopilot, 504 no answer
========================================  ============================================================
"""

from __future__ import annotations

from fastapi import APIRouter

from companion.api_models import FenceAnswer, FenceSet
from companion.node import AutopilotFence, FenceError
from taskflight_common.httpapi import ApiError


def router(fence: AutopilotFence) -> APIRouter:
    """``POST /fence`` over ``fence`` (the node's :meth:`~companion.node.QuadNode.fence_client`)."""
    app = APIRouter(tags=["fence"])

    @app.post("/fence", response_model=FenceAnswer)
    def post_fence(body: FenceSet) -> FenceAnswer:
        """Replace the autopilot's fence with the polygon (the mission protocol, type FENCE), then enable it
        (FENCE_TYPE's polygon bit, FENCE_ENABLE 1) when ``enable``; the answer is the autopilot's."""
        try:
            up = fence.upload(body.points, body.enable)
        except ValueError as exc:
            raise ApiError(400, str(exc)) from None
        except FenceError as exc:
            raise ApiError(504 if "no answer" in str(exc) else 409, str(exc)) from None
        return FenceAnswer(vertices=up.vertices, enabled=up.enabled, fence_type=up.fence_type)

    return app
