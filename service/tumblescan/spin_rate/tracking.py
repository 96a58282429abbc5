"""Line tracks across frames: predict each frame from the last (the target mask turned about its
centroid, refined by ECC affine alignment), then match segments by the paper's similarities
(angle, perpendicular offset, overlap, length ratio), mutual best only.

The grid over in-image rotations can pick an alias: a nearly square bright face (a noisy frame's
mask holds only the sunlit face of the bus) looks alike turned by 90°, and a mirror-symmetric
outline looks alike turned by +θ or -θ. Matching through such a prediction chains every edge to a
neighbouring parallel one, and those tracks mislead the rigid fit (benchmark ``oblique_110_noisy``:
four pairs predicted 55-71° off, tracks shifted round the bus's four parallel edges, rate 36 %
off; ``los_109_clean``: two pairs 34° and 84° off, the two longest tracks joined across one, 6.7 %
off). A spin turns the image at a rate that changes slowly, so a pair whose turn is far from the
median rate's (or whose ECC did not converge) is predicted again from a grid about the expected
turn, and the prediction whose ECC correlation is higher is kept (``suspect_turns``,
``better_prediction``); a pair that still turns the image the other way is not matched across (``untrusted_pairs``)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._typing import FloatArray
from .segments import Segments
from .target import TargetMask

ANGLE_STEP_DEG = 2.0
ANGLE_GRID_DEG = np.arange(-60.0, 60.01, ANGLE_STEP_DEG)
# A pair whose in-image turn is over SUSPECT_TURN_DEG from the median turn rate's is predicted again
# from a grid of ±RETRY_HALF_WIDTH_DEG about that expected turn (aliases seen: 34-90° off; the right
# pairs of a benchmark sequence lie within 6° of it, a dropped frame's included).
SUSPECT_TURN_DEG = 12.0
# The image turns (the expected turn means something) above this median turn a frame; the estimate's
# sense hint uses the same gate (estimate.py: the median turn rate times the median interval).
TURNING_MIN_DEG = 3.0
RETRY_HALF_WIDTH_DEG = 10.0
MAX_ANGLE_DEG = 8.0
MAX_OFFSET_PX = 5.0
MIN_SIMILARITY = 0.05
# A match whose perpendicular offset from its prediction is far above the pair's typical offset is
# a jump to a neighbouring (parallel) edge, not the same edge: the track is cut there.
JUMP_MIN_PX = 1.5
JUMP_FACTOR = 4.0


@dataclass
class Track:
    """One straight edge followed through the frames: frame index -> segment index in that frame."""

    members: dict[int, int] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.members)


@dataclass(frozen=True)
class Prediction:
    """A frame pair's image-to-image prediction: the 2x3 affine (px -> px), the grid angle (deg,
    OpenCV's sense) that seeded it, and the final ECC correlation (NaN when ECC did not converge
    and the grid's rotation was kept)."""

    affine: FloatArray
    grid_angle_deg: float
    ecc_rho: float

    @property
    def turn_deg(self) -> float:
        """The affine's in-image rotation (deg, clockwise as displayed)."""
        return affine_turn_deg(self.affine)


def affine_turn_deg(A: FloatArray) -> float:
    """The rotation (deg, clockwise as displayed: x right, y down) of a 2x3 affine, from its
    antisymmetric part: ``atan2(A10 - A01, A00 + A11)``."""
    return float(np.degrees(np.arctan2(A[1, 0] - A[0, 1], A[0, 0] + A[1, 1])))


