"""The result of a marker-pose-graph job (the digest's output contract)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict


class PoseValue(BaseModel):
    q_wxyz: list[float]  # Hamilton, scalar first, body -> reference
    t_m: list[float]  # body origin in the reference frame [m]


class FramePose(BaseModel):
    frame: int
    t: float
    status: Literal["measured", "bridged", "missing"]
    n_markers: int
    T_world_body: PoseValue | None = None
    cov: list[list[float]] | None = None  # 6x6, (dtheta_world [rad] x3, dp_world [m] x3)
    T_launch_body: PoseValue | None = None
    ypr_deg: list[float] | None = None  # ZYX angles of T_launch_body
    residual_rms_m: float | None = None
    n_tags: int | None = None  # levels B and C: inlier tag detections (over all cameras) in the frame
    residual_rms_px: float | None = None  # levels B and C: RMS corner residual [px]


class LayoutMarker(BaseModel):
    id: str
    xyz: list[float]
    sigma_m: float


class LayoutInfo(BaseModel):
    source: Literal["given", "estimated"]
    frame_markers: list[str]  # the three markers that define the launch frame
    markers: list[LayoutMarker]


class Segment(BaseModel):
    frames: list[int]  # first and last frame number
    linked_by: str


class GraphInfo(BaseModel):
    model_config = ConfigDict(extra="allow")

    nodes: int
    landmarks: int
    factors: dict[str, int]
    iterations: int
    chi2_final: float
    dof: int
    solver: str
    time_s: float


class Rejection(BaseModel):
    frame: int
    track: str
    residual_m: float | None
    residual_px: float | None = None  # levels B and C: the detection's largest corner residual [px]
    reason: Literal["residual", "conflict"]


class Residuals(BaseModel):
    rms_m: float | None  # level A [m]; None for tags
    per_marker_rms_m: dict[str, float]
    rms_px: float | None = None  # levels B and C: RMS corner residual [px]
    per_tag_rms_px: dict[str, float] | None = None
    rejected: list[Rejection]


class DetectionInfo(BaseModel):
    """Level C: what the tag detector found in the images."""

    detector: str
    images: int
    detections: int
    known_tags: int  # detections of a tag in the layout
    per_camera: dict[str, int]
    time_s: float


class MarkerPoseResult(BaseModel):
    model_config = ConfigDict(extra="forbid")

    kind: Literal["marker-pose-graph"] = "marker-pose-graph"
    level: Literal["A", "B", "C"] = "A"  # A: markers, B: tag corners, C: images
    method: Literal["graph", "paper"]
    body_frame: Literal["layout", "launch"]
    point_sigma_m: float | None  # level A's marker sigma [m]; None for tags
    pixel_sigma_px: dict[str, float] | None = None  # levels B and C: corner sigma per camera [px]
    detection: DetectionInfo | None = None
    motion_prior: str
    poses: list[FramePose]
    layout: LayoutInfo
    associations: dict[str, str | None]
    segments: list[Segment]
    graph: GraphInfo
    residuals: Residuals
    coverage: float  # share of frames with 3 or more markers that were measured
    warnings: list[str]
    timing_s: dict[str, float]
