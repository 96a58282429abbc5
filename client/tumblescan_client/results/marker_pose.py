"""The client's typed result of a ``marker-pose-graph`` job (mirrors the service's model)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict


class _Model(BaseModel):
    model_config = ConfigDict(extra="allow")


class PoseValue(_Model):
    q_wxyz: list[float]
    t_m: list[float]


class FramePose(_Model):
    frame: int
    t: float
    status: Literal["measured", "bridged", "missing"]
    n_markers: int
    T_world_body: PoseValue | None = None
    cov: list[list[float]] | None = None
    T_launch_body: PoseValue | None = None
    ypr_deg: list[float] | None = None
    residual_rms_m: float | None = None
    n_tags: int | None = None  # levels B and C: inlier tag detections (over all cameras) in the frame
    residual_rms_px: float | None = None  # levels B and C: RMS corner residual [px]


class LayoutMarker(_Model):
    id: str
    xyz: list[float]
    sigma_m: float


class LayoutInfo(_Model):
    source: Literal["given", "estimated"]
    frame_markers: list[str]
    markers: list[LayoutMarker]


class Segment(_Model):
    frames: list[int]
    linked_by: str


class GraphInfo(_Model):
    nodes: int
    landmarks: int
    factors: dict[str, int]
    iterations: int
    chi2_final: float
    dof: int
    solver: str
    time_s: float


class Rejection(_Model):
    frame: int
    track: str
    residual_m: float | None
    residual_px: float | None = None  # levels B and C: the detection's largest corner residual [px]
    reason: str


class Residuals(_Model):
    rms_m: float | None  # level A [m]; None for tags
    per_marker_rms_m: dict[str, float]
    rms_px: float | None = None  # levels B and C: RMS corner residual [px]
    per_tag_rms_px: dict[str, float] | None = None
    rejected: list[Rejection]


class DetectionInfo(_Model):
    detector: str
    images: int
    detections: int
    known_tags: int
    per_camera: dict[str, int]
    time_s: float


class MarkerPoseResult(_Model):
    kind: Literal["marker-pose-graph"] = "marker-pose-graph"
    level: Literal["A", "B", "C"] = "A"
    method: str
    body_frame: str
    point_sigma_m: float | None
    pixel_sigma_px: dict[str, float] | None = None
    detection: DetectionInfo | None = None
    motion_prior: str
    poses: list[FramePose]
    layout: LayoutInfo
    associations: dict[str, str | None]
    segments: list[Segment]
    graph: GraphInfo
    residuals: Residuals
    coverage: float
    warnings: list[str]
    timing_s: dict[str, float]