def predict_affine(
    prev: FloatArray, next_: FloatArray, tp: TargetMask, tn: TargetMask, angles_deg: FloatArray = ANGLE_GRID_DEG
) -> Prediction:
    """The 2x3 affine taking frame ``prev``'s pixels to ``next_``'s, seeded by the best of the grid
    ``angles_deg`` (deg, OpenCV's sense: counter-clockwise as displayed, the opposite of
    ``affine_turn_deg``)."""
    import cv2

    assert tp.mask is not None and tn.mask is not None and tp.bbox is not None and tn.bbox is not None
    assert tp.centroid_px is not None and tn.centroid_px is not None
    H, W = prev.shape
    pad = 12
    u0 = max(min(tp.bbox[0], tn.bbox[0]) - pad, 0)
    v0 = max(min(tp.bbox[1], tn.bbox[1]) - pad, 0)
    u1 = min(max(tp.bbox[2], tn.bbox[2]) + pad, W - 1)
    v1 = min(max(tp.bbox[3], tn.bbox[3]) + pad, H - 1)
    o = np.array([u0, v0], dtype=float)
    # Step 1: edge-strength images (robust to shading changes), half resolution; the previous one
    # turned about its centroid on a 2° grid, the shift from phase correlation; best response wins.
    gp = _edges(prev[v0 : v1 + 1, u0 : u1 + 1])
    gn = _edges(next_[v0 : v1 + 1, u0 : u1 + 1])
    cp = (tp.centroid_px - o) * 0.5
    win = cv2.createHanningWindow((gn.shape[1], gn.shape[0]), cv2.CV_32F)
    best, best_angle, best_shift = -1.0, 0.0, np.zeros(2)
    for ang in angles_deg:
        R = cv2.getRotationMatrix2D((float(cp[0]), float(cp[1])), float(ang), 1.0)
        warped = cv2.warpAffine(gp, R, (gn.shape[1], gn.shape[0]))
        shift, response = cv2.phaseCorrelate(warped, gn, win)
        if response > best:
            best, best_angle, best_shift = float(response), float(ang), np.array(shift, dtype=float)
    M = cv2.getRotationMatrix2D((float(tp.centroid_px[0] - o[0]), float(tp.centroid_px[1] - o[1])), best_angle, 1.0)
    M = np.asarray(M, dtype=float)
    M[:, 2] = M[:, 2] + 2.0 * best_shift
    # Step 2: ECC affine on blurred crops (warp maps next -> prev), seeded with the inverse of M.
    ip = cv2.GaussianBlur(prev[v0 : v1 + 1, u0 : u1 + 1].astype(np.float32), (0, 0), 2.0)
    inn = cv2.GaussianBlur(next_[v0 : v1 + 1, u0 : u1 + 1].astype(np.float32), (0, 0), 2.0)
    warp = cv2.invertAffineTransform(M).astype(np.float32)
    rho = float("nan")
    try:
        rho, warp = cv2.findTransformECC(  # type: ignore[call-overload]
            inn, ip, warp, cv2.MOTION_AFFINE, (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 60, 1e-5), None, 5
        )
        M = cv2.invertAffineTransform(warp)
    except cv2.error:
        pass  # ECC did not converge: keep the mask rotation
    # Back to full-image coordinates: x_n = A x_p + b in crop coordinates.
    A, b = M[:, :2].astype(float), M[:, 2].astype(float)
    return Prediction(np.column_stack([A, A @ -o + b + o]), best_angle, float(rho))


def expected_turns(turns_deg: FloatArray, dt_s: FloatArray, converged: np.ndarray) -> FloatArray | None:
    """Each frame pair's expected turn (deg): the median turn rate of the pairs whose ECC converged
    times the pair's interval (a dropped frame turns twice as far); None under 3 such pairs.

    Parameters
    ----------
    turns_deg : (P,) each pair's turn (deg, ``affine_turn_deg``); dt_s : (P,) its interval (s);
    converged : (P,) bool, whether its ECC converged.
    """
    turns_deg = np.asarray(turns_deg, dtype=float)
    dt_s = np.asarray(dt_s, dtype=float)
    if int(np.sum(converged)) < 3:
        return None
    return np.asarray(float(np.median(turns_deg[converged] / dt_s[converged])) * dt_s, dtype=float)


def suspect_turns(turns_deg: FloatArray, dt_s: FloatArray, converged: np.ndarray) -> FloatArray:
    """For each frame pair (as ``expected_turns``), its expected turn (deg) when the pair is suspect,
    else NaN: a pair is suspect when its ECC did not converge or its turn is over
    ``SUSPECT_TURN_DEG`` from the expected one."""
    out = np.full(len(turns_deg), np.nan)
    expected = expected_turns(turns_deg, dt_s, converged)
    if expected is None:
        return out
    bad = ~np.asarray(converged, dtype=bool) | (np.abs(np.asarray(turns_deg) - expected) > SUSPECT_TURN_DEG)
    out[bad] = expected[bad]
    return out


def untrusted_pairs(turns_deg: FloatArray, dt_s: FloatArray, converged: np.ndarray) -> np.ndarray:
    """(P,) bool: the frame pairs (as ``expected_turns``) that still turn the image the other way
    from the expected turn, by over ``SUSPECT_TURN_DEG``, after the retry, when the image turns (the
    median expected turn over ``TURNING_MIN_DEG`` a frame). A spin seen off the image plane turns
    the image one way (its sense), though unevenly (a pair at -22° where -4° is expected can be
    right: benchmark ``plane_116_clean``, which then kept too few tracks); a pair turned the other
    way is not the spin. No segment is matched across such a pair: a match through a wrong
    prediction joins two edges into one track, while a gap is bridged later by the rigid model's
    re-matching (benchmark ``oblique_116``: with pairs turned +12..+54° against -10° expected
    matched, the fit ended 35 % off, or too few tracks were left; without, 0.06-0.11 %). When the
    image does not turn (the axis near the image plane) every pair is kept."""
    keep_all = np.zeros(len(turns_deg), dtype=bool)
    expected = expected_turns(turns_deg, dt_s, converged)
    if expected is None:
        return keep_all
    if float(np.median(np.abs(expected))) <= TURNING_MIN_DEG:
        return keep_all
    turns = np.asarray(turns_deg, dtype=float)
    return np.asarray((np.abs(turns - expected) > SUSPECT_TURN_DEG) & (turns * expected < 0), dtype=bool)


