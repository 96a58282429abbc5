"""Weak perspective: the panel axis up to its mirror twin, from one wing's 4 corners and the panel size.

When the target is far, every edge's plane passes (nearly) through it and their intersection is
the line of sight. A rectangle of known size still fixes the pose up to the two-fold planar
ambiguity, which IPPE (Collins & Bartoli 2014, ``cv2.SOLVEPNP_IPPE``) returns explicitly. The
corners are where the wing's two long edges (rails) meet its end edges.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._typing import FloatArray
from ..imaging.camera import PinholeCamera
from ..imaging.lines import line_intersection
from .edges import Edge, Family

RAIL_TOLERANCE_PX = 2.5
END_SEARCH_PX = 6.0
MONTE_CARLO = 40


@dataclass(frozen=True)
class PoseCandidate:
    """One IPPE solution: the axis and panel normal (camera frame), its reprojection rms (px) and
    the axis covariance in ``basis`` (2, 3) from corner noise (Monte Carlo)."""

    axis_cam: FloatArray
    normal_cam: FloatArray
    cost_px: float
    cov_tangent_rad2: FloatArray
    basis: FloatArray


def wing_corners(family: Family, edges: list[Edge]) -> list[tuple[FloatArray, float]]:
    """Candidate corner sets (4, 2) of a wing, each ordered rail A start/end, rail B end/start
    (along the axis family's image direction), with their σ (px), most likely first: the longest
    rails (a wing's long edges) and their longest covered intervals first."""
    a = family.image_direction()
    b = np.array([-a[1], a[0]])
    rails = _rails(family.edges, b)
    rails.sort(key=lambda r: -sum(e.length_px for e in r))
    span = _span(family.edges, a)
    tol = 0.03 * span
    members = {id(e) for e in family.edges}
    cross = [e for e in edges if id(e) not in members and _angle_diff(e, a) > np.radians(20)]
    out = []
    for ka, rail_a in enumerate(rails[:3]):
        off_a = _offset(rail_a, b)
        for rail_b in rails[ka + 1 : 4]:
            if abs(_offset(rail_b, b) - off_a) <= 3.0:
                continue
            line_a, line_b = _rail_line(rail_a), _rail_line(rail_b)
            sig = [e.line.sigma_px for e in rail_a + rail_b]
            sigma = max(0.3, 2.0 * float(np.median(sig)))
            for ia in sorted(_merged(rail_a, a, tol), key=lambda iv: iv[0] - iv[1]):
                for ib in sorted(_merged(rail_b, a, tol), key=lambda iv: iv[0] - iv[1]):
                    overlap = min(ib[1], ia[1]) - max(ib[0], ia[0])
                    if overlap < 0.5 * min(ia[1] - ia[0], ib[1] - ib[0]) or min(ia[1] - ia[0], ib[1] - ib[0]) < 10:
                        continue
                    corners = np.array(
                        [
                            _corner(line_a, ia[0], a, cross),
                            _corner(line_a, ia[1], a, cross),
                            _corner(line_b, ib[1], a, cross),
                            _corner(line_b, ib[0], a, cross),
                        ]
                    )
                    out.append((corners, sigma))
    return out


def best_wing(
    sets: list[tuple[FloatArray, float]],
    length_m: float,
    width_m: float,
    camera: PinholeCamera,
    range_m: float | None = None,
) -> tuple[FloatArray, float, float] | None:
    """The first corner set (in the given order) that an L x W rectangle fits within 1 px rms and,
    with a range prior, at a depth within 10 % of it; else the best-fitting one. Returns
    (corners, σ, reprojection rms px). Four points of a parallelogram fit a rectangle of the wrong
    length by tilting it, so the fit alone cannot rank the sets: the order does."""
    best = None
    for corners, sigma in sets:
        sols = _solve(corners, length_m, width_m, camera)
        if not sols:
            continue
        cost = min(c for _, _, c, _ in sols)
        depth_ok = range_m is None or all(abs(z / range_m - 1) < 0.1 for _, _, _, z in sols)
        if cost <= 1.0 and depth_ok:
            return corners, sigma, cost
        if depth_ok and (best is None or cost < best[2]):
            best = (corners, sigma, cost)
    return best


def ippe_candidates(
    corners_px: FloatArray,
    length_m: float,
    width_m: float,
    camera: PinholeCamera,
    sigma_px: float,
    rng: np.random.Generator,
) -> list[PoseCandidate]:
    """Both IPPE poses of the wing rectangle (length along model x), best first. Their covariance
    comes from redoing IPPE on corners perturbed by ``sigma_px`` (Monte Carlo)."""
    base = _solve(corners_px, length_m, width_m, camera)
    if not base:
        return []
    samples: list[list[FloatArray]] = [[] for _ in base]
    for _ in range(MONTE_CARLO):
        noisy = _solve(corners_px + rng.normal(0, sigma_px, corners_px.shape), length_m, width_m, camera)
        for k, (ax, *_) in enumerate(base):
            if noisy:
                near = max(noisy, key=lambda s: abs(float(s[0] @ ax)))
                samples[k].append(near[0] * np.sign(near[0] @ ax))
    out = []
    for k, (ax, nrm, cost, _) in enumerate(base):
        basis = _basis(ax)
        dev = np.array([basis @ (s - ax) for s in samples[k]]) if samples[k] else np.zeros((0, 2))
        cov = np.cov(dev.T) if len(dev) > 2 else np.eye(2)
        out.append(PoseCandidate(ax, nrm, cost, np.atleast_2d(cov), basis))
    return sorted(out, key=lambda c: c.cost_px)


def _solve(
    corners: FloatArray, L: float, W: float, camera: PinholeCamera
) -> list[tuple[FloatArray, FloatArray, float, float]]:
    """IPPE's poses: (axis, normal, reprojection rms px, depth m) each."""
    import cv2

    obj = np.array([[0, 0, 0], [L, 0, 0], [L, W, 0], [0, W, 0]], dtype=np.float64)
    try:
        n, rvecs, tvecs, errs = cv2.solvePnPGeneric(
            obj, np.ascontiguousarray(corners, dtype=np.float64), camera.K, None, flags=cv2.SOLVEPNP_IPPE
        )
    except cv2.error:
        return []
    out = []
    for k in range(n):
        R, _ = cv2.Rodrigues(rvecs[k])
        cost = float(np.ravel(errs)[k]) if errs is not None else 0.0
        depth = float(np.ravel(tvecs[k])[2])
        out.append((np.asarray(R[:, 0], dtype=float), np.asarray(R[:, 2], dtype=float), cost, depth))
    return out


def _basis(d: FloatArray) -> FloatArray:
    helper = np.array([1.0, 0, 0]) if abs(d[0]) < 0.9 else np.array([0, 1.0, 0])
    e1 = np.cross(d, helper)
    e1 /= np.linalg.norm(e1)
    return np.vstack([e1, np.cross(d, e1)])


def _offset(rail: list[Edge], b: FloatArray) -> float:
    w = np.array([e.length_px for e in rail])
    return float(np.sum(w * np.array([b @ e.line.centroid_px for e in rail])) / w.sum())


def _rails(edges: list[Edge], b: FloatArray) -> list[list[Edge]]:
    """Edges on one image line, by their offset across the axis."""
    rails: list[list[Edge]] = []
    for e in sorted(edges, key=lambda e: float(b @ e.line.centroid_px)):
        if rails and b @ e.line.centroid_px - _offset(rails[-1], b) <= RAIL_TOLERANCE_PX:
            rails[-1].append(e)
        else:
            rails.append([e])
    return rails


def _span(edges: list[Edge], a: FloatArray) -> float:
    s = np.array([a @ p for e in edges for p in e.line.endpoints_px])
    return float(np.ptp(s))


def _merged(rail: list[Edge], a: FloatArray, tol: float) -> list[tuple[float, float]]:
    """Along-axis intervals covered by the rail's edges, merging gaps under ``tol`` px."""
    ivs = sorted(tuple(sorted(float(a @ p) for p in e.line.endpoints_px)) for e in rail)
    out = [list(ivs[0])]
    for lo, hi in ivs[1:]:
        if lo <= out[-1][1] + tol:
            out[-1][1] = max(out[-1][1], hi)
        else:
            out.append([lo, hi])
    return [(lo, hi) for lo, hi in out]


def _rail_line(rail: list[Edge]) -> FloatArray:
    return max(rail, key=lambda e: e.length_px).line.abc


def _angle_diff(e: Edge, a: FloatArray) -> float:
    return float(np.arccos(min(1.0, abs(float(e.line.direction @ a)))))


def _corner(rail_abc: FloatArray, s: float, a: FloatArray, cross: list[Edge]) -> FloatArray:
    """The rail's point at along-coordinate ``s``, moved to where an end edge crosses the rail
    when one crosses within 6 px."""
    n = rail_abc[:2]
    p0 = -rail_abc[2] * n  # foot of the rail line from the origin
    t = np.array([-n[1], n[0]])
    t = t if t @ a >= 0 else -t
    guess = p0 + (s - a @ p0) / (t @ a) * t
    best, best_d = guess, END_SEARCH_PX
    for e in cross:
        x = line_intersection(rail_abc, e.line.abc)
        if x is None:
            continue
        d = float(np.linalg.norm(x - guess))
        ends = e.line.endpoints_px
        seg_gap = _point_segment_distance(x, ends[0], ends[1])
        if d < best_d and seg_gap < END_SEARCH_PX:
            best, best_d = x, d
    return np.asarray(best, dtype=float)


def _point_segment_distance(p: FloatArray, a: FloatArray, b: FloatArray) -> float:
    ab = b - a
    t = float(np.clip(float((p - a) @ ab) / max(float(ab @ ab), 1e-12), 0, 1))
    return float(np.linalg.norm(p - (a + t * ab)))
