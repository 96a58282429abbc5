"""Level B: each frame's body pose from the tag corners every camera saw (multi-camera PnP).

1. **Start**: ``cv2.solvePnPGeneric`` of one camera's corners against the tags' body
   coordinates (IPPE for one tag: both of its solutions; SQPnP for several), moved into the world
   through the camera's pose; with the previous frame's pose, the candidate with the lowest
   (gated) reprojection cost over all cameras wins. The camera with the most tags goes first; the
   others' candidates are added only when no candidate fits every camera within 5 sigma on
   average (one small tag alone can flip: IPPE's two solutions are close in cost; the other
   cameras' tags decide).
2. **Joint Gauss-Newton** over all cameras' corners of the frame, batched over frames:
   ``min sum_n sum_c |uv_nc - pi_n(T_world_body p_c)|^2 / sigma_n^2`` (``pi_n``: detection n's
   camera with its distortion), world-side perturbations. This is the maximum-likelihood pose for
   Gaussian corner noise, and ``(J^T W J)^-1`` at the optimum is its covariance (the per-frame
   Cramer-Rao bound evaluated at the estimate).
3. **Outliers**: a detection with a corner farther than ``outlier_sigma`` sigmas from its
   prediction is dropped (the worst one per frame and round) and the frame refitted.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._typing import BoolArray, FloatArray, IntArray
from .geometry import exp_so3
from .tag_camera import RigArrays, body_to_pixels, project, projection_jacobian, to_camera
from .tags_io import TagInput

MAX_ITERATIONS = 30
MAX_OUTLIER_ROUNDS = 5
# A start whose gated cost is at most this many sigma^2 per corner coordinate is good enough to
# start Gauss-Newton from (a wrong flip costs tens to thousands); the other cameras' PnP is skipped.
GOOD_START_Z2 = 25.0
# Two starts whose costs differ by less than this (a likelihood ratio of 100) fit equally well...
AMBIGUITY_CHI2 = 2.0 * np.log(100.0)
# ...and make the frame ambiguous when their rotations are this far apart [deg].
AMBIGUITY_DEG = 10.0


@dataclass
class FrameFit:
    """Per-frame fits. R (F, 3, 3) R_world_body and t (F, 3) [m]; cov (F, 6, 6) in the order
    (dtheta_world [rad], dp_world [m]), NaN where not measured; measured (F,); inlier (N,) per
    detection; residual_px (N, 4, 2) against the final poses (NaN where the frame has no pose)."""

    R: FloatArray
    t: FloatArray
    cov: FloatArray
    measured: BoolArray
    inlier: BoolArray
    residual_px: FloatArray
    iterations: int
    chi2: float
    dof: int
    ambiguous: BoolArray  # (F,) two poses fitted the frame's tags; the one nearest the last frame's was kept


def fit_tag_poses(data: TagInput, sigma_px: FloatArray, outlier_sigma: float) -> FrameFit:
    """Fit every frame of ``data``; sigma_px (C,): each camera's corner sigma [px]."""
    rig = _rig(data, sigma_px)
    corners_b = data.corners_body_m[data.det_tag]  # (N, 4, 3)
    R, t, ok, ambiguous = initial_poses(data, rig, outlier_sigma)
    inlier = ok[data.det_frame].copy()
    iterations = 0
    F = data.n_frames
    H = np.zeros((F, 6, 6))
    rows = np.arange(len(data.det_frame))
    for _ in range(MAX_OUTLIER_ROUNDS + 1):
        # Only the frames that lost a detection are refitted after the first round.
        k = data.det_frame[rows]
        R[k], t[k], H_rows, it = gauss_newton(
            R[k], t[k], corners_b[rows], data.corners_px[rows], data.det_cam[rows], rig, inlier[rows], k
        )
        H[k] = H_rows
        iterations += it
        res = _residuals(R, t, corners_b, data, rig)
        z = np.linalg.norm(res, axis=-1) / rig.sigma_px[data.det_cam][:, None]  # (N, 4)
        worst = np.where(inlier, z.max(axis=1), 0.0)
        bad = worst > outlier_sigma
        if not bad.any():
            break
        # Drop only the worst detection of each frame per round (one gross error drags the others).
        top = np.full(F, -1.0)
        np.maximum.at(top, data.det_frame, np.where(bad, worst, -1.0))
        inlier &= ~(bad & (worst >= top[data.det_frame]))
        rows = np.flatnonzero(top[data.det_frame] >= 0)
    n_in = np.bincount(data.det_frame[inlier], minlength=data.n_frames)
    measured = (n_in > 0) & (np.linalg.cond(np.where((n_in > 0)[:, None, None], H, np.eye(6))) < 1e12)
    cov = np.full((data.n_frames, 6, 6), np.nan)
    cov[measured] = np.linalg.inv(H[measured])
    R[~measured], t[~measured] = np.nan, np.nan
    res = _residuals(R, t, corners_b, data, rig)
    use = inlier & measured[data.det_frame]
    chi2 = float(np.sum((res[use] / rig.sigma_px[data.det_cam[use]][:, None, None]) ** 2))
    inlier &= measured[data.det_frame]
    dof = int(8 * use.sum() - 6 * measured.sum())
    return FrameFit(R, t, cov, measured, inlier, res, iterations, chi2, dof, ambiguous & measured)


