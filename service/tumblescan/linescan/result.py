"""The motion result: the contract the CLI, the API and the client all return."""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from .._typing import FloatArray
from ..geometry.rotations import axis_from_angles
from ..target.motion import Motion
from .validation import Similarity, axis_sigma_rad

Vec3 = tuple[float, float, float]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class SpinPublic(_Strict):
    axis: Vec3 = Field(description="unit spin axis at the reference time, sensor frame")
    alpha_deg: float
    beta_deg: float
    rate_deg_s: float = Field(ge=0)


class PrecessionPublic(_Strict):
    axis: Vec3 | None = Field(description="unit precession axis; null for the spin-only model")
    alpha_deg: float | None
    beta_deg: float | None
    rate_deg_s: float = Field(ge=0, description="0 for the spin-only model")
    center_m: Vec3 = Field(
        description="precession centre; for spin-only, the point of the spin axis nearest the features' centroid"
    )


class UncertaintyPublic(_Strict):
    """1-sigma from the covariance of the maximum-likelihood fit; axes as total angular sigma."""

    spin_axis_deg: float
    spin_rate_deg_s: float
    precession_axis_deg: float | None
    precession_rate_deg_s: float
    center_m: Vec3


class FitPublic(_Strict):
    rms_residual_m: float = Field(
        description="tracks: RMS position residual; frames: RMS surfel centroid-to-plane residual"
    )
    observations: int = Field(description="all observations (tracks) or points (frames) given, outliers included")
    tracks: int = Field(description="feature tracks; 0 when the motion came from dense frames")
    frames: int
    outliers: int = Field(0, description="observations rejected as outliers (counted in observations)")
    source: Literal["tracks", "frames"] = "tracks"
    points_used: int | None = Field(
        None,
        description="frames: points in the fit: in surfels matched across frames, or on thin members fitted as lines",
    )
    frame_rms_m: list[float | None] | None = Field(
        None,
        description="frames: RMS centroid-to-plane residual of each frame (null: no matches); a bad frame stands out",
    )


class ValidationPublic(_Strict):
    """Two-frame-count similarity check (paper eq. 11)."""

    passed: bool
    frames: tuple[int, int]
    distance: float | None
    threshold: float | None
    test: Literal["fixed", "covariance", "skipped"] = "fixed"


class SolverPublic(_Strict):
    path: str
    iterations: int
    attempts: int
    elapsed_s: float


class MotionResult(_Strict):
    model: Literal["spin-precession", "spin-only"]
    reference_time_s: float
    spin: SpinPublic
    precession: PrecessionPublic
    nutation_angle_deg: float | None = Field(description="angle between the axes; null for spin-only")
    uncertainty: UncertaintyPublic
    fit: FitPublic
    validation: ValidationPublic
    solver: SolverPublic
    warnings: list[str] = Field(default_factory=list)

    def motion(self) -> Motion:
        """The estimated motion, for rectification (spin-only: no precession)."""
        axis = self.precession.axis or (0.0, 0.0, 1.0)
        return Motion.from_degrees(
            spin_axis=self.spin.axis,
            spin_rate_deg_s=self.spin.rate_deg_s,
            precession_axis=axis,
            precession_rate_deg_s=self.precession.rate_deg_s if self.precession.axis else 0.0,
            center_m=self.precession.center_m,
            reference_time_s=self.reference_time_s,
        )


def nearest_on_spin_axis(x: FloatArray, point_m: FloatArray) -> FloatArray:
    """The point of the spin axis (through ``x``'s centre) nearest ``point_m``."""
    l_s = axis_from_angles(x[0], x[1])
    return np.asarray(x[6:9] + l_s * float(l_s @ (point_m - x[6:9])), dtype=float)


def motion_fields(
    x: FloatArray, cov: FloatArray, *, spin_only: bool, center_m: FloatArray, reference_time_s: float
) -> dict[str, Any]:
    """The motion part of a :class:`MotionResult` from a canonical 9-vector and its covariance."""
    deg = np.degrees
    l_s = axis_from_angles(x[0], x[1])
    l_p = None if spin_only else axis_from_angles(x[3], x[4])
    return {
        "model": "spin-only" if spin_only else "spin-precession",
        "reference_time_s": reference_time_s,
        "spin": {"axis": l_s.tolist(), "alpha_deg": deg(x[0]), "beta_deg": deg(x[1]), "rate_deg_s": deg(x[2])},
        "precession": {
            "axis": None if l_p is None else l_p.tolist(),
            "alpha_deg": None if spin_only else deg(x[3]),
            "beta_deg": None if spin_only else deg(x[4]),
            "rate_deg_s": 0.0 if spin_only else deg(x[5]),
            "center_m": np.asarray(center_m).tolist(),
        },
        "nutation_angle_deg": None if l_p is None else deg(np.arccos(np.clip(l_s @ l_p, -1, 1))),
        "uncertainty": {
            "spin_axis_deg": deg(axis_sigma_rad(x, cov, 0, 1)),
            "spin_rate_deg_s": deg(np.sqrt(cov[2, 2])),
            "precession_axis_deg": None if spin_only else deg(axis_sigma_rad(x, cov, 3, 4)),
            "precession_rate_deg_s": deg(np.sqrt(cov[5, 5])),
            "center_m": np.sqrt(np.diag(cov)[6:9]).tolist(),
        },
    }


def validation_fields(check: Similarity | None, n_frames: int, n2: int) -> dict[str, Any]:
    return {
        "passed": bool(check is not None and check.passed),
        "frames": (n_frames, n2),
        "distance": None if check is None or not np.isfinite(check.distance) else check.distance,
        "threshold": None if check is None or not np.isfinite(check.threshold) else check.threshold,
        "test": "skipped" if check is None else check.test,
    }
