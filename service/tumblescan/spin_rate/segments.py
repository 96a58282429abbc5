"""Straight edges on the target in each frame: LSD, collinear fragments merged, each refined to a
sub-pixel line from edge profiles (``imaging.lines``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._typing import FloatArray
from ..imaging.lines import detect_segments, edge_points, fit_line
from .target import TargetMask

MIN_LENGTH_PX = 10.0
MASK_MARGIN_PX = 4


@dataclass(frozen=True)
class Segments:
    """One frame's segments: ends (N, 2, 2) in px, and the per-point scatter of each fitted edge."""

    ends_px: FloatArray
    sigma_px: FloatArray

    def __len__(self) -> int:
        return len(self.ends_px)


def frame_segments(
    gray: FloatArray, gray8: np.ndarray, target: TargetMask, min_length_px: float = MIN_LENGTH_PX
) -> Segments:
    """LSD segments of ``gray8`` whose middle lies on the (dilated) target mask, collinear fragments
    merged, each refitted on ``gray`` (robust line through sub-pixel edge points)."""
    import cv2

    if target.mask is None:
        return Segments(np.zeros((0, 2, 2)), np.zeros(0))
    seg = detect_segments(gray8, min_length_px * 0.6).reshape(-1, 2, 2)
    near = cv2.dilate(target.mask.astype(np.uint8), np.ones((2 * MASK_MARGIN_PX + 1,) * 2, np.uint8)) > 0
    mid = seg.mean(axis=1)
    H, W = near.shape
    iu = np.clip(np.rint(mid[:, 0]).astype(int), 0, W - 1)
    iv = np.clip(np.rint(mid[:, 1]).astype(int), 0, H - 1)
    seg = merge_collinear(seg[near[iv, iu]])
    ends, sigmas = [], []
    for s in seg:
        if np.linalg.norm(s[1] - s[0]) < min_length_px:
            continue
        pts = edge_points(gray, s.ravel(), step_px=1.0, end_trim_px=2.0)
        line = fit_line(pts.uv_px)
        if line is None or line.length_px < 0.6 * min_length_px:
            continue
        ends.append(line.endpoints_px)
        sigmas.append(line.sigma_px)
    if not ends:
        return Segments(np.zeros((0, 2, 2)), np.zeros(0))
    return Segments(np.array(ends), np.array(sigmas))


def merge_collinear(seg: FloatArray, angle_deg: float = 2.0, offset_px: float = 1.0, gap_px: float = 6.0) -> FloatArray:
    """Join segments (N, 2, 2) that lie on one line (angle, perpendicular offset) with a gap under
    ``gap_px`` between them, greedily, longest first."""
    if len(seg) < 2:
        return seg
    order = np.argsort(-np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1))
    out: list[FloatArray] = []
    for s in seg[order]:
        for k, o in enumerate(out):
            t = o[1] - o[0]
            L = float(np.linalg.norm(t))
            t = t / L
            n = np.array([-t[1], t[0]])
            ts = s[1] - s[0]
            ts = ts / np.linalg.norm(ts)
            if abs(float(t @ ts)) < np.cos(np.radians(angle_deg)):
                continue
            if np.max(np.abs((s - o[0]) @ n)) > offset_px:
                continue
            a = sorted([0.0, L])
            b = sorted(((s - o[0]) @ t).tolist())
            gap = max(b[0] - a[1], a[0] - b[1])
            if gap > gap_px:
                continue
            lo, hi = min(a[0], b[0]), max(a[1], b[1])
            out[k] = np.array([o[0] + lo * t, o[0] + hi * t])
            break
        else:
            out.append(s.copy())
    return np.array(out)
