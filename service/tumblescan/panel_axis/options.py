"""Estimator options (small, strict)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationInfo, field_validator
from pydantic_core import PydanticCustomError


class EstimateOptions(BaseModel):
    """``method``: ``ours`` (LSD on the grayscale image, sub-pixel edges, N-plane fit with σ) or
    ``paper`` (Otsu mask, LSD on the mask, two longest edges, two-plane intersection).

    Infinity and NaN are refused in every float option (an infinite ``weak_snr`` forced every view
    to weak perspective). The paper's pipeline has no σ, so no perspective SNR: it cannot tell a
    weak-perspective view, and the options that act on that test are refused with it rather than
    ignored (``require_axis`` let it answer the line of sight)."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    method: Literal["ours", "paper"] = "ours"
    # No edge is longer than the longest image accepted: 64 Mpx with sides of 64 px or more.
    min_line_px: float = Field(30.0, ge=10, le=1_000_000, description="shortest long edge, px")
    weak_snr: float = Field(20.0, gt=0, description="perspective SNR under which the view is weak perspective")
    require_axis: bool = Field(
        False,
        description="refuse (depth_unobservable) instead of the in-image angle when weak perspective has no prior "
        "(method 'ours' only)",
    )
    seed: int = Field(0, ge=0, description="seeds RANSAC and the weak-perspective Monte Carlo")

    @field_validator("weak_snr")
    @classmethod
    def _weak_snr_needs_ours(cls, v: float, info: ValidationInfo) -> float:
        # Given, and not the default (a client may send every option; the default changes nothing).
        if info.data.get("method") == "paper" and v != cls.model_fields["weak_snr"].default:
            raise PydanticCustomError(
                "option_not_applicable",
                "does not apply to method 'paper' (it has no sigma, so no perspective SNR to compare)",
            )
        return v

    @field_validator("require_axis")
    @classmethod
    def _require_axis_needs_ours(cls, v: bool, info: ValidationInfo) -> bool:
        if v and info.data.get("method") == "paper":
            raise PydanticCustomError(
                "option_not_applicable",
                "does not apply to method 'paper': it has no sigma, so it cannot tell a weak-perspective view "
                "(whose planes meet at the line of sight) and would answer the line of sight; use method 'ours'",
            )
        return v
