"""Straight edges: LSD segments, sub-pixel edge points along each, and a robust line fit with its own σ.

Coordinates are pixels with centres at integers (OpenCV). A fitted line is kept as its centroid
``c``, unit direction ``t`` and unit normal ``n`` (``a·u + b·v + c = 0`` with ``(a, b) = n``),
with the variances of its offset along ``n`` at the centroid and of its angle.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._typing import FloatArray

PROFILE_STEP_PX = 0.25
MIN_POINT_SIGMA_PX = 0.01


def detect_segments(gray8: np.ndarray, min_length_px: float = 0.0) -> FloatArray:
    """LSD segments ``(N, 4)`` as ``[x1, y1, x2, y2]`` (px) of an 8-bit image, at least ``min_length_px`` long.

    OpenCV's ``createLineSegmentDetector`` (von Gioi et al. 2010) with standard refinement; it was
    missing from OpenCV 3.4.6-3.4.15 and 4.1-4.5.3 and is back since 4.5.4.
    """
    import cv2

    lsd = cv2.createLineSegmentDetector(cv2.LSD_REFINE_STD)
    found = lsd.detect(np.ascontiguousarray(gray8, dtype=np.uint8))[0]
    if found is None:
        return np.zeros((0, 4))
    seg = np.asarray(found, dtype=float).reshape(-1, 4)
    length = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])
    return seg[length >= min_length_px]


@dataclass(frozen=True)
class EdgePoints:
    """Sub-pixel edge points (N, 2) along a segment and the gradient peak at each (DN/px, signed by polarity)."""

    uv_px: FloatArray
    strength: FloatArray


def edge_points(
    image: FloatArray,
    segment: FloatArray,
    *,
    half_width_px: float = 3.0,
    step_px: float = 0.5,
    end_trim_px: float = 3.0,
) -> EdgePoints:
    """Sample intensity profiles normal to ``segment`` every ``step_px`` (bilinear, ``cv2.remap``) and
    locate the edge in each as the centroid of the gradient of the dominant polarity within ±1.5 px
    of its peak. Profiles whose peak is under a third of the median peak (occluded, ended) are dropped.
    """
    import cv2

    p1, p2 = segment[:2], segment[2:]
    length = float(np.hypot(*(p2 - p1)))
    t = (p2 - p1) / length
    n = np.array([-t[1], t[0]])
    s = np.arange(end_trim_px, length - end_trim_px + 1e-9, step_px)
    if len(s) < 3:
        return EdgePoints(np.zeros((0, 2)), np.zeros(0))
    o = np.arange(-half_width_px, half_width_px + 1e-9, PROFILE_STEP_PX)
    pts = p1 + s[:, None, None] * t + o[None, :, None] * n  # (S, O, 2)
    prof = cv2.remap(
        np.asarray(image, dtype=np.float32),
        pts[..., 0].astype(np.float32),
        pts[..., 1].astype(np.float32),
        cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_REPLICATE,
    ).astype(float)
    g = np.gradient(prof, PROFILE_STEP_PX, axis=1)
    polarity = 1.0 if np.median(g.sum(axis=1)) >= 0 else -1.0
    g = np.clip(g * polarity, 0.0, None)
    peak = g.argmax(axis=1)
    peak_val = g[np.arange(len(s)), peak]
    window = np.abs(o[None, :] - o[peak][:, None]) <= 1.5
    w = np.where(window, g, 0.0)
    wsum = w.sum(axis=1)
    ok = (wsum > 0) & (peak_val >= max(np.median(peak_val), 1e-12) / 3.0)
    ok &= (peak > 0) & (peak < len(o) - 1)  # a peak at the profile's end is a neighbour's edge
    off = (w * o).sum(axis=1) / np.where(wsum > 0, wsum, 1.0)
    uv = p1 + s[:, None] * t + off[:, None] * n
    return EdgePoints(uv[ok], polarity * peak_val[ok])


@dataclass(frozen=True)
class EdgeLine:
    """A fitted image line. ``var_offset_px2`` is the variance of its offset along ``normal`` at
    ``centroid_px``; ``var_angle_rad2`` of its angle; ``sigma_px`` the per-point scatter."""

    centroid_px: FloatArray
    direction: FloatArray
    normal: FloatArray
    sigma_px: float
    n_points: int
    n_effective: float
    half_length_px: float
    var_offset_px2: float
    var_angle_rad2: float
    inliers: int

    @property
    def abc(self) -> FloatArray:
        """The line ``a·u + b·v + c = 0`` with ``(a, b)`` the unit normal."""
        return np.array([self.normal[0], self.normal[1], -float(self.normal @ self.centroid_px)])

    @property
    def endpoints_px(self) -> FloatArray:
        """The two ends (2, 2) of the fitted support."""
        h = self.half_length_px * self.direction
        return np.array([self.centroid_px - h, self.centroid_px + h])

    @property
    def length_px(self) -> float:
        return 2.0 * self.half_length_px


def fit_line(uv_px: FloatArray, *, iterations: int = 4) -> EdgeLine | None:
    """Robust total-least-squares line through points ``uv_px`` (N, 2): Tukey weights at 4.685·σ
    (σ from the median absolute residual). The variances use the point scatter and an effective
    count ``N·(1-ρ₁)/(1+ρ₁)`` (ρ₁ the residuals' lag-1 correlation: the PSF correlates neighbours).
    None when under 5 points survive."""
    p = np.asarray(uv_px, dtype=float)
    if len(p) < 5:
        return None
    w = np.ones(len(p))
    for _ in range(iterations):
        c = (w[:, None] * p).sum(axis=0) / w.sum()
        q = p - c
        cov = (w[:, None] * q).T @ q
        _, evecs = np.linalg.eigh(cov)
        normal = evecs[:, 0]
        r = q @ normal
        scale = max(1.4826 * float(np.median(np.abs(r))), MIN_POINT_SIGMA_PX)
        z = r / (4.685 * scale)
        w = np.where(np.abs(z) < 1, (1 - z**2) ** 2, 0.0)
        if w.sum() < 5:
            return None
    keep = w > 0
    c = (w[:, None] * p).sum(axis=0) / w.sum()
    q = p - c
    _, evecs = np.linalg.eigh((w[:, None] * q).T @ q)
    normal = evecs[:, 0]
    direction = np.array([-normal[1], normal[0]])
    r = (q @ normal)[keep]
    s = (q @ direction)[keep]
    n = int(keep.sum())
    sigma = max(float(np.sqrt(np.sum(r**2) / max(n - 2, 1))), MIN_POINT_SIGMA_PX)
    order = np.argsort(s)
    rs = r[order]
    rho1 = float(np.sum(rs[1:] * rs[:-1]) / max(np.sum(rs**2), 1e-30)) if n > 3 else 0.0
    rho1 = min(max(rho1, 0.0), 0.95)
    n_eff = n * (1 - rho1) / (1 + rho1)
    scale_eff = n / n_eff
    var_offset = sigma**2 / n * scale_eff
    var_angle = sigma**2 / max(float(np.sum(s**2)), 1e-12) * scale_eff
    half = float(max(np.abs(s.min()), np.abs(s.max())))
    return EdgeLine(c, direction, normal, sigma, n, n_eff, half, var_offset, var_angle, n)


def line_intersection(l1: FloatArray, l2: FloatArray) -> FloatArray | None:
    """The image point (2,) where two lines ``abc`` meet; None when they are parallel."""
    x = np.cross(l1, l2)
    if abs(x[2]) < 1e-12:
        return None
    return np.asarray(x[:2] / x[2], dtype=float)