def _rig(data: TagInput, sigma_px: FloatArray) -> RigArrays:
    rig = RigArrays.of(data.cameras)
    return RigArrays(rig.K, rig.dist, rig.R_cam_world, rig.t_world_cam, np.asarray(sigma_px, dtype=float))


def _residuals(R: FloatArray, t: FloatArray, corners_b: FloatArray, data: TagInput, rig: RigArrays) -> FloatArray:
    k = data.det_frame
    return np.asarray(data.corners_px - body_to_pixels(R[k], t[k], corners_b, data.det_cam, rig))


def gauss_newton(
    R_rows: FloatArray,
    t_rows: FloatArray,
    corners_b: FloatArray,
    corners_px: FloatArray,
    cam: IntArray,
    rig: RigArrays,
    use: BoolArray,
    frame: IntArray,
) -> tuple[FloatArray, FloatArray, FloatArray, int]:
    """Batched Gauss-Newton of the poses of the frames that detections (N rows) belong to.

    R_rows (N, 3, 3), t_rows (N, 3): each row's frame's starting pose; corners_b (N, 4, 3) body
    [m]; corners_px (N, 4, 2); cam (N,); use (N,): the detections fitted; frame (N,): each row's
    frame (any integer labels). Returns per row (R, t, H (6, 6) the frame's information
    ``J^T W J`` at the result) and the iterations."""
    labels, k = np.unique(frame, return_inverse=True)
    F = len(labels)
    first = np.unique(k, return_index=True)[1]
    R, t = R_rows[first].copy(), t_rows[first].copy()
    w = 1.0 / rig.sigma_px[cam] ** 2
    active = np.bincount(k[use], minlength=F) > 0
    iterations = 0
    for _ in range(MAX_ITERATIONS):
        iterations += 1
        Rk = np.where(active[k][:, None, None], R[k], np.eye(3))
        tk = np.where(active[k][:, None], t[k], 0.0)
        uv, J = projection_jacobian(Rk, tk, corners_b, cam, rig)
        r = corners_px - uv
        H, g = _normal_equations(J, r, np.where(use, w, 0.0), k, F)
        ok = active & (np.abs(np.linalg.det(H)) > 0)
        step = np.zeros((F, 6))
        step[ok] = np.linalg.solve(H[ok], g[ok][..., None])[..., 0]
        R = np.einsum("fij,fjk->fik", exp_so3(step[:, :3]), R)
        t = t + step[:, 3:]
        if np.max(np.abs(step), initial=0.0) < 1e-10:
            break
    # The information at the final poses (one more evaluation, no step).
    Rk = np.where(active[k][:, None, None], R[k], np.eye(3))
    tk = np.where(active[k][:, None], t[k], 0.0)
    uv, J = projection_jacobian(Rk, tk, corners_b, cam, rig)
    H, _ = _normal_equations(J, corners_px - uv, np.where(use, w, 0.0), k, F)
    return R[k], t[k], H[k], iterations


def _normal_equations(
    J: FloatArray, r: FloatArray, w: FloatArray, k: IntArray, F: int
) -> tuple[FloatArray, FloatArray]:
    """Per frame ``H = sum w J^T J`` (F, 6, 6) and ``g = sum w J^T r`` (F, 6) from every detection's
    corners: J (N, 4, 2, 6), r (N, 4, 2) [px], w (N,) [1/px^2], k (N,) frame of each."""
    Jn = J.reshape(len(J), -1, 6)
    JtW = np.transpose(Jn, (0, 2, 1)) * w[:, None, None]
    H_n = JtW @ Jn
    g_n = (JtW @ r.reshape(len(r), -1, 1))[..., 0]
    H = np.zeros((F, 36))
    g = np.zeros((F, 6))
    for i in range(36):  # bincount per entry: much faster than np.add.at on (F, 6, 6)
        H[:, i] = np.bincount(k, H_n.reshape(-1, 36)[:, i], minlength=F)
    for i in range(6):
        g[:, i] = np.bincount(k, g_n[:, i], minlength=F)
    return H.reshape(F, 6, 6), g


