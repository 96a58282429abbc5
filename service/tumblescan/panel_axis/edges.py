"""Edges of the target: LSD on the grayscale image inside the target's box, each segment refined to
sub-pixel edge points and a robust line with its own σ, then back-projected to a plane."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._typing import FloatArray
from ..imaging.camera import PinholeCamera
from ..imaging.lines import EdgeLine, detect_segments, edge_points, fit_line
from .axis import PlaneObs, line_plane
from .segment import Target

MIN_SEGMENT_PX = 15.0
MAX_POINT_SIGMA_PX = 1.0
BOX_MARGIN_PX = 8


@dataclass(frozen=True)
class Edge:
    """One refined edge: the LSD ``segment_px`` (x1, y1, x2, y2, measured pixels), the fitted
    ``line`` in ideal (undistorted) pixels, and its ``plane`` through the camera."""

    segment_px: FloatArray
    line: EdgeLine
    plane: PlaneObs

    @property
    def length_px(self) -> float:
        return self.line.length_px

    @property
    def angle_rad(self) -> float:
        """Image direction in [0, π)."""
        return float(np.arctan2(self.line.direction[1], self.line.direction[0]) % np.pi)


def find_edges(gray: FloatArray, target: Target, camera: PinholeCamera) -> list[Edge]:
    """LSD segments of at least 15 px inside the target's box, refined (see module docstring)."""
    u0, v0, u1, v1 = target.bbox_px
    H, W = gray.shape
    u0, v0 = max(u0 - BOX_MARGIN_PX, 0), max(v0 - BOX_MARGIN_PX, 0)
    u1, v1 = min(u1 + BOX_MARGIN_PX, W - 1), min(v1 + BOX_MARGIN_PX, H - 1)
    segments = detect_segments(target.gray8[v0 : v1 + 1, u0 : u1 + 1], MIN_SEGMENT_PX)
    segments = segments + np.array([u0, v0, u0, v0], dtype=float)
    edges = []
    for seg in segments:
        pts = edge_points(gray, seg)
        if len(pts.uv_px) < 5:
            continue
        line = fit_line(camera.undistort(pts.uv_px))
        if line is None or line.sigma_px > MAX_POINT_SIGMA_PX or line.length_px < MIN_SEGMENT_PX * 0.5:
            continue
        edges.append(Edge(seg, line, line_plane(camera, line)))
    return edges


@dataclass(frozen=True)
class Family:
    """Edges whose 3D lines share a direction (``direction`` from the RANSAC hypothesis refit)."""

    edges: list[Edge]
    direction: FloatArray

    @property
    def total_length_px(self) -> float:
        return float(sum(e.length_px for e in self.edges))

    def image_direction(self) -> FloatArray:
        """Length-weighted mean image direction (2,) of the family's lines (as an axis)."""
        a = np.array([2 * e.angle_rad for e in self.edges])
        w = np.array([e.length_px for e in self.edges])
        m = np.arctan2((w * np.sin(a)).sum(), (w * np.cos(a)).sum()) / 2
        return np.array([np.cos(m), np.sin(m)])


def group_families(edges: list[Edge], camera: PinholeCamera, *, max_families: int = 4) -> list[Family]:
    """Families of parallel 3D lines by RANSAC over every pair of the 30 longest edges: a pair of
    planes proposes ``d = n_i × n_j``; an edge agrees when its image direction is within 1.5° of
    the line from its centroid to the vanishing point ``K·d`` (an image test: a hypothesis from two
    close lines is poor in depth but fine in the image); the hypothesis with the most agreeing
    length wins, is refitted on its edges, and they leave the pool."""
    from .axis import fit_direction

    pool = sorted(edges, key=lambda e: -e.length_px)
    families: list[Family] = []
    while len(pool) >= 2 and len(families) < max_families:
        top = pool[:30]
        pairs = [(i, j) for i in range(len(top)) for j in range(i + 1, len(top))]
        C = np.array([e.line.centroid_px for e in pool])
        T = np.array([e.line.direction for e in pool])
        lengths = np.array([e.length_px for e in pool])
        Ntop = np.array([e.plane.normal for e in top])
        ij = np.array(pairs)
        D = np.cross(Ntop[ij[:, 0]], Ntop[ij[:, 1]])
        nd = np.linalg.norm(D, axis=1)
        D = D[nd > 1e-12] / nd[nd > 1e-12, None]
        if len(D) == 0:
            break
        agree = _agree(C, T, D @ camera.K.T)  # (hypotheses, edges)
        scores = agree.astype(float) @ lengths
        best = int(np.argmax(scores))
        best_in = agree[best]
        if best_in.sum() < 2:
            break
        members = [e for e, k in zip(pool, best_in, strict=True) if k]
        d = fit_direction([e.plane for e in members]).direction
        families.append(Family(members, d))
        pool = [e for e, k in zip(pool, best_in, strict=True) if not k]
    return families


AGREE_SIN = np.sin(np.radians(1.5))


def _agree(C: FloatArray, T: FloatArray, V: FloatArray) -> np.ndarray:
    """(H, M): whether edge m (centroid C[m], direction T[m]) points at vanishing point V[h] (homogeneous)."""
    # Direction from each centroid toward v (a point, or a direction when v_h[2] ~ 0).
    tx = V[:, None, 0] - C[None, :, 0] * V[:, None, 2]
    ty = V[:, None, 1] - C[None, :, 1] * V[:, None, 2]
    norm = np.hypot(tx, ty)
    cross = np.abs(tx * T[None, :, 1] - ty * T[None, :, 0])
    return np.asarray(cross < AGREE_SIN * np.maximum(norm, 1e-300))
