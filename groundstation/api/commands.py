"""``/api/commands``: one command to several vehicles, answered per vehicle."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from typing import Any

from fastapi import APIRouter, Request

from groundstation.companions import ApiError
from groundstation.schemas import MultiCommand, MultiCommandAnswer

from . import principal_of, service_of

router = APIRouter(tags=["commands"])


@router.post("/commands", response_model=MultiCommandAnswer)
def command_many(request: Request, body: MultiCommand) -> Any:
    """Every target named in the request; each answers on its own (one unreachable does not stop the
    others). Each vehicle's command is audited."""
    svc, who = service_of(request), principal_of(request)
    targets = list(dict.fromkeys(body.vehicles))

    def one(vid: int) -> dict[str, Any]:
        try:
            out = svc.command(vid, body.command)
        except ApiError as exc:
            out = {"vehicle": vid, "command": body.command, "ok": False, "status": exc.status, "answer": None,
                   "error": exc.message}
        svc.audit(who, body.command, f"vehicle {vid}", {"vehicles": targets}, out["status"], out)
        return out

    with ThreadPoolExecutor(max_workers=min(8, len(targets))) as pool:
        results = list(pool.map(one, targets))
    return {"results": results}
