"""The target region: a threshold ``min(Otsu, background median + 6·σ_MAD)``, connected components,
stars dropped, and the region's principal elongation and projected wing width."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._typing import BoolArray, FloatArray
from .errors import NoTargetError

MIN_TARGET_PX = 200
MIN_BLOB_PX = 60
TIP_FRACTION = 0.2


@dataclass(frozen=True)
class Target:
    """``gray8`` the 8-bit image LSD sees; ``mask`` the kept blobs; ``bbox_px`` (u0, v0, u1, v1);
    ``direction`` the unit principal elongation (image), ``elongation`` √(λ1/λ2) of the pixel
    spread; ``tip_width_px`` the larger median width, across ``direction``, of the two outer 20 %
    of the region (the wing tips)."""

    gray8: np.ndarray
    mask: BoolArray
    threshold: float
    target_px: int
    bbox_px: tuple[int, int, int, int]
    direction: FloatArray
    elongation: float
    tip_width_px: float
    touches_border: bool
    saturated_px: int


def to_8bit(gray: FloatArray) -> np.ndarray:
    """8-bit images stay as they are; deeper ones are scaled so the 99.99th percentile is 255."""
    top = float(gray.max())
    if top <= 255:
        return np.asarray(gray, dtype=np.uint8)
    hi = max(float(np.percentile(gray, 99.99)), 1.0)
    return np.asarray(np.clip(gray * (255.0 / hi), 0, 255), dtype=np.uint8)


def find_target(gray: FloatArray, full_scale: float) -> Target:
    """Segment the target; ``NoTargetError`` when its largest blob is under 200 px."""
    import cv2

    gray8 = to_8bit(gray)
    otsu, _ = cv2.threshold(gray8, 0, 255, cv2.THRESH_BINARY | cv2.THRESH_OTSU)
    sky, sigma = _sky(gray8)
    med = float(np.median(sky))
    # Dark panels can fall under Otsu's bus/panel split, so 6σ over the sky caps it; the floor
    # keeps a blank sky from passing for a target.
    thr = max(min(float(otsu), med + 6.0 * sigma), med + 4.0 * sigma + 2.0)
    raw = (gray8.astype(np.float32) - (sky - med).astype(np.float32) > thr).astype(np.uint8)
    # Bridge thin yokes and blur gaps, then keep blobs that are not stars.
    joined = cv2.dilate(raw, np.ones((3, 3), np.uint8))
    n, labels, stats, _ = cv2.connectedComponentsWithStats(joined, connectivity=8)
    areas = stats[1:, cv2.CC_STAT_AREA] if n > 1 else np.zeros(0, int)
    if len(areas) == 0 or areas.max() < MIN_TARGET_PX:
        biggest = int(areas.max()) if len(areas) else 0
        raise NoTargetError(f"image: no target (largest blob {biggest} px, under {MIN_TARGET_PX} px)", field="image")
    keep = 1 + np.flatnonzero(areas >= max(MIN_BLOB_PX, 0.05 * areas.max()))
    lut = np.zeros(n, bool)
    lut[keep] = True
    mask = lut[labels] & (raw > 0)
    vs, us = np.nonzero(mask)
    H, W = gray.shape
    bbox = (int(us.min()), int(vs.min()), int(us.max()), int(vs.max()))
    touches = bbox[0] <= 1 or bbox[1] <= 1 or bbox[2] >= W - 2 or bbox[3] >= H - 2
    direction, elongation, tip = _shape(us.astype(float), vs.astype(float))
    saturated = int(np.count_nonzero(gray[mask] >= full_scale))
    return Target(gray8, mask, thr, len(us), bbox, direction, elongation, tip, touches, saturated)


def _sky(gray8: np.ndarray, border_px: int = 8) -> tuple[FloatArray, float]:
    """The sky as a plane fitted to the image's border strips (two passes, dropping stars), and
    the noise σ about it (MAD)."""
    H, W = gray8.shape
    b = border_px
    strips = [
        (slice(0, b), slice(0, W)),
        (slice(H - b, H), slice(0, W)),
        (slice(b, H - b), slice(0, b)),
        (slice(b, H - b), slice(W - b, W)),
    ]
    us, vs, ys = [], [], []
    for rows, cols in strips:
        vv, uu = np.mgrid[rows, cols]
        us.append(uu.ravel()[::3])  # every third pixel is plenty for three coefficients
        vs.append(vv.ravel()[::3])
        ys.append(gray8[rows, cols].ravel()[::3])
    A = np.column_stack([np.concatenate(us), np.concatenate(vs), np.ones(sum(len(u) for u in us))]).astype(float)
    y = np.concatenate(ys).astype(float)
    keep = np.ones(len(y), bool)
    coef = np.zeros(3)
    sigma = 1.0
    for _ in range(2):
        coef = np.linalg.lstsq(A[keep], y[keep], rcond=None)[0]
        r = y - A @ coef
        sigma = max(1.4826 * float(np.median(np.abs(r[keep] - np.median(r[keep])))), 0.5)
        keep = np.abs(r) < 4 * sigma + 1
    plane = coef[0] * np.arange(W)[None, :] + coef[1] * np.arange(H)[:, None] + coef[2]
    return plane, sigma


def _shape(us: FloatArray, vs: FloatArray) -> tuple[FloatArray, float, float]:
    """Principal direction, elongation and tip width of a pixel set."""
    p = np.column_stack([us, vs])
    q = p - p.mean(axis=0)
    evals, evecs = np.linalg.eigh(q.T @ q / len(q))
    direction = evecs[:, 1]
    elongation = float(np.sqrt(evals[1] / max(evals[0], 1e-9)))
    along = q @ direction
    across = q @ np.array([-direction[1], direction[0]])
    lo, hi = along.min(), along.max()
    span = hi - lo
    widths = []
    for a0, a1 in ((lo, lo + TIP_FRACTION * span), (hi - TIP_FRACTION * span, hi)):
        sel = (along >= a0) & (along <= a1)
        if sel.sum() < 10:
            continue
        bins = np.floor(along[sel]).astype(int)
        order = np.argsort(bins)
        b, x = bins[order], across[sel][order]
        cuts = np.flatnonzero(np.diff(b)) + 1
        per_bin = [float(np.ptp(c)) + 1.0 for c in np.split(x, cuts) if len(c)]
        widths.append(float(np.median(per_bin)))
    return direction, elongation, max(widths) if widths else 0.0
