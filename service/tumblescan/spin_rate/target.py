"""Where the target is in each frame: a mask from the sky level and the noise, its largest blob."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._typing import FloatArray

MIN_TARGET_AREA_PX = 150
SIGMA_THRESHOLD = 6.0


@dataclass(frozen=True)
class TargetMask:
    """The target's pixels in one frame (None when not found) and what the estimator needs of them."""

    mask: np.ndarray | None
    area_px: int
    centroid_px: FloatArray | None
    bbox: tuple[int, int, int, int] | None  # u0, v0, u1, v1 (inclusive)
    touches_border: bool
    saturated: bool
    sky_dn: float
    noise_dn: float

    @property
    def found(self) -> bool:
        return self.mask is not None


def find_target(gray: FloatArray, full_scale: float, polarity: str = "bright") -> TargetMask:
    """The largest blob above ``sky + max(6 σ_noise, 1.2 % of full scale)`` after a 5x5 closing
    (the sky level is the median, σ the scaled MAD); None under ``MIN_TARGET_AREA_PX`` pixels."""
    import cv2

    img = gray if polarity == "bright" else full_scale - gray
    sky = float(np.median(img))
    noise = max(1.4826 * float(np.median(np.abs(img - sky))), 1e-6)
    thr = sky + max(SIGMA_THRESHOLD * noise, 0.012 * full_scale)
    binary = cv2.morphologyEx((img > thr).astype(np.uint8), cv2.MORPH_CLOSE, np.ones((5, 5), np.uint8))
    n, labels, stats, centroids = cv2.connectedComponentsWithStats(binary, connectivity=8)
    if n <= 1:
        return TargetMask(None, 0, None, None, False, False, sky, noise)
    best = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    area = int(stats[best, cv2.CC_STAT_AREA])
    if area < MIN_TARGET_AREA_PX:
        return TargetMask(None, area, None, None, False, False, sky, noise)
    mask = labels == best
    x, y, w, h = (
        int(stats[best, k]) for k in (cv2.CC_STAT_LEFT, cv2.CC_STAT_TOP, cv2.CC_STAT_WIDTH, cv2.CC_STAT_HEIGHT)
    )
    H, W = gray.shape
    border = x == 0 or y == 0 or x + w >= W or y + h >= H
    saturated = bool(np.mean(gray[mask] >= full_scale) > 0.01)
    return TargetMask(mask, area, np.asarray(centroids[best], dtype=float), (x, y, x + w - 1, y + h - 1), border,
                      saturated, sky, noise)  # fmt: skip


def to_gray8(gray: FloatArray, target: TargetMask, full_scale: float, polarity: str = "bright") -> np.ndarray:
    """An 8-bit image for LSD: the sky at 0 and the target's 99.5th percentile at 230."""
    img = gray if polarity == "bright" else full_scale - gray
    top = float(np.percentile(img[target.mask], 99.5)) if target.mask is not None else float(img.max())
    scale = 230.0 / max(top - target.sky_dn, 1e-6)
    return np.asarray(np.clip((img - target.sky_dn) * scale, 0, 255), dtype=np.uint8)
