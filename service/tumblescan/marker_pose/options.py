"""Options and limits of marker-pose-graph (small pydantic models; unknown keys are refused)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field


class _MotionPrior(BaseModel):
    """The constant-velocity graph every level can put over its per-frame poses."""

    model_config = ConfigDict(extra="forbid")

    motion_prior: Literal["none", "constant_velocity"] = Field(
        "none", description="constant_velocity: white-noise-acceleration prior between frames (smooths, bridges gaps)"
    )
    angular_accel_psd: float | None = Field(
        None, gt=0, description="PSD of the white angular acceleration [rad^2/s^3]; default: from the data"
    )
    accel_psd: float | None = Field(
        None, gt=0, description="PSD of the white linear acceleration [m^2/s^3]; default: from the data"
    )
    max_bridge_frames: int = Field(10, ge=0, le=10_000, description="longest gap the motion prior bridges [frames]")


class MarkerPoseOptions(_MotionPrior):
    """How to estimate from marker coordinates (level A)."""

    method: Literal["graph", "paper"] = Field(
        "graph",
        description="graph: per-frame identification and Kabsch, refined by a GTSAM pose graph (ours); "
        "paper: vector-cross poses chained frame to frame, then a pose graph (the paper's method, for benchmarks)",
    )
    body_frame: Literal["layout", "launch"] | None = Field(
        None, description="frame of the reported body poses; default: the given layout's, else the launch frame"
    )
    robust: Literal["none", "huber", "cauchy"] = Field("none", description="robust kernel on the graph's factors")
    robust_k: float = Field(3.0, gt=0, le=100, description="kernel width in sigmas")
    outlier_sigma: float = Field(5.0, ge=3.0, le=50.0, description="per-marker residual gate [sigmas]")
    point_sigma_m: float | None = Field(
        None, description="1-sigma marker error per axis [m]; overrides the document's sensor.point_sigma_m"
    )
    marginals: bool = Field(True, description="compute each pose's covariance from the graph")


class MarkerPoseLimits(BaseModel):
    """Input sizes a deployment accepts."""

    model_config = ConfigDict(extra="forbid")

    max_observations: int = Field(2_000_000, ge=1)
    max_frames: int = Field(200_000, ge=1)
    max_tracks: int = Field(200_000, ge=1)
    max_layout_markers: int = Field(256, ge=3)
    max_range_m: float = Field(100.0, gt=0, description="points farther from the world origin are refused")
    max_cameras: int = Field(64, ge=1, description="cameras of a tags or images input")
    max_images: int = Field(20_000, ge=1, description="images in an images zip")
    max_archive_bytes: int = Field(2_000_000_000, ge=1, description="size of an images zip [bytes]")


class TagPoseOptions(_MotionPrior):
    """How to estimate from tag corners (level B): a joint Gauss-Newton fit of every camera's
    corners per frame, then the same constant-velocity graph as level A when asked for."""

    outlier_sigma: float = Field(5.0, ge=3.0, le=50.0, description="per-corner residual gate [sigmas]")
    pixel_sigma_px: float | None = Field(
        None, gt=0, le=10, description="1-sigma corner error per image axis [px]; overrides every camera's pixel_sigma"
    )
    marginals: bool = Field(True, description="compute each pose's covariance")
    estimate_pixel_sigma: bool = Field(
        False,
        description="estimate the corner sigma from the fit's residuals (robustly, pooled over the cameras) and "
        "refit with it, instead of trusting each camera's pixel_sigma",
    )


class ImagePoseOptions(TagPoseOptions):
    """Level C: tags detected in the images first, then level B. The detector's corner accuracy
    depends on the images, so the corner sigma is estimated from the residuals by default."""

    estimate_pixel_sigma: bool = Field(
        True, description="estimate the corner sigma from the fit's residuals (a detector's accuracy is not known)"
    )

    detector: Literal["apriltag", "aruco"] = Field(
        "apriltag",
        description="apriltag: pupil-apriltags (the more accurate); aruco: OpenCV's ArUco AprilTag dictionary",
    )
    quad_decimate: float = Field(
        1.0, ge=1.0, le=4.0, description="apriltag: detect quads on an image decimated this much"
    )
    roi_tracking: bool = Field(
        True,
        description="search each image around the tags its camera found in the previous frame "
        "(the whole image every 10 frames, after a gap, or when none were found); about 10x faster",
    )
