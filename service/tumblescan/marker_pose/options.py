"""Options and limits of marker-pose-graph (small pydantic models; unknown keys are refused)."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator
from pydantic_core import InitErrorDetails, PydanticCustomError

# Bounds of the white-acceleration PSDs (rad^2/s^3 and m^2/s^3 alike). A PSD q lets the velocity
# wander by sqrt(q T) in T seconds: 1e-6 is 1 mm/s (1 mrad/s) in a second, a target on rails; 1e4
# is 100 m/s (100 rad/s) in a second, no smoothing left at any motion-capture rate (the data's
# PSDs, the default, are about 1e-4 to 1e-2). A motion factor's covariance is q dt^3 / 3 (pose)
# and q dt (twist) against the frames' pose covariances: an infinite q leaves the twists
# undetermined and a vanishing one makes the graph singular to working precision (GTSAM:
# "indeterminate linear system"). Within the bounds the graph solves at 10 Hz to 1 kHz, the
# marginals by QR where Cholesky fails (``graph.solve_marginals``; tested at the extremes).
MIN_PSD, MAX_PSD = 1e-6, 1e4


def not_applicable(model: BaseModel, name: str, why: str) -> ValidationError:
    """A refusal of option ``name`` that its other options make meaningless: a validation error at
    the option's own location, so the API names ``options.<name>`` and the CLI ``<name>``, as for a
    value out of range (a plain ``ValueError`` here would be located at the options as a whole)."""
    details = InitErrorDetails(
        type=PydanticCustomError("option_not_applicable", why), loc=(name,), input=getattr(model, name)
    )
    return ValidationError.from_exception_data(type(model).__name__, [details])


def _set_away_from_default(model: BaseModel, name: str) -> bool:
    """Given, and not to its default (a client sending every default changes nothing)."""
    return name in model.model_fields_set and getattr(model, name) != type(model).model_fields[name].default


class _MotionPrior(BaseModel):
    """The constant-velocity graph every level can put over its per-frame poses."""

    # NaN or Infinity in any option is refused by name (they pass pydantic's bounds otherwise).
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    motion_prior: Literal["none", "constant_velocity"] = Field(
        "none", description="constant_velocity: white-noise-acceleration prior between frames (smooths, bridges gaps)"
    )
    angular_accel_psd: float | None = Field(
        None,
        ge=MIN_PSD,
        le=MAX_PSD,
        description="PSD of the white angular acceleration [rad^2/s^3], 1e-6 to 1e4; default: from the data",
    )
    accel_psd: float | None = Field(
        None,
        ge=MIN_PSD,
        le=MAX_PSD,
        description="PSD of the white linear acceleration [m^2/s^3], 1e-6 to 1e4; default: from the data",
    )
    max_bridge_frames: int = Field(10, ge=0, le=10_000, description="longest gap the motion prior bridges [frames]")

    @model_validator(mode="after")
    def _tunings_need_the_prior(self) -> Any:
        """The PSDs and the bridge length tune the constant-velocity graph: without it they would be
        ignored, so they are refused by name instead."""
        if self.motion_prior == "none":
            for name in ("angular_accel_psd", "accel_psd", "max_bridge_frames"):
                if _set_away_from_default(self, name):
                    raise not_applicable(self, name, "applies with motion_prior 'constant_velocity' only")
        return self


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
        None,
        gt=0,
        le=0.1,
        description="1-sigma marker error per axis [m], at most 0.1 (the document's own range); "
        "overrides the document's sensor.point_sigma_m",
    )
    marginals: bool = Field(True, description="compute each pose's covariance from the graph")

    @model_validator(mode="after")
    def _paper_takes_its_own_graph(self) -> Any:
        """The paper's method is its chain and pose graph as published (kept for benchmarks): it has
        no motion prior and no robust kernel, so asking for either is refused, not ignored. A robust
        width without a kernel would be ignored too."""
        if self.method == "paper":
            if self.motion_prior != "none":
                raise not_applicable(
                    self,
                    "motion_prior",
                    f"'{self.motion_prior}' does not apply to method 'paper' (the paper's chain has no motion "
                    "prior; use method 'graph')",
                )
            if self.robust != "none":
                raise not_applicable(self, "robust", f"'{self.robust}' does not apply to method 'paper'")
        if self.robust == "none" and _set_away_from_default(self, "robust_k"):
            raise not_applicable(self, "robust_k", "applies with robust 'huber' or 'cauchy' only")
        return self


class MarkerPoseLimits(BaseModel):
    """Input sizes a deployment accepts."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

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

    @model_validator(mode="after")
    def _decimation_is_apriltags(self) -> Any:
        """OpenCV's ArUco detector has no decimation: refused, not ignored."""
        if self.detector != "apriltag" and _set_away_from_default(self, "quad_decimate"):
            raise not_applicable(self, "quad_decimate", f"applies to detector 'apriltag' only, not '{self.detector}'")
        return self