def retry_grid(expected_turn_deg: float) -> FloatArray:
    """The grid angles (deg, OpenCV's sense) within ``RETRY_HALF_WIDTH_DEG`` of an expected turn."""
    return np.arange(
        -expected_turn_deg - RETRY_HALF_WIDTH_DEG, -expected_turn_deg + RETRY_HALF_WIDTH_DEG + 0.01, ANGLE_STEP_DEG
    )


def better_prediction(first: Prediction, retry: Prediction) -> Prediction:
    """The retry when its ECC converged to a higher correlation than the first's (or the first's did
    not converge); both align the same crops, so their correlations compare."""
    if np.isfinite(retry.ecc_rho) and not (first.ecc_rho >= retry.ecc_rho):
        return retry
    return first


def _edges(img: FloatArray) -> np.ndarray:
    """Gradient magnitude, blurred and halved (float32)."""
    import cv2

    f = img.astype(np.float32)
    g = cv2.magnitude(cv2.Sobel(f, cv2.CV_32F, 1, 0), cv2.Sobel(f, cv2.CV_32F, 0, 1))
    g = cv2.GaussianBlur(g, (0, 0), 1.5)
    return np.asarray(cv2.resize(g, None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA), dtype=np.float32)


def match(prev: FloatArray, nxt: FloatArray, affine: FloatArray) -> list[tuple[int, int]]:
    """Mutual-best pairs (i in ``prev``, j in ``nxt``) of segments (N, 2, 2) after mapping ``prev``
    through ``affine``: ``sim = s_len·s_ang·s_off·overlap`` above ``MIN_SIMILARITY``."""
    if len(prev) == 0 or len(nxt) == 0:
        return []
    A, b = affine[:, :2], affine[:, 2]
    p = prev @ A.T + b
    sim = np.zeros((len(p), len(nxt)))
    tp, Lp = _dir(p)
    tn, Ln = _dir(nxt)
    cos = np.abs(tp @ tn.T)
    ang = np.degrees(np.arccos(np.clip(cos, 0, 1)))
    for i in range(len(p)):
        ok = np.flatnonzero(ang[i] < MAX_ANGLE_DEG)
        if not len(ok):
            continue
        n_i = np.array([-tp[i, 1], tp[i, 0]])
        q = nxt[ok]
        off = np.abs((q - p[i, 0]) @ n_i).mean(axis=1)
        s = (q - p[i, 0]) @ tp[i]
        lo, hi = np.minimum(s[:, 0], s[:, 1]), np.maximum(s[:, 0], s[:, 1])
        overlap = np.clip(np.minimum(hi, Lp[i]) - np.maximum(lo, 0.0), 0, None) / np.minimum(Lp[i], Ln[ok])
        s_len = np.minimum(Lp[i], Ln[ok]) / np.maximum(Lp[i], Ln[ok])
        s_ang = 1 - ang[i, ok] / MAX_ANGLE_DEG
        s_off = np.exp(-0.5 * (off / (MAX_OFFSET_PX / 2)) ** 2) * (off < MAX_OFFSET_PX)
        sim[i, ok] = np.sqrt(s_len) * s_ang * s_off * np.clip(overlap, 0, 1)
    pairs, offsets = [], []
    for i in range(len(p)):
        j = int(np.argmax(sim[i]))
        if sim[i, j] > MIN_SIMILARITY and int(np.argmax(sim[:, j])) == i:
            pairs.append((i, j))
            n_i = np.array([-tp[i, 1], tp[i, 0]])
            offsets.append(float(np.abs((nxt[j] - p[i, 0]) @ n_i).mean()))
    return reject_jumps(pairs, np.array(offsets))


def reject_jumps(pairs: list[tuple[int, int]], offsets_px: FloatArray) -> list[tuple[int, int]]:
    """The pairs whose perpendicular offset (px, after the affine prediction) is under
    ``max(JUMP_MIN_PX, JUMP_FACTOR × median offset)``: the affine predicts the edges of one frame
    pair alike, so an edge far off its prediction has jumped to a neighbouring edge (the right one
    was missed) and its track is cut there rather than bent."""
    if len(pairs) < 3:
        return pairs
    limit = max(JUMP_MIN_PX, JUMP_FACTOR * float(np.median(offsets_px)))
    return [pr for pr, off in zip(pairs, offsets_px, strict=True) if off <= limit]


def build_tracks(segments: list[Segments], pairs: dict[tuple[int, int], list[tuple[int, int]]]) -> list[Track]:
    """Chain frame-to-frame pairs (``(k, l)`` frames -> segment pairs) into tracks."""
    tracks: list[Track] = []
    open_: dict[tuple[int, int], Track] = {}
    for (k, l_), matched in sorted(pairs.items()):
        for i, j in matched:
            tr = open_.pop((k, i), None)
            if tr is None:
                tr = Track({k: i})
                tracks.append(tr)
            tr.members[l_] = j
            open_[(l_, j)] = tr
    return tracks


def _dir(seg: FloatArray) -> tuple[FloatArray, FloatArray]:
    d = seg[:, 1] - seg[:, 0]
    L = np.linalg.norm(d, axis=1)
    return d / np.maximum(L, 1e-9)[:, None], L
