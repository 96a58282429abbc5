"""Options of an estimate (the job's options model)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field


class EstimateOptions(BaseModel):
    model_config = ConfigDict(extra="forbid")

    method: Literal["ours", "paper"] = Field(
        "ours", description="ours (rigid-body fit) or the paper's (mean end points, sine fit)"
    )
    return_tracks: bool | None = Field(None, description="add per-track observations (default: meta.json's options)")
