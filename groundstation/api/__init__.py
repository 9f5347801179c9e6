"""The ground service's routers, one per resource (FastAPI full-stack template layout)."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from typing import Any

from fastapi import Request

from groundstation.auth import Principal
from groundstation.companions import ApiError
from groundstation.service import GroundService


def service_of(request: Request) -> GroundService:
    return request.app.state.service


def principal_of(request: Request) -> Principal:
    who = request.scope.get("state", {}).get("principal")
    if who is None:  # the Access middleware always sets it on /api; defensive
        raise ApiError(401, "authentication required")
    return who


def audited(request: Request, action: str, target: str, body: Any, fn: Any) -> Any:
    """Run an operator command and write it to the audit log with its answer (or its refusal)."""
    svc, who = service_of(request), principal_of(request)
    try:
        answer = fn()
    except ApiError as exc:
        svc.audit(who, action, target, body, exc.status, exc.body())
        raise
    except Exception as exc:
        svc.audit(who, action, target, body, 500, {"error": type(exc).__name__})
        raise
    status = answer.get("status", 200) if isinstance(answer, dict) and "command" in answer else 200
    svc.audit(who, action, target, body, status, answer)
    return answer


def each_vehicle(request: Request, action: str, targets: list[int], one: Any) -> list[dict[str, Any]]:
    """``one(vid)`` -> a CommandAnswer record for every target at once, each audited."""
    svc, who = service_of(request), principal_of(request)

    def run(vid: int) -> dict[str, Any]:
        try:
            out = one(vid)
        except ApiError as exc:
            out = {"vehicle": vid, "command": action, "ok": False, "status": exc.status, "answer": None,
                   "error": exc.message}
        svc.audit(who, action, f"vehicle {vid}", {"vehicles": targets}, out["status"], out)
        return out

    with ThreadPoolExecutor(max_workers=min(16, len(targets))) as pool:
        return list(pool.map(run, targets))
