"""The Process Monitor's in-flight tuning (seed 003 Sec. II: "inflight gain tuning for low-level
controllers") and the executive layer's processes (seed 001's process manager).

========================================  ============================================================
``GET  /params/{name}``                   an autopilot parameter, read over the companion's MAVLink link
``PUT  /params/{name}``                   ``{"value": 0.15}``: set it; the answer is the autopilot's
                                          read-back (409 if it kept another value, 504 if no answer)
``GET  /processes``                       the executive layer's processes, when it is served
========================================  ============================================================
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from fastapi import APIRouter

from companion.api_models import ParamAnswer, ParamSet
from companion.behaviors.processes import ProcessManager
from companion.node import AutopilotParams, ParamError
from taskflight_common.httpapi import ApiError


def router(params: AutopilotParams, processes: ProcessManager | None = None) -> APIRouter:
    """``/params/{name}`` (and ``/processes`` with the executive layer's process manager)."""
    app = APIRouter(tags=["parameters"])

    def answer(fn: Callable[..., Any], *args: Any) -> ParamAnswer:
        try:
            v = fn(*args)
        except ValueError as exc:
            raise ApiError(400, str(exc)) from None
        except ParamError as exc:
            status = 409 if "kept" in str(exc) else 504
            raise ApiError(status, str(exc)) from None
        return ParamAnswer(name=v.name, value=v.value, type=v.param_type)

    @app.get("/params/{name}", response_model=ParamAnswer)
    def get_param(name: str) -> ParamAnswer:
        return answer(params.get, name)

    @app.put("/params/{name}", response_model=ParamAnswer)
    def put_param(name: str, body: ParamSet) -> ParamAnswer:
        return answer(params.set, name, body.value)

    if processes is not None:
        @app.get("/processes")
        def get_processes() -> list[dict[str, Any]]:
            return processes.status()

    return app
