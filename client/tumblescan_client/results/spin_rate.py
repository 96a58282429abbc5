"""``spin-from-images``: the spin rate and axis result, mirroring the service's contract
(``tumblescan.spin_from_images.result/1``)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field


class _Model(BaseModel):
    model_config = ConfigDict(extra="allow")


class AxisCandidate(_Model):
    axis_camera: list[float]
    kind: str  # "mirror" (weak-perspective twin) or "rate" (a rival rate near the image plane)
    cost: float
    rate_deg_s: float | None = None


class Spin(_Model):
    spinning: bool
    rate_deg_s: float
    sigma_rate_deg_s: float
    rate_rad_s: float
    period_s: float | None
    sigma_period_s: float | None
    sense_about_los: Literal[-1, 1] | None
    axis_camera: list[float] | None
    sigma_axis_deg: float | None
    axis_ambiguous: bool
    axis_candidates: list[AxisCandidate]
    axis_los_angle_deg: float | None
    projected_axis_angle_deg: float | None
    reference_time_s: float
    coarse_rate_deg_s: float | None = None


class Quality(_Model):
    frames_used: int
    frames_with_target: int
    line_tracks: int
    observations: int
    fit_rms_px: float | None
    revolutions_covered: float
    step_deg_median: float
    nyquist_rate_deg_s: float
    model: str
    flags: list[str]


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
    schema_: str = Field("tumblescan.spin_from_images.result/1", alias="schema")
    status: str = "succeeded"
    method: str = "ours"
    spin: Spin
    quality: Quality
    frames: list[FrameInfo]
    tracks: list[TrackObs] | None = None
    warnings: list[str] = Field(default_factory=list)
    timings_ms: dict[str, float] = Field(default_factory=dict)
