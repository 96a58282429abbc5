"""Weak perspective: the panel axis up to its mirror twin, from one wing's 4 corners and the panel size.

When the target is far, every edge's plane passes (nearly) through it and their intersection is
the line of sight. A rectangle of known size still fixes the pose up to the two-fold planar
ambiguity, which IPPE (Collins & Bartoli 2014, ``cv2.SOLVEPNP_IPPE``) returns explicitly. The
corners are where the wing's two long edges (rails) meet its end edges.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from .._typing import FloatArray
from ..geometry.rotations import tangent_basis
from ..imaging.camera import PinholeCamera
from ..imaging.lines import line_intersection
from .edges import Edge, Family

RAIL_TOLERANCE_PX = 2.5
END_SEARCH_PX = 6.0
MONTE_CARLO = 40
MAX_TIP_SCALE = 1.1  # a tip over 1.1x the prior's width at the prior's range cannot be the wing's tip
MIN_ROOT_SCALE = 0.05  # projected over true wing length under which the tip cannot be a wing's
ROOT_MIN_HIDDEN_PX = 3.0  # a root this far beyond the visible rail ends must be hidden by the target


@dataclass(frozen=True)
class CornerSet:
    """A wing's 4 image corners (4, 2) px, ordered rail A start/end, rail B end/start (along the
    axis family's image direction), and their σ (px). ``rebuild`` is set when two corners are derived
    from the other two (a root hidden behind the bus): it maps perturbed corners to a consistent set,
    so the Monte Carlo perturbs what was measured."""

    corners_px: FloatArray
    sigma_px: float
    rebuild: Callable[[FloatArray], FloatArray | None] | None = None


@dataclass(frozen=True)
class PoseCandidate:
    """One IPPE solution: the axis and panel normal (camera frame), its reprojection rms (px) and
    the axis covariance in ``basis`` (2, 3) from corner noise (Monte Carlo)."""

    axis_cam: FloatArray
    normal_cam: FloatArray
    cost_px: float
    cov_tangent_rad2: FloatArray
    basis: FloatArray


@dataclass(frozen=True)
class _RailPair:
    """Two rails (a wing's long edges, fitted lines ``line_a``, ``line_b``) and an interval of each
    along the image axis ``a`` that overlap: the candidate long sides of one wing. ``cross``: the
    edges across the axis, which close the corners; ``sigma`` the corner sigma [px]."""

    a: FloatArray
    line_a: FloatArray
    line_b: FloatArray
    ia: tuple[float, float]
    ib: tuple[float, float]
    cross: list[Edge]
    sigma: float

    def corner(self, on_b: bool, at: float) -> FloatArray:
        return _corner(self.line_b if on_b else self.line_a, at, self.a, self.cross)


def _rail_pairs(family: Family, edges: list[Edge]) -> Iterator[_RailPair]:
    """The rail pairs of ``family``, most likely first: the longest rails and their longest
    covered intervals first."""
    a = family.image_direction()
    b = np.array([-a[1], a[0]])
    rails = _rails(family.edges, b)
    rails.sort(key=lambda r: -sum(e.length_px for e in r))
    tol = 0.03 * _span(family.edges, a)
    members = {id(e) for e in family.edges}
    cross = [e for e in edges if id(e) not in members and _angle_diff(e, a) > np.radians(20)]
    for ka, rail_a in enumerate(rails[:3]):
        for rail_b in rails[ka + 1 : 4]:
            if abs(_offset(rail_b, b) - _offset(rail_a, b)) <= 3.0:
                continue
            line_a, line_b = _rail_line(rail_a), _rail_line(rail_b)
            sigma = max(0.3, 2.0 * float(np.median([e.line.sigma_px for e in rail_a + rail_b])))
            for ia in sorted(_merged(rail_a, a, tol), key=lambda iv: iv[0] - iv[1]):
                for ib in sorted(_merged(rail_b, a, tol), key=lambda iv: iv[0] - iv[1]):
                    overlap = min(ib[1], ia[1]) - max(ib[0], ia[0])
                    if overlap < 0.5 * min(ia[1] - ia[0], ib[1] - ib[0]) or min(ia[1] - ia[0], ib[1] - ib[0]) < 10:
                        continue
                    yield _RailPair(a, line_a, line_b, ia, ib, cross, sigma)


def wing_corners(family: Family, edges: list[Edge]) -> list[CornerSet]:
    """Candidate corner sets of a wing (see ``CornerSet``), most likely first (``_rail_pairs``)."""
    return [
        CornerSet(
            np.array(
                [
                    p.corner(False, p.ia[0]),
                    p.corner(False, p.ia[1]),
                    p.corner(True, p.ib[1]),
                    p.corner(True, p.ib[0]),
                ]
            ),
            p.sigma,
        )
        for p in _rail_pairs(family, edges)
    ]


def hidden_root_corners(
    family: Family,
    edges: list[Edge],
    mask: np.ndarray,
    length_m: float,
    width_m: float,
    px_per_m: float,
) -> list[CornerSet]:
    """Corner sets of wings whose root (the end at the bus) is hidden behind the bus, in the order of
    ``wing_corners``. The tip's two corners are measured; the root's are derived from them, the
    rails' image direction ``a`` and the prior (a scaled orthographic view at ``px_per_m`` = f/range,
    which weak perspective is). With the tip edge's image vector ``w`` and ``e = w/(px_per_m·W)``,
    the projected unit axis is ``x·a`` and the unit short direction ``e``; both are columns of a
    rotation, so ``|e|² + e_z² = 1``, ``x² + d_z² = 1`` and ``x(a·e) + d_z e_z = 0``, whence
    ``x² = (1 − |e|²)/(1 − |e|² + (a·e)²)`` and the root lies ``x·px_per_m·L`` px from the tip. A
    set is kept when the root is not short of the visible rail ends and, where it lies beyond them,
    the target (the bus) covers it, as it must if it is hidden. ``mask`` (H, W) bool: the target."""
    a = family.image_direction()
    ends = np.array([a @ p for e in family.edges for p in e.line.endpoints_px])
    mid = float(ends.min() + ends.max()) / 2  # the bus is between the wings
    out = []
    for p in _rail_pairs(family, edges):
        ia, ib = p.ia, p.ib
        # Both tips on one side of the bus: the ends farther from the middle.
        side = np.sign((ia[0] + ia[1]) / 2 - mid)
        if side == 0 or side != np.sign((ib[0] + ib[1]) / 2 - mid):
            continue
        hi = side > 0
        tip_a = p.corner(False, ia[1] if hi else ia[0])
        tip_b = p.corner(True, ib[1] if hi else ib[0])
        toward_root = -side * a

        def rebuild(c: FloatArray, hi: bool = hi, r: FloatArray = toward_root) -> FloatArray | None:
            ta, tb = (c[1], c[2]) if hi else (c[0], c[3])
            return _with_root(ta, tb, a, r, hi, length_m, width_m, px_per_m)

        corners = _with_root(tip_a, tip_b, a, toward_root, hi, length_m, width_m, px_per_m)
        if corners is None:
            continue
        root_a, root_b = (corners[0], corners[3]) if hi else (corners[1], corners[2])
        seen_a = ia[0] if hi else ia[1]
        seen_b = ib[0] if hi else ib[1]
        length_px = float(np.linalg.norm(root_a - tip_a))
        if not all(
            _root_plausible(root, seen, a, side, mask, length_px) for root, seen in ((root_a, seen_a), (root_b, seen_b))
        ):
            continue
        out.append(CornerSet(corners, p.sigma, rebuild))
    return out


def _with_root(
    tip_a: FloatArray,
    tip_b: FloatArray,
    a: FloatArray,
    toward_root: FloatArray,
    hi: bool,
    length_m: float,
    width_m: float,
    px_per_m: float,
) -> FloatArray | None:
    """The 4 corners (ordered as in ``CornerSet``) of the wing with tip corners ``tip_a`` (rail A)
    and ``tip_b`` (rail B), its root derived as in ``hidden_root_corners``; None when the tip is
    wider than the prior allows."""
    e = (tip_b - tip_a) / (px_per_m * width_m)
    q = 1.0 - float(e @ e)
    if q < 1.0 - MAX_TIP_SCALE**2:
        return None
    q = max(q, 0.0)
    ae2 = float(a @ e) ** 2
    x = 1.0 if q + ae2 < 1e-12 else float(np.sqrt(q / (q + ae2)))
    if x < MIN_ROOT_SCALE:  # the axis along the line of sight: no wing would be seen
        return None
    step = x * px_per_m * length_m * toward_root
    root_a, root_b = tip_a + step, tip_b + step
    if hi:
        return np.array([root_a, tip_a, tip_b, root_b])
    return np.array([tip_a, root_a, root_b, tip_b])


def _root_plausible(
    root: FloatArray, seen_end: float, a: FloatArray, side: float, mask: np.ndarray, length_px: float
) -> bool:
    """The root is not short of the rail's visible end (``seen_end``, along ``a``; the root is on the
    ``-side`` of the tip) by more than 3 px or 5 % of the wing's ``length_px``, and when it is beyond
    it by more than ``ROOT_MIN_HIDDEN_PX``, the target covers it within 2 px (what hides it)."""
    beyond = side * (seen_end - float(a @ root))  # > 0: the root lies past the visible end
    if beyond < -max(ROOT_MIN_HIDDEN_PX, 0.05 * length_px):
        return False
    if beyond <= ROOT_MIN_HIDDEN_PX:
        return True
    u, v = round(float(root[0])), round(float(root[1]))
    H, W = mask.shape
    if not (0 <= u < W and 0 <= v < H):
        return False
    return bool(mask[max(v - 2, 0) : v + 3, max(u - 2, 0) : u + 3].any())


def best_wing(
    sets: list[CornerSet],
    length_m: float,
    width_m: float,
    camera: PinholeCamera,
    range_m: float | None = None,
) -> tuple[CornerSet, float] | None:
    """The first corner set (in the given order) that an L x W rectangle fits within 1 px rms and,
    with a range prior, at a depth within 10 % of it; else the best-fitting one. Returns the set
    and its reprojection rms (px). Four points of a parallelogram fit a rectangle of the wrong
    length by tilting it, so the fit alone cannot rank the sets: the order does."""
    best = None
    for cs in sets:
        sols = _solve(cs.corners_px, length_m, width_m, camera)
        if not sols:
            continue
        cost = min(c for _, _, c, _ in sols)
        depth_ok = range_m is None or all(abs(z / range_m - 1) < 0.1 for _, _, _, z in sols)
        if cost <= 1.0 and depth_ok:
            return cs, cost
        if depth_ok and (best is None or cost < best[1]):
            best = (cs, cost)
    return best


def ippe_candidates(
    corner_set: CornerSet,
    length_m: float,
    width_m: float,
    camera: PinholeCamera,
    sigma_px: float,
    rng: np.random.Generator,
) -> list[PoseCandidate]:
    """Both IPPE poses of the wing rectangle (length along model x), best first. Their covariance
    comes from redoing IPPE on corners perturbed by ``sigma_px`` (Monte Carlo; derived corners are
    rebuilt from the perturbed measured ones)."""
    corners_px = corner_set.corners_px
    base = _solve(corners_px, length_m, width_m, camera)
    if not base:
        return []
    samples: list[list[FloatArray]] = [[] for _ in base]
    for _ in range(MONTE_CARLO):
        perturbed: FloatArray | None = corners_px + rng.normal(0, sigma_px, corners_px.shape)
        if corner_set.rebuild is not None and perturbed is not None:
            perturbed = corner_set.rebuild(perturbed)
        if perturbed is None:
            continue
        noisy = [sol for sol in _solve(perturbed, length_m, width_m, camera) if np.all(np.isfinite(sol[0]))]
        for k, (ax, *_) in enumerate(base):
            if noisy:
                near = max(noisy, key=lambda s: abs(float(s[0] @ ax)))
                samples[k].append(near[0] * np.sign(near[0] @ ax))
    out = []
    for k, (ax, nrm, cost, _) in enumerate(base):
        basis = np.vstack(tangent_basis(ax))
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
