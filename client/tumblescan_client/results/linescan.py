"""``linescan-motion``: the motion result, mirroring the service's contract exactly."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict

Vec3 = tuple[float, float, float]


class _Model(BaseModel):
    model_config = ConfigDict(extra="allow")


class Spin(_Model):
    axis: Vec3
    alpha_deg: float
    beta_deg: float
    rate_deg_s: float


class Precession(_Model):
    axis: Vec3 | None
    alpha_deg: float | None
    beta_deg: float | None
    rate_deg_s: float
    center_m: Vec3


class Uncertainty(_Model):
    spin_axis_deg: float
    spin_rate_deg_s: float
    precession_axis_deg: float | None
    precession_rate_deg_s: float
    center_m: Vec3


class Fit(_Model):
    rms_residual_m: float
    observations: int
    tracks: int
    frames: int
    outliers: int = 0
    source: Literal["tracks", "frames"] = "tracks"
    points_used: int | None = None
    frame_rms_m: list[float | None] | None = None


class Validation(_Model):
    passed: bool
    frames: tuple[int, int]
    distance: float | None
    threshold: float | None
    test: str = "fixed"


class Solver(_Model):
    path: str
    iterations: int
    attempts: int
    elapsed_s: float


class MotionResult(_Model):
    model: Literal["spin-precession", "spin-only"]
    reference_time_s: float
    spin: Spin
    precession: Precession
    nutation_angle_deg: float | None
    uncertainty: Uncertainty
    fit: Fit
    validation: Validation
    solver: Solver
    warnings: list[str] = []
