"""Linking per-frame fixes into tracks: constant-velocity prediction, KD-tree neighbours and a
sparse one-to-one assignment per frame.

A track without a velocity yet (one fix) may move up to ``max_speed_m_s``; once it has two
fixes its velocity is the mean since its first fix and the gate is a few σ of the last fix
plus room for acceleration. Tracks unseen for more than ``max_gap_frames`` frames end.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._typing import FloatArray, IntArray
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
            pred, radius = _predict(tracks, live, t, max_speed_m_s, max_accel_m_s2)
            tree = cKDTree(pred)
            dist, idx = tree.query(p, k=min(NEIGHBOURS, len(live)), distance_upper_bound=float(radius.max()))
            dist, idx = dist.reshape(k, -1), idx.reshape(k, -1)
            fix_i, nb = np.nonzero(np.isfinite(dist))
            track_i = idx[fix_i, nb]
            cost = _cost(tracks, live, t, p, cov, sigma, pred, radius, fix_i, track_i, max_accel_m_s2)
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
) -> tuple[FloatArray, FloatArray]:
    """Predicted positions (n, 3) and gate radii (n,) in m of the live tracks at time ``t``."""
    pred = np.empty((len(live), 3))
    radius = np.empty(len(live))
    for n, i in enumerate(live):
        tr = tracks[i]
        dt = t - tr.last_t
        if tr.fixes < 2:
            pred[n] = tr.last_p
            radius[n] = max_speed_m_s * dt + 6.0 * tr.last_sigma_m
            continue
        span = tr.last_t - tr.first_t
        v = (tr.last_p - tr.first_p) / span
        pred[n] = tr.last_p + v * dt
        radius[n] = 6.0 * tr.last_sigma_m * (1.0 + 2.0 * dt / span) + max_accel_m_s2 * (span + dt) * dt
    return pred, radius


def _cost(
    tracks: list[_Track],
    live: list[int],
    t: float,
    p: FloatArray,
    cov: FloatArray,
    sigma: FloatArray,
    pred: FloatArray,
    radius: FloatArray,
    fix_i: IntArray,
    track_i: IntArray,
    max_accel_m_s2: float,
) -> FloatArray:
    """Cost of linking fix ``fix_i`` to live track ``track_i`` (negative inside the gate).

    A track with a velocity is gated on the Mahalanobis distance of the innovation (6σ), with
    ``S = (1 + 2 dt/span)² C_last + C_new + (a_max span dt)² I``; a new track on the distance
    it could have flown, widened by 6σ of the new fix."""
    e = p[fix_i] - pred[track_i]
    d = np.linalg.norm(e, axis=1)
    cost = (d / (radius[track_i] + 6.0 * sigma[fix_i])) ** 2 - 1.0
    has_v = np.array([tracks[live[n]].fixes >= 2 for n in track_i], dtype=bool)
    if has_v.any():
        idx = np.flatnonzero(has_v)
        S = cov[fix_i[idx]].copy()
        for row, n in enumerate(track_i[idx].tolist()):
            tr = tracks[live[n]]
            dt, span = t - tr.last_t, tr.last_t - tr.first_t
            S[row] += (1.0 + 2.0 * dt / span) ** 2 * tr.last_cov_m2 + (max_accel_m_s2 * span * dt) ** 2 * np.eye(3)
        m2 = np.einsum("ni,ni->n", e[idx], np.linalg.solve(S, e[idx][..., None])[..., 0])
        cost[idx] = m2 / 36.0 - 1.0
    return cost
