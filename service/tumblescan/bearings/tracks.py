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
class _Tracks:
    """Every track's state, one row per track (arrays grow as tracks start)."""

    first_t: FloatArray
    first_p: FloatArray
    last_t: FloatArray
    last_p: FloatArray
    last_sigma_m: FloatArray
    last_cov_m2: FloatArray
    last_frame: IntArray
    fixes: IntArray

    @classmethod
    def empty(cls) -> _Tracks:
        z = np.zeros(0)
        return cls(
            z, np.zeros((0, 3)), z, np.zeros((0, 3)), z, np.zeros((0, 3, 3)), z.astype(np.int64), z.astype(np.int64)
        )

    def __len__(self) -> int:
        return int(self.first_t.size)

    def update(self, rows: IntArray, t: float, p: FloatArray, sigma: FloatArray, cov: FloatArray, f: int) -> None:
        self.last_t[rows], self.last_p[rows], self.last_sigma_m[rows], self.last_cov_m2[rows] = t, p, sigma, cov
        self.last_frame[rows] = f
        self.fixes[rows] += 1

    def start(self, t: float, p: FloatArray, sigma: FloatArray, cov: FloatArray, f: int) -> None:
        n = p.shape[0]
        self.first_t = np.concatenate([self.first_t, np.full(n, t)])
        self.first_p = np.concatenate([self.first_p, p])
        self.last_t = np.concatenate([self.last_t, np.full(n, t)])
        self.last_p = np.concatenate([self.last_p, p])
        self.last_sigma_m = np.concatenate([self.last_sigma_m, sigma])
        self.last_cov_m2 = np.concatenate([self.last_cov_m2, cov])
        self.last_frame = np.concatenate([self.last_frame, np.full(n, f, dtype=np.int64)])
        self.fixes = np.concatenate([self.fixes, np.ones(n, dtype=np.int64)])


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

    tracks = _Tracks.empty()
    out: list[IntArray] = []
    for f, (t, p, cov) in enumerate(zip(t_s, p_job_m, cov_m2, strict=True)):
        k = p.shape[0]
        sigma = np.sqrt(np.maximum(np.trace(cov, axis1=1, axis2=2), 0.0)) if k else np.zeros(0)
        live = np.flatnonzero(f - tracks.last_frame <= max_gap_frames + 1)
        ids = np.full(k, -1, dtype=np.int64)
        if live.size and k:
            pred, radius, S_pred, has_v = _predict(tracks, live, t, max_speed_m_s, max_accel_m_s2)
            tree = cKDTree(pred)
            dist, idx = tree.query(p, k=min(NEIGHBOURS, live.size), distance_upper_bound=float(radius.max()))
            dist, idx = dist.reshape(k, -1), idx.reshape(k, -1)
            fix_i, nb = np.nonzero(np.isfinite(dist))
            track_i = idx[fix_i, nb]
            cost = _cost(p, cov, sigma, pred, radius, S_pred, has_v, fix_i, track_i)
            keep = cost < 0.0
            fix_i, track_i, cost = fix_i[keep], track_i[keep], cost[keep]
            chosen = assign_sparse(fix_i, track_i, cost, k, live.size)
            ids[fix_i[chosen]] = live[track_i[chosen]]
        linked = np.flatnonzero(ids >= 0)
        tracks.update(ids[linked], t, p[linked], sigma[linked], cov[linked], f)
        new = np.flatnonzero(ids < 0)
        ids[new] = len(tracks) + np.arange(new.size)
        tracks.start(t, p[new], sigma[new], cov[new], f)
        out.append(ids)
    return out


def _predict(
    tracks: _Tracks, live: IntArray, t: float, max_speed_m_s: float, max_accel_m_s2: float
) -> tuple[FloatArray, FloatArray, FloatArray, BoolArray]:
    """Predicted positions (n, 3), gate radii (n,) in m, the prediction's covariance (n, 3, 3)
    in m² and whether each live track has a velocity yet, at time ``t``.

    The covariance is ``(1 + 2 dt/span)² C_last + (a_max span dt)² I``: the last fix's error
    carried by a velocity measured over ``span``, plus room for acceleration."""
    last_p, first_p = tracks.last_p[live], tracks.first_p[live]
    last_t, first_t = tracks.last_t[live], tracks.first_t[live]
    sigma, cov = tracks.last_sigma_m[live], tracks.last_cov_m2[live]
    has_v = tracks.fixes[live] >= 2
    dt = t - last_t
    span = np.where(has_v, last_t - first_t, 1.0)
    v = np.where(has_v[:, None], (last_p - first_p) / span[:, None], 0.0)
    pred = last_p + v * dt[:, None]
    grow = 1.0 + 2.0 * dt / span
    accel = max_accel_m_s2 * span * dt
    radius = np.where(has_v, 6.0 * sigma * grow + accel, max_speed_m_s * dt + 6.0 * sigma)
    S = grow[:, None, None] ** 2 * cov + (accel**2)[:, None, None] * np.eye(3)[None]
    return pred, radius, S, has_v


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
