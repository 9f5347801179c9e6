"""Request and answer models the companion's control surface and the ground service share.

The ground service proxies the Process Monitor's parameter tuning (seed 003 Sec. II, "inflight gain
tuning for low-level controllers") to a vehicle's companion with the companion's own contract; both import
it from here (the ground service imports no module of the companion's HTTP surface).
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field


class ParamSet(BaseModel):
    """``PUT /params/{name}``: the value to set."""

    model_config = ConfigDict(extra="forbid")

    value: float = Field(..., allow_inf_nan=False)


class ParamAnswer(BaseModel):
    """An autopilot parameter as the autopilot answered (the read-back after a set)."""

    name: str
    value: float
    type: int


class FenceSet(BaseModel):
    """``POST /fence``: the autopilot's inclusion polygon, ``[[lat, lon], ...]``, and whether to enable it."""

    model_config = ConfigDict(extra="forbid")

    points: list[list[float]] = Field(..., min_length=3, max_length=100,
                                      description="the polygon's vertices [[lat, lon], ...] in order")
    enable: bool = Field(True, description="set FENCE_TYPE's polygon bit and FENCE_ENABLE 1")


class FenceAnswer(BaseModel):
    """What the autopilot holds after the upload (FENCE_TYPE's read-back when enabled)."""

    vertices: int
    enabled: bool
    fence_type: int | None = None
