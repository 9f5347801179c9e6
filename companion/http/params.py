"""The Process Monitor's in-flight tuning (seed 003 Sec. II: "inflight gain tuning for low-level
controllers") and the executive layer's processes (seed 001's process manager).

========================================  ============================================================
``GET  /params/{name}``                   an autopilot parameter, read over the companion's MAVLink link,
                                          with its range from the autopilot's table (``min``, ``max``,
                                          ``units``; null when the table does not list it)
``PUT  /params/{name}``                   ``{"value": 0.15, "force": false}``: set it; the answer is the
                                          autopilot's read-back with ``old``, the value read first (400
                                          naming the field for a name outside the table, a value out of
                                          range or more than 50 % of a change while armed without
                                          ``force``; 409 if it kept another value, 504 if no answer)
``GET  /processes``                       the executive layer's processes, when it is served
========================================  ============================================================

Parameter writes are the operator's only (:data:`companion.http.auth.OPERATOR_ONLY`), so is ``force``.
The guard is :mod:`mission_specs.param_table`, applied in the link (:mod:`companion.link.params`).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from fastapi import APIRouter

from companion.api_models import ParamAnswer, ParamSet
from companion.behaviors.processes import ProcessManager
from companion.node import AutopilotParams, ParamError
from taskflight_common.httpapi import ApiError

log = logging.getLogger(__name__)


def router(params: AutopilotParams, processes: ProcessManager | None = None) -> APIRouter:
    """``/params/{name}`` (and ``/processes`` with the executive layer's process manager)."""
    app = APIRouter(tags=["parameters"])

    def answer(fn: Callable[..., Any], *args: Any) -> ParamAnswer:
        try:
            v = fn(*args)
            spec = params.spec(v.name)
            autopilot = params.table().autopilot
        except ValueError as exc:
            raise ApiError(400, str(exc)) from None
        except ParamError as exc:
            status = 409 if "kept" in str(exc) else 504
            raise ApiError(status, str(exc)) from None
        out = ParamAnswer(name=v.name, value=v.value, type=v.param_type, old=v.old)
        if spec is not None:
            out = out.model_copy(update={"min": spec.min, "max": spec.max, "units": spec.units,
                                         "description": spec.description, "autopilot": autopilot})
        return out

    @app.get("/params/{name}", response_model=ParamAnswer)
    def get_param(name: str) -> ParamAnswer:
        return answer(params.get, name)

    @app.put("/params/{name}", response_model=ParamAnswer)
    def put_param(name: str, body: ParamSet) -> ParamAnswer:
        got = answer(params.set, name, body.value, body.force)
        log.info("parameter %s: %s -> %s%s", name, got.old, got.value, " (forced)" if body.force else "")
        return got

    if processes is not None:
        @app.get("/processes")
        def get_processes() -> list[dict[str, Any]]:
            return processes.status()

    return app
