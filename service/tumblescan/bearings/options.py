"""Options of a bearings estimate (small, strict: an unknown option is refused)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field


class EstimateOptions(BaseModel):
    """How to associate, triangulate and link."""

    model_config = ConfigDict(extra="forbid")
    method: Literal["ml", "paper"] = Field(
        default="ml",
        description=(
            "ml: epipolar chi-square gate, one-to-one assignment, ML triangulation; "
            "paper: the paper's elevation difference and Mean Shift"
        ),
    )
    gate_chi2: float = Field(default=16.0, gt=0.0, le=1000.0, description="chi-square (1 dof) gate on a pair")
    ambiguity_margin_chi2: float = Field(
        default=4.0,
        ge=0.0,
        le=1000.0,
        description="flag a pair ambiguous when an alternative is this close in chi-square",
    )
    low_parallax_deg: float = Field(default=2.0, ge=0.0, le=90.0)
    multi_frame: bool = Field(
        default=True, description="resolve ambiguous frames with the pairs other frames support (station tracks)"
    )
    max_angular_rate_deg_s: float = Field(
        default=5.0, gt=0.0, le=180.0, description="fastest target across the sky, for starting station tracks"
    )
    link_tracks: bool = Field(default=True, description="give targets track ids stable across frames")
    max_speed_m_s: float = Field(default=10_000.0, gt=0.0, description="fastest target, for starting tracks")
    max_gap_frames: int = Field(default=2, ge=0, le=100, description="frames a track may go unseen")
    paper_gate_sigma: float = Field(default=5.0, gt=0.0, description="paper: elevation-difference gate in its sigmas")
    paper_radius_deg: float = Field(default=10.0, gt=0.0, le=90.0, description="paper: Mean Shift radius")
