"""``/api/mission_files``: the bundled Task Specification Trees (seed 000 Sec. III) and a mission file's
text read into the JSON body ``POST /api/vehicles/{vid}/mission`` takes (the browser reads no YAML).

``GET /api/mission_files``: the bundled missions' names (``taskflight mission list``);
``GET /api/mission_files/{name}``: one of them; ``POST /api/mission_files/parse``
``{"text": "<YAML or JSON>"}``: a mission file chosen in the page. Each answers
``{mission, description, tree}``; a file that is not a mission answers 400 saying why. Delegation
(whether the vehicle can fly it) is the vehicle's: its answer comes back node by node from
``POST /api/vehicles/{vid}/mission`` (422 with ``reasons`` naming the nodes).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import yaml
from fastapi import APIRouter
from fastapi import Path as PathParam
from pydantic import BaseModel, ConfigDict, Field

from groundstation.companions import ApiError
from mission_specs import bundled

router = APIRouter(tags=["missions"])

NAME_RE = re.compile(r"^[A-Za-z0-9_.-]{1,80}\.ya?ml$")


class MissionText(BaseModel):
    model_config = ConfigDict(extra="forbid")
    text: str = Field(..., min_length=1, max_length=200_000, description="a mission file's YAML (or JSON)")


class MissionFile(BaseModel):
    mission: str
    description: str = ""
    tree: dict[str, Any]


class MissionNames(BaseModel):
    missions: list[str]


def _folder() -> Path:
    return bundled("behavior_catalog.yaml").parent


def mission_of(data: Any, where: str) -> dict[str, Any]:
    """``{mission, description, tree}`` of a mission file's data; ApiError 400 naming the field."""
    if not isinstance(data, dict):
        raise ApiError(400, f"{where}: not a mission file (expected a mapping with 'mission' and 'tree')")
    name, tree = data.get("mission"), data.get("tree")
    if not isinstance(name, str) or not name.strip():
        raise ApiError(400, f"{where}: mission: a non-empty name is required")
    if not isinstance(tree, dict):
        raise ApiError(400, f"{where}: tree: a mapping (the Task Specification Tree's root node) is required")
    description = data.get("description", "")
    return {"mission": name[:100], "description": str(description or "")[:1000], "tree": tree}


@router.get("/mission_files", response_model=MissionNames)
def list_missions() -> Any:
    """The bundled missions (the YAML files of ``mission_specs`` with a ``mission`` key)."""
    names = []
    for path in sorted(_folder().glob("*.yaml")):
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
        if isinstance(data, dict) and "mission" in data:
            names.append(path.name)
    return {"missions": names}


@router.get("/mission_files/{name}", response_model=MissionFile)
def get_mission_file(name: str = PathParam(..., description="e.g. scan_and_search_outdoor.yaml")) -> Any:
    """One bundled mission (``taskflight mission list`` names them) as the mission upload's JSON."""
    if not NAME_RE.match(name):
        raise ApiError(400, f"name: {name!r} is not a bundled mission's file name")
    path = _folder() / name
    if not path.is_file():
        raise ApiError(404, f"no bundled mission {name!r} (GET /api/mission_files lists them)")
    return mission_of(yaml.safe_load(path.read_text(encoding="utf-8")), name)


@router.post("/mission_files/parse", response_model=MissionFile)
def parse_mission(body: MissionText) -> Any:
    """A mission file's text (YAML, or JSON, which is YAML) as the mission upload's JSON; changes nothing."""
    try:
        data = yaml.safe_load(body.text)
    except yaml.YAMLError as exc:
        raise ApiError(400, f"text: not YAML: {exc}") from None
    return mission_of(data, "text")
