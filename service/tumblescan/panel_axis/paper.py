"""The paper's pipeline as written (Song et al. 2020, §2): Otsu mask, LSD on the binary mask, the
two longest (nearly parallel, distinct) edges along the mask's elongation (our reading of its
"length, slope and end-point constraints"), and the intersection of their planes ``n_1 × n_2``.
No σ. The short centre line L″ comes the same way from the two longest edges across the axis."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._typing import FloatArray
from ..imaging.camera import PinholeCamera
from ..imaging.lines import detect_segments
from .errors import NoTargetError, TooFewEdgesError
from .segment import MIN_TARGET_PX, to_8bit

PARALLEL_DEG = 10.0
DISTINCT_PX = 3.0
SLOPE_DEG = 20.0


@dataclass(frozen=True)
class PaperFit:
    axis_cam: FloatArray
    short_cam: FloatArray | None
    edges_px: FloatArray  # the segments used (k, 4)
    threshold: float
    target_px: int


def estimate_paper(gray: FloatArray, camera: PinholeCamera, min_line_px: float) -> PaperFit:
    import cv2

    gray8 = to_8bit(gray)
    thr, mask = cv2.threshold(gray8, 0, 255, cv2.THRESH_BINARY | cv2.THRESH_OTSU)
    target_px = int(np.count_nonzero(mask))
    if target_px < MIN_TARGET_PX:
        raise NoTargetError(f"image: no target ({target_px} px over Otsu's threshold)", field="image")
    seg = detect_segments(mask, min_line_px)
    if len(seg) < 2:
        raise TooFewEdgesError(f"image: {len(seg)} edges of {min_line_px:.0f} px or more on the mask", field="image")
    seg = seg[np.argsort(-np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1]))]
    # The paper's "slope constraint" (its rules are not given): long edges run along the target's
    # principal elongation.
    vs, us = np.nonzero(mask)
    q = np.column_stack([us, vs]).astype(float)
    q -= q.mean(axis=0)
    principal = np.linalg.eigh(q.T @ q)[1][:, 1]
    along = seg[[_angle(s, np.array([0.0, 0.0, *principal])) < SLOPE_DEG for s in seg]]
    if len(along) >= 2:
        seg = np.vstack([along, seg[[_angle(s, np.array([0.0, 0.0, *principal])) >= SLOPE_DEG for s in seg]]])
    pair = _pair(seg, seg[0], parallel=True)
    if pair is None:
        raise TooFewEdgesError("image: no second long edge parallel to the longest", field="image")
    axis = _intersect(camera, pair)
    across = [s for s in seg if _angle(s, seg[0]) > 45.0]
    short = None
    if len(across) >= 2:
        p2 = _pair(np.array(across), across[0], parallel=True)
        if p2 is not None:
            short = _intersect(camera, p2)
    return PaperFit(axis, short, np.array(pair), float(thr), target_px)


def _pair(seg: FloatArray, first: FloatArray, *, parallel: bool) -> list[FloatArray] | None:
    for s in seg[1:]:
        if _angle(s, first) < PARALLEL_DEG and _distance(first, s) > DISTINCT_PX:
            return [first, s]
    return None


def _intersect(camera: PinholeCamera, pair: list[FloatArray]) -> FloatArray:
    normals = []
    for s in pair:
        p = camera.undistort(s.reshape(2, 2))
        line = np.cross([p[0, 0], p[0, 1], 1.0], [p[1, 0], p[1, 1], 1.0])
        normals.append(camera.plane_normal(line))
    d = np.cross(normals[0], normals[1])
    return np.asarray(d / np.linalg.norm(d), dtype=float)


def _angle(a: FloatArray, b: FloatArray) -> float:
    ta = np.arctan2(a[3] - a[1], a[2] - a[0])
    tb = np.arctan2(b[3] - b[1], b[2] - b[0])
    d = abs(ta - tb) % np.pi
    return float(np.degrees(min(d, np.pi - d)))


def _distance(a: FloatArray, b: FloatArray) -> float:
    """Distance from b's midpoint to a's line (px)."""
    t = a[2:] - a[:2]
    n = np.array([-t[1], t[0]]) / np.linalg.norm(t)
    return float(abs(n @ ((b[:2] + b[2:]) / 2 - a[:2])))
