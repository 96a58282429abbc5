"""Linking per-frame fixes into tracks: constant-velocity prediction, KD-tree neighbours and a
sparse one-to-one assignment per frame.

A track without a velocity yet (one fix) may move up to ``max_speed_m_s``; once it has two
fixes its velocity is the mean since its first fix and the gate is a few σ of the last fix
plus room for acceleration. Tracks unseen for more than ``max_gap_frames`` frames end.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._typing import BoolArray, FloatArray, IntArray
from .assign import assign_sparse

NEIGHBOURS = 6


@dataclass
class _Track:
    first_t: float
    first_p: FloatArray
    last_t: float
    last_p: FloatArray
    last_sigma_m: float
    last_cov_m2: FloatArray
    last_frame: int
    fixes: int


def link_tracks(
    t_s: list[float],
    p_job_m: list[FloatArray],
    cov_m2: list[FloatArray],
    *,
    max_speed_m_s: float = 10_000.0,
    max_accel_m_s2: float = 20.0,
    max_gap_frames: int = 2,
) -> list[IntArray]:
    """Track number of every fix, frame by frame (same shapes as ``p_job_m[f][:, 0]``).

    ``t_s`` (frames,) in s; ``p_job_m[f]`` (k_f, 3) and ``cov_m2[f]`` (k_f, 3, 3) per frame.
    """
    from scipy.spatial import cKDTree

    tracks: list[_Track] = []
    out: list[IntArray] = []
    for f, (t, p, cov) in enumerate(zip(t_s, p_job_m, cov_m2, strict=True)):
        k = p.shape[0]
        sigma = np.sqrt(np.maximum(np.trace(cov, axis1=1, axis2=2), 0.0)) if k else np.zeros(0)
        live = [n for n, tr in enumerate(tracks) if f - tr.last_frame <= max_gap_frames + 1]
        ids = np.full(k, -1, dtype=np.int64)
        if live and k:
            pred, radius, S_pred, has_v = _predict(tracks, live, t, max_speed_m_s, max_accel_m_s2)
            tree = cKDTree(pred)
            dist, idx = tree.query(p, k=min(NEIGHBOURS, len(live)), distance_upper_bound=float(radius.max()))
            dist, idx = dist.reshape(k, -1), idx.reshape(k, -1)
            fix_i, nb = np.nonzero(np.isfinite(dist))
            track_i = idx[fix_i, nb]
            cost = _cost(p, cov, sigma, pred, radius, S_pred, has_v, fix_i, track_i)
            keep = cost < 0.0
            fix_i, track_i, cost = fix_i[keep], track_i[keep], cost[keep]
            chosen = assign_sparse(fix_i, track_i, cost, k, len(live))
            ids[fix_i[chosen]] = np.asarray(live)[track_i[chosen]]
        for j in range(k):
            if ids[j] < 0:
                tracks.append(_Track(t, p[j].copy(), t, p[j].copy(), float(sigma[j]), cov[j].copy(), f, 1))
                ids[j] = len(tracks) - 1
            else:
                tr = tracks[ids[j]]
                tr.last_t, tr.last_p, tr.last_sigma_m, tr.last_frame = t, p[j].copy(), float(sigma[j]), f
                tr.last_cov_m2 = cov[j].copy()
                tr.fixes += 1
        out.append(ids)
    return out


def _predict(
    tracks: list[_Track], live: list[int], t: float, max_speed_m_s: float, max_accel_m_s2: float
) -> tuple[FloatArray, FloatArray, FloatArray, BoolArray]:
    """Predicted positions (n, 3), gate radii (n,) in m, the prediction's covariance (n, 3, 3)
    in m² and whether each live track has a velocity yet, at time ``t``.

    The covariance is ``(1 + 2 dt/span)² C_last + (a_max span dt)² I``: the last fix's error
    carried by a velocity measured over ``span``, plus room for acceleration."""
    n = len(live)
    last_p = np.array([tracks[i].last_p for i in live])
    first_p = np.array([tracks[i].first_p for i in live])
    last_t = np.array([tracks[i].last_t for i in live])
    first_t = np.array([tracks[i].first_t for i in live])
    sigma = np.array([tracks[i].last_sigma_m for i in live])
    cov = np.array([tracks[i].last_cov_m2 for i in live])
    has_v = np.array([tracks[i].fixes >= 2 for i in live], dtype=bool)
    dt = t - last_t
    span = np.where(has_v, last_t - first_t, 1.0)
    v = np.where(has_v[:, None], (last_p - first_p) / span[:, None], 0.0)
    pred = last_p + v * dt[:, None]
    grow = 1.0 + 2.0 * dt / span
    accel = max_accel_m_s2 * span * dt
    radius = np.where(has_v, 6.0 * sigma * grow + accel, max_speed_m_s * dt + 6.0 * sigma)
    S = grow[:, None, None] ** 2 * cov + (accel**2)[:, None, None] * np.eye(3)[None]
    return pred, radius, S.reshape(n, 3, 3), has_v


def _cost(
    p: FloatArray,
    cov: FloatArray,
    sigma: FloatArray,
    pred: FloatArray,
    radius: FloatArray,
    S_pred: FloatArray,
    has_v: BoolArray,
    fix_i: IntArray,
    track_i: IntArray,
) -> FloatArray:
    """Cost of linking fix ``fix_i`` to live track ``track_i`` (negative inside the gate).

    A track with a velocity is gated on the Mahalanobis distance of the innovation (6σ) with
    covariance ``S_pred + C_new``; a new track on the distance it could have flown, widened by
    6σ of the new fix."""
    e = p[fix_i] - pred[track_i]
    d = np.linalg.norm(e, axis=1)
    cost = (d / (radius[track_i] + 6.0 * sigma[fix_i])) ** 2 - 1.0
    idx = np.flatnonzero(has_v[track_i])
    if idx.size:
        S = S_pred[track_i[idx]] + cov[fix_i[idx]]
        with np.errstate(all="ignore"):
            m2 = np.einsum("ni,ni->n", e[idx], np.linalg.solve(S, e[idx][..., None])[..., 0])
        cost[idx] = np.where(np.isfinite(m2), m2 / 36.0 - 1.0, 1.0)
    return cost
