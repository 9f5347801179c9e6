"""Request and answer models the companion's control surface and the ground service share.

The ground service proxies the Process Monitor's parameter tuning (seed 003 Sec. II, "inflight gain
tuning for low-level controllers") to a vehicle's companion with the companion's own contract; both import
it from here (the ground service imports no module of the companion's HTTP surface).
"""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field, field_validator

from mission_specs.param_table import ParamWriteError, check_number


class ParamSet(BaseModel):
    """``PUT /params/{name}``: the value to set; ``force``: the operator's override of the in-flight
    bound (a change of more than 50 % of the current value while armed)."""

    model_config = ConfigDict(extra="forbid")

    value: float = Field(..., allow_inf_nan=False)
    force: bool = Field(False, description="operator only: accept more than a 50 % change in flight")

    @field_validator("value", mode="before")
    @classmethod
    def _number(cls, v: Any) -> float:
        try:
            return check_number(v)  # an empty or non-numeric value is refused (never read as 0)
        except ParamWriteError as exc:
            raise ValueError(exc.reason) from None


class ParamAnswer(BaseModel):
    """An autopilot parameter as the autopilot answered (the read-back after a set)."""

    name: str
    value: float
    type: int
    old: float | None = Field(default=None, description="after a write: the value read before it")
    min: float | None = Field(default=None, description="the lowest value accepted (the autopilot's table)")
    max: float | None = Field(default=None, description="the highest value accepted")
    units: str | None = None
    description: str | None = None
    autopilot: str | None = Field(default=None, description="the table the range is from: arducopter or "
                                  "model; null: not a parameter written through this station")


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
