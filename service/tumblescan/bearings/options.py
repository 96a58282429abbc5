"""Options of a bearings estimate (small, strict: an unknown option is refused, and so is an
option the chosen method or settings would not use, so that none is ever silently ignored)."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationInfo, field_validator
from pydantic_core import PydanticCustomError

# The options each method reads (the rest apply to both): given with the other method they
# would change nothing, so they are refused rather than ignored.
ML_ONLY = ("gate_chi2", "ambiguity_margin_chi2", "multi_frame", "max_angular_rate_deg_s")
PAPER_ONLY = ("paper_gate_sigma", "paper_radius_deg")
# Read only while linking 3D tracks: always with the paper's method (its correction works on
# tracks), with ours only when ``link_tracks`` is on.
LINKING = ("max_speed_m_s", "max_gap_frames")
# Read only by the multi-frame association (ours).
MULTI_FRAME = ("max_angular_rate_deg_s",)
# What turns each on with method 'ml', and why it is refused when that is off.
SWITCHED_BY = {
    **{
        name: ("multi_frame", "when multi_frame is false (it starts the multi-frame station tracks)")
        for name in MULTI_FRAME
    },
    **{name: ("link_tracks", "when link_tracks is false with method 'ml' (no tracks are linked)") for name in LINKING},
}


def _changed(model: type[BaseModel], value: Any, info: ValidationInfo) -> bool:
    """Whether ``value`` differs from the field's default (only then can it be ignored)."""
    return bool(value != model.model_fields[str(info.field_name)].default)


def _not_applicable(why: str) -> PydanticCustomError:
    return PydanticCustomError("option_not_applicable", "does not apply {why}", {"why": why})


class EstimateOptions(BaseModel):
    """How to associate, triangulate and link. Every float must be finite: NaN or Infinity
    would pass no bound check downstream (an infinite gate keeps every pair)."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    method: Literal["ml", "paper"] = Field(
        default="ml",
        description=(
            "ml: epipolar chi-square gate, one-to-one assignment, ML triangulation; "
            "paper: the paper's elevation difference and Mean Shift"
        ),
    )
    gate_chi2: float = Field(default=16.0, gt=0.0, le=1000.0, description="ml: chi-square (1 dof) gate on a pair")
    ambiguity_margin_chi2: float = Field(
        default=4.0,
        ge=0.0,
        le=1000.0,
        description="ml: flag a pair ambiguous when an alternative is this close in chi-square",
    )
    low_parallax_deg: float = Field(default=2.0, ge=0.0, le=90.0)
    multi_frame: bool = Field(
        default=True, description="ml: resolve ambiguous frames with the pairs other frames support (station tracks)"
    )
    max_angular_rate_deg_s: float = Field(
        default=5.0,
        gt=0.0,
        le=180.0,
        description="ml with multi_frame: fastest target across the sky, for starting station tracks",
    )
    link_tracks: bool = Field(default=True, description="give targets track ids stable across frames")
    max_speed_m_s: float = Field(
        default=10_000.0, gt=0.0, description="fastest target, for starting tracks (ml: with link_tracks)"
    )
    max_gap_frames: int = Field(
        default=2, ge=0, le=100, description="frames a track may go unseen (ml: with link_tracks)"
    )
    paper_gate_sigma: float = Field(default=5.0, gt=0.0, description="paper: elevation-difference gate in its sigmas")
    paper_radius_deg: float = Field(default=10.0, gt=0.0, le=90.0, description="paper: Mean Shift radius")

    # Field validators run on given values only (not on defaults) and after the fields declared
    # before them, so ``info.data`` holds the method, ``multi_frame`` and ``link_tracks``. A value
    # equal to the default changes nothing and passes: a client may send every option.
    @field_validator(*ML_ONLY)
    @classmethod
    def _ml_only(cls, value: Any, info: ValidationInfo) -> Any:
        if info.data.get("method") == "paper" and _changed(cls, value, info):
            raise _not_applicable("to method 'paper' (an option of method 'ml')")
        return value

    @field_validator(*PAPER_ONLY)
    @classmethod
    def _paper_only(cls, value: Any, info: ValidationInfo) -> Any:
        if info.data.get("method", "paper") != "paper" and _changed(cls, value, info):
            raise _not_applicable(f"to method '{info.data['method']}' (an option of method 'paper')")
        return value

    @field_validator(*MULTI_FRAME, *LINKING)
    @classmethod
    def _switched_on(cls, value: Any, info: ValidationInfo) -> Any:
        switch, why = SWITCHED_BY[str(info.field_name)]
        if info.data.get("method") == "ml" and info.data.get(switch) is False and _changed(cls, value, info):
            raise _not_applicable(why)
        return value
