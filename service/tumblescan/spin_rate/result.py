"""The result contract ``tumblescan.spin_from_images.result/1`` (see docs/spin_rate.md)."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

RESULT_SCHEMA = "tumblescan.spin_from_images.result/1"
Flag = Literal[
    "short_arc",
    "weak_perspective",
    "few_tracks",
    "target_touches_border",
    "saturated",
    "alias_unchecked",
    "rate_ambiguous",
]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid")


class AxisCandidate(_Model):
    """Another (axis, rate) the data fit almost as well: the weak-perspective twin (``mirror``, the
    reported rate), or near the image plane a rival rate (``rate``, with ``rate_deg_s``; the flag
    ``rate_ambiguous`` and a σ that covers it)."""

    axis_camera: list[float]
    kind: Literal["mirror", "rate"]
    cost: float = Field(description="its fit cost over the best one's (1 = as good)")
    rate_deg_s: float | None = Field(None, description="a rival's rate (kind rate); null for the mirror twin")


class Spin(_Model):
    """The spin: rate ≥ 0 with 1-σ, the axis (spin vector = rate·axis, camera frame), the sense."""

    spinning: bool
    rate_deg_s: float
    sigma_rate_deg_s: float
    rate_rad_s: float
    period_s: float | None
    sigma_period_s: float | None
    sense_about_los: Literal[-1, 1] | None = Field(
        description="sign(a·z): +1 clockwise as displayed; null near the image plane"
    )
    axis_camera: list[float] | None
    sigma_axis_deg: float | None
    axis_ambiguous: bool
    axis_candidates: list[AxisCandidate]
    axis_los_angle_deg: float | None
    projected_axis_angle_deg: float | None
    reference_time_s: float
    coarse_rate_deg_s: float | None = Field(None, description="the Lomb-Scargle periodogram's peak (initialiser)")


class Quality(_Model):
    frames_used: int
    frames_with_target: int
    line_tracks: int
    observations: int
    fit_rms_px: float | None
    revolutions_covered: float
    step_deg_median: float
    nyquist_rate_deg_s: float
    model: Literal["rigid", "paper", "static"]
    flags: list[Flag]


class FrameInfo(_Model):
    index: int
    t_s: float
    target_found: bool
    target_area_px: int
    centroid_px: list[float] | None
    lines: int
    tracked: int
    rms_px: float | None


class TrackObs(_Model):
    track: int
    frame: int
    ends_px: list[list[float]]
    residuals_px: list[float]


class SpinResult(_Model):
    schema_: Literal["tumblescan.spin_from_images.result/1"] = Field(
        "tumblescan.spin_from_images.result/1", alias="schema"
    )
    status: Literal["succeeded"] = "succeeded"
    method: Literal["ours", "paper"] = "ours"
    spin: Spin
    quality: Quality
    frames: list[FrameInfo]
    tracks: list[TrackObs] | None = None
    warnings: list[str] = Field(default_factory=list)
    timings_ms: dict[str, float] = Field(default_factory=dict)

    model_config = ConfigDict(extra="forbid", populate_by_name=True)

    def to_json(self) -> dict[str, Any]:
        return self.model_dump(mode="json", by_alias=True)