def initial_poses(
    data: TagInput, rig: RigArrays, gate_sigma: float
) -> tuple[FloatArray, FloatArray, BoolArray, BoolArray]:
    """Each frame's starting pose (see the module's step 1). Returns R (F, 3, 3), t (F, 3), which
    frames have one, and which were ambiguous (two poses fit; continuity chose)."""

    F = data.n_frames
    R = np.tile(np.eye(3), (F, 1, 1))
    t = np.zeros((F, 3))
    ok = np.zeros(F, dtype=bool)
    corners_b = data.corners_body_m
    starts = np.searchsorted(data.det_frame, np.arange(F + 1))
    prev: tuple[FloatArray, FloatArray] | None = None
    ambiguous = np.zeros(F, dtype=bool)
    for f in range(F):
        rows = np.arange(starts[f], starts[f + 1])
        if not len(rows):
            prev = None  # continuity is only trusted from one frame to the next
            continue
        # Cameras by their number of tags: the first one's PnP usually fits every camera; the
        # others are tried only when it does not (a flip, a single small tag).
        cams, counts = np.unique(data.det_cam[rows], return_counts=True)
        order = cams[np.argsort(-counts, kind="stable")]
        cands: list[tuple[FloatArray, FloatArray]] = [] if prev is None else [prev]
        best: tuple[FloatArray, FloatArray] | None = None
        for batch in (order[:1], order[1:]):
            for c in batch:
                cands += _pnp_candidates(data, rows[data.det_cam[rows] == c], int(c), corners_b)
            if not cands:
                continue
            costs = _candidate_costs(cands, rows, corners_b, data, rig, gate_sigma)
            best, ambiguous[f] = _pick(cands, costs, prev)
            if costs.min() <= GOOD_START_Z2 * 8 * len(rows):
                break
        if best is None:
            continue
        R[f], t[f] = best
        ok[f] = True
        prev = best
    return R, t, ok, ambiguous


def _pick(
    cands: list[tuple[FloatArray, FloatArray]], costs: FloatArray, prev: tuple[FloatArray, FloatArray] | None
) -> tuple[tuple[FloatArray, FloatArray], bool]:
    """The start among candidates: the lowest cost, unless other candidates fit about as well
    (a likelihood ratio under ``AMBIGUITY_CHI2``) with a rotation more than ``AMBIGUITY_DEG``
    away: then the frame is ambiguous (one small tag's two IPPE poses) and the candidate nearest
    the previous frame's pose is taken."""
    from .geometry import log_so3

    best = int(np.argmin(costs))
    fits = np.flatnonzero(costs <= costs[best] + AMBIGUITY_CHI2)
    Rb = cands[best][0]
    apart = [i for i in fits if np.degrees(np.linalg.norm(log_so3(cands[i][0] @ Rb.T))) > AMBIGUITY_DEG]
    if not apart:
        return cands[best], False
    if prev is not None:
        dist = [np.linalg.norm(log_so3(cands[i][0] @ prev[0].T)) for i in fits]
        return cands[int(fits[int(np.argmin(dist))])], True
    return cands[best], True


def _pnp_candidates(
    data: TagInput, mine: IntArray, c: int, corners_b: FloatArray
) -> list[tuple[FloatArray, FloatArray]]:
    """Body poses in the world from camera ``c``'s detections ``mine``: IPPE's two solutions for
    one tag, SQPnP's one for several."""
    import cv2

    obj = corners_b[data.det_tag[mine]].reshape(-1, 3)
    img = data.corners_px[mine].reshape(-1, 2)
    flag = cv2.SOLVEPNP_IPPE if len(mine) == 1 else cv2.SOLVEPNP_SQPNP
    cam = data.cameras[c]
    try:
        n, rvecs, tvecs, _ = cv2.solvePnPGeneric(obj, img, cam.K, cam.dist, flags=flag)
    except cv2.error:
        return []
    out = []
    for rv, tv in zip(rvecs[:n], tvecs[:n], strict=True):
        R_cb = cv2.Rodrigues(rv)[0]
        out.append((cam.R_world_cam @ R_cb, cam.R_world_cam @ tv.ravel() + cam.t_world_cam))
    return out


def _candidate_costs(
    cands: list[tuple[FloatArray, FloatArray]],
    rows: IntArray,
    corners_b: FloatArray,
    data: TagInput,
    rig: RigArrays,
    gate_sigma: float,
) -> FloatArray:
    """Each candidate pose's gated reprojection cost: the sum of ``min(z^2, gate^2)`` over the
    frame's corner coordinates, z in sigmas."""
    K, n = len(cands), len(rows)
    Rc = np.array([c[0] for c in cands])
    tc = np.array([c[1] for c in cands])
    pb = corners_b[data.det_tag[rows]]  # (n, 4, 3)
    pw = np.einsum("kij,npj->knpi", Rc, pb) + tc[:, None, None]
    cam = np.tile(data.det_cam[rows], K)
    pc = to_camera(pw.reshape(K * n, 4, 3), cam, rig)
    uv = project(pc, cam, rig).reshape(K, n, 4, 2)
    z2 = np.sum((uv - data.corners_px[rows]) ** 2, axis=-1) / rig.sigma_px[data.det_cam[rows]][None, :, None] ** 2
    behind = (pc[..., 2] <= 0).reshape(K, n, 4)
    return np.asarray(
        np.where(behind | ~np.isfinite(z2), gate_sigma**2, np.minimum(z2, gate_sigma**2)).sum(axis=(1, 2))
    )
