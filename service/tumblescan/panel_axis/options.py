"""Estimator options (small, strict)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field


class EstimateOptions(BaseModel):
    """``method``: ``ours`` (LSD on the grayscale image, sub-pixel edges, N-plane fit with σ) or
    ``paper`` (Otsu mask, LSD on the mask, two longest edges, two-plane intersection)."""

    model_config = ConfigDict(extra="forbid")

    method: Literal["ours", "paper"] = "ours"
    # No edge is longer than the longest image accepted: 64 Mpx with sides of 64 px or more.
    min_line_px: float = Field(30.0, ge=10, le=1_000_000, description="shortest long edge, px")
    weak_snr: float = Field(20.0, gt=0, description="perspective SNR under which the view is weak perspective")
    require_axis: bool = Field(
        False,
        description="refuse (depth_unobservable) instead of the in-image angle when weak perspective has no prior",
    )
    seed: int = Field(0, ge=0, description="seeds RANSAC and the weak-perspective Monte Carlo")
