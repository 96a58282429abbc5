"""Line-scan lidar geometry and noise (method.md section 1, paper Table 1).

Sensor frame: origin at the lidar, ``z`` along the boresight, ``x`` to the right (the
direction the line sweeps), ``y`` down. Line ``k`` of frame ``f`` is taken at

    t = f * frame_period_s + k * scan_time_s / lines

and points at azimuth ``az_k`` (about ``y``); pixel ``i`` of a line at elevation ``el_i``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field, model_validator

ARCSEC_RAD = np.pi / (180.0 * 3600.0)


class SensorNoise(BaseModel):
    """Measurement noise: 1-sigma range along the line of sight, angle across it."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    range_sigma_m: float = Field(0.02, gt=0, le=100, allow_inf_nan=False)
    angle_sigma_arcsec: float = Field(36.0, gt=0, le=3.6e5, allow_inf_nan=False)

    @property
    def angle_sigma_rad(self) -> float:
        return self.angle_sigma_arcsec * ARCSEC_RAD

    def whitening(self, obs_m: NDArray[np.float64]) -> NDArray[np.float64]:
        """Per-observation ``W = Sigma^-1/2``, shape ``(n, 3, 3)``, for a sensor at the origin.

        ``Sigma = s_r^2 u u^T + (s_a rho)^2 (I - u u^T)`` with ``u`` the unit line of sight
        and ``rho`` the range, so ``W = u u^T / s_r + (I - u u^T) / (s_a rho)``.
        """
        rho = np.linalg.norm(obs_m, axis=-1)
        u = obs_m / rho[:, None]
        uu = u[:, :, None] * u[:, None, :]
        across = (np.eye(3) - uu) / (self.angle_sigma_rad * rho)[:, None, None]
        return np.asarray(uu / self.range_sigma_m + across, dtype=float)

    def sample(self, points_m: NDArray[np.float64], rng: np.random.Generator) -> NDArray[np.float64]:
        """Add range noise along and angle noise across each point's line of sight."""
        rho = np.linalg.norm(points_m, axis=-1)
        u = points_m / rho[:, None]
        e1, e2 = perpendiculars(u)
        n = len(points_m)
        d_rho = rng.normal(0.0, self.range_sigma_m, n)
        d_a = rng.normal(0.0, self.angle_sigma_rad, (n, 2)) * rho[:, None]
        noisy = points_m + u * d_rho[:, None] + e1 * d_a[:, [0]] + e2 * d_a[:, [1]]
        return np.asarray(noisy, dtype=float)


def perpendiculars(u: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Two unit vectors across each unit vector ``u`` (rows), completing a right-handed basis."""
    helper = np.where(np.abs(u[:, [0]]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    e1 = np.cross(u, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    return e1, np.cross(u, e1)


class Scanner(BaseModel):
    """Line-scan lidar parameters; defaults are the paper's Table 1."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    lines: int = Field(512, ge=2, le=8192, description="lines per frame (swept in azimuth)")
    pixels: int = Field(512, ge=1, le=8192, description="ranges per line (in elevation)")
    fov_azimuth_deg: float = Field(10.0, gt=0, lt=180, allow_inf_nan=False)
    fov_elevation_deg: float = Field(10.0, gt=0, lt=180, allow_inf_nan=False)
    frame_period_s: float = Field(1.0, gt=0, le=3600, allow_inf_nan=False)
    scan_time_s: float = Field(0.5, gt=0, le=3600, allow_inf_nan=False)
    max_range_m: float = Field(1000.0, gt=0, allow_inf_nan=False)
    noise: SensorNoise = SensorNoise()

    @model_validator(mode="after")
    def _scan_fits_in_period(self) -> Scanner:
        if self.scan_time_s > self.frame_period_s:
            raise ValueError("scan_time_s must not exceed frame_period_s")
        return self

    def line_times_s(self, frames: int, start_s: float = 0.0) -> NDArray[np.float64]:
        """Time of every line, shape ``(frames, lines)``."""
        f = np.arange(frames)[:, None] * self.frame_period_s
        k = np.arange(self.lines)[None, :] * (self.scan_time_s / self.lines)
        return np.asarray(start_s + f + k, dtype=float)

    def azimuths_rad(self) -> NDArray[np.float64]:
        """Centre azimuth of each line, ``(lines,)``, increasing with the line index."""
        return _bin_centres(self.fov_azimuth_deg, self.lines)

    def elevations_rad(self) -> NDArray[np.float64]:
        """Centre elevation of each pixel, ``(pixels,)``."""
        return _bin_centres(self.fov_elevation_deg, self.pixels)

    def ray_directions(self) -> NDArray[np.float64]:
        """Unit ray directions, shape ``(lines, pixels, 3)``."""
        return directions(self.azimuths_rad()[:, None], self.elevations_rad()[None, :])


def _bin_centres(fov_deg: float, n: int) -> NDArray[np.float64]:
    half = np.radians(fov_deg) / 2
    return np.asarray(-half + (np.arange(n) + 0.5) * (2 * half / n), dtype=float)


def directions(azimuth_rad: NDArray[np.float64], elevation_rad: NDArray[np.float64]) -> NDArray[np.float64]:
    """Unit vectors ``(sin az cos el, sin el, cos az cos el)``, broadcasting the inputs."""
    az, el = np.broadcast_arrays(azimuth_rad, elevation_rad)
    ce = np.cos(el)
    return np.stack([np.sin(az) * ce, np.sin(el), np.cos(az) * ce], axis=-1)


def azimuth_elevation(points_m: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Inverse of :func:`directions` for points (any length): ``(azimuth, elevation)`` radians."""
    x, y, z = points_m[..., 0], points_m[..., 1], points_m[..., 2]
    az = np.arctan2(x, z)
    el = np.arctan2(y, np.hypot(x, z))
    return az, el
