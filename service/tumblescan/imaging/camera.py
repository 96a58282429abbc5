"""The pinhole camera: intrinsics, projection and back-projection.

Pixel centres are at integer coordinates (OpenCV): ``uv_px = (fx·x/z + skew·y/z + cx, fy·y/z + cy)``
for a point ``p_cam_m = (x, y, z)`` in the camera frame (x right, y down, z forward). Distortion,
when given, is OpenCV's ``[k1, k2, p1, p2, k3]``; the renderer draws an ideal pinhole image, and the
estimators undistort measured points before using them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._typing import FloatArray


@dataclass(frozen=True)
class PinholeCamera:
    """A pinhole camera of ``width_px`` x ``height_px`` pixels (focal lengths and principal point in px)."""

    width_px: int
    height_px: int
    fx_px: float
    fy_px: float
    cx_px: float
    cy_px: float
    skew: float = 0.0
    distortion: tuple[float, float, float, float, float] | None = None

    @property
    def K(self) -> FloatArray:
        """The 3x3 intrinsic matrix."""
        return np.array([[self.fx_px, self.skew, self.cx_px], [0.0, self.fy_px, self.cy_px], [0.0, 0.0, 1.0]])

    @property
    def focal_px(self) -> float:
        """The mean focal length (px), used to turn pixel lengths into angles."""
        return 0.5 * (self.fx_px + self.fy_px)

    def project(self, p_cam_m: FloatArray) -> FloatArray:
        """Ideal (undistorted) pixel coordinates of points ``p_cam_m`` (N, 3) in front of the camera -> (N, 2)."""
        p = np.atleast_2d(np.asarray(p_cam_m, dtype=float))
        x = p[:, 0] / p[:, 2]
        y = p[:, 1] / p[:, 2]
        return np.column_stack([self.fx_px * x + self.skew * y + self.cx_px, self.fy_px * y + self.cy_px])

    def rays(self, uv_px: FloatArray) -> FloatArray:
        """Unit viewing directions (N, 3) in the camera frame through ideal pixel coordinates ``uv_px`` (N, 2)."""
        uv = np.atleast_2d(np.asarray(uv_px, dtype=float))
        y = (uv[:, 1] - self.cy_px) / self.fy_px
        x = (uv[:, 0] - self.cx_px - self.skew * y) / self.fx_px
        d = np.column_stack([x, y, np.ones_like(x)])
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    def undistort(self, uv_px: FloatArray) -> FloatArray:
        """Measured pixel coordinates (N, 2) -> ideal pinhole coordinates (no-op without distortion)."""
        uv = np.atleast_2d(np.asarray(uv_px, dtype=float))
        if self.distortion is None or not any(self.distortion):
            return uv
        import cv2

        pts = cv2.undistortPoints(uv.reshape(-1, 1, 2), self.K, np.asarray(self.distortion, dtype=float), P=self.K)
        return np.asarray(pts, dtype=float).reshape(-1, 2)

    def plane_normal(self, line_abc: FloatArray) -> FloatArray:
        """Unit normal (camera frame) of the plane through the camera centre that projects to the ideal
        image line ``a·u + b·v + c = 0``: ``n = normalize(Kᵀ l)``."""
        n = self.K.T @ np.asarray(line_abc, dtype=float)
        return np.asarray(n / np.linalg.norm(n), dtype=float)

    def contains(self, uv_px: FloatArray, margin_px: float = 0.0) -> bool:
        """Whether every point lies inside the image, ``margin_px`` away from its border."""
        uv = np.atleast_2d(uv_px)
        lo = -0.5 + margin_px
        return bool(
            np.all(uv[:, 0] >= lo)
            and np.all(uv[:, 1] >= lo)
            and np.all(uv[:, 0] <= self.width_px - 0.5 - margin_px)
            and np.all(uv[:, 1] <= self.height_px - 0.5 - margin_px)
        )


def camera_from_fov(width_px: int, height_px: int, fov_x_deg: float) -> PinholeCamera:
    """A square-pixel camera with the principal point at the image centre and horizontal field ``fov_x_deg``."""
    f = 0.5 * width_px / np.tan(np.radians(fov_x_deg) / 2.0)
    return PinholeCamera(width_px, height_px, float(f), float(f), (width_px - 1) / 2.0, (height_px - 1) / 2.0)
