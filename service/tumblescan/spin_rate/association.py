"""Which observed segment belongs to which fitted line: hard outlier rejection and re-matching.

A line track that switches to another edge (the right one was missed in a frame, or a parallel
edge lies a pixel away) is not noise: a rigid motion at a slightly wrong rate explains the switched
edges too, and the Cauchy loss alone does not undo that (measured on the simulator: tracks with
such switches pulled the rate 4-5 % off while the fit's rms stayed under 0.1 px). Observations far
off the fitted lines are therefore dropped outright and the fit repeated, and re-matching accepts
a segment only within a gate tied to the fit's residual scale.
"""

from __future__ import annotations

import numpy as np

from .._typing import FloatArray
from .rigid import Observations, RigidFit, fit_rigid, init_structure, predict_lines, robust_scale_px
from .rigid_model import RigidModel

MIN_TRACK_OBS = 3
OUTLIER_SCALES = 5.0
OUTLIER_MIN_PX = 0.3
OUTLIER_PEELS = 8
PEEL_NFEV = 25
STRAY_MIN_PX = 1.0
STRAY_FACTOR = 3.0
REMATCH_MAX_PX = 2.0
REMATCH_SCALES = 6.0
REMATCH_MIN_PX = 0.5
REMATCH_DEG = 3.0
# A track that is a rigid line only piecewise (it switched edges without a jump) is split where a
# line per piece lowers χ² by over SPLIT_DELTA_CHI2 (σ the fit's robust scale, at least
# SPLIT_MIN_SCALE_PX: edge biases of about 0.1 px are not switches); pieces of SPLIT_MIN_OBS or more.
SPLIT_DELTA_CHI2 = 25.0
SPLIT_MIN_SCALE_PX = 0.1
SPLIT_MIN_OBS = 3
SPLIT_NFEV = 40


def subset(obs: Observations, keep: np.ndarray) -> Observations:
    """The observations where ``keep`` (O,), tracks renumbered."""
    _, track = np.unique(obs.track[keep], return_inverse=True)
    return Observations.build(track, obs.t_s[keep], obs.ends_px[keep], obs.K)


def reject_outliers(obs: Observations, fit: RigidFit, t_ref: float) -> tuple[Observations, RigidFit]:
    """Peel outliers worst first: the track holding the worst observation loses its observations
    whose larger end-point residual exceeds ``max(OUTLIER_MIN_PX, OUTLIER_SCALES × robust scale)``
    (the whole track when under ``MIN_TRACK_OBS`` remain), the fit is repeated, and so on, at most
    ``OUTLIER_PEELS`` times and never below 2 tracks. Dropping every such observation at once lets
    one switched track, which pulls the rate and so the residuals of good tracks, take good
    observations with it. Returns the kept observations and their fit."""
    peeled = False
    for _ in range(OUTLIER_PEELS):
        r = _worse_end_px(fit)
        bad = r > max(OUTLIER_MIN_PX, OUTLIER_SCALES * robust_scale_px(fit.residuals_px))
        if not bad.any():
            break
        keep = ~(bad & (obs.track == obs.track[int(np.argmax(r))]))
        counts = np.bincount(obs.track[keep], minlength=obs.n_tracks)
        keep &= counts[obs.track] >= MIN_TRACK_OBS
        if len(np.unique(obs.track[keep])) < 2:
            break
        obs = subset(obs, keep)
        fit = fit_rigid(
            obs,
            fit.omega_rad_s,
            fit.axis,
            fit.c0,
            t_ref,
            drift=fit.drift,
            max_nfev=PEEL_NFEV,
            passes=1,
            uncertainty=False,
        )
        peeled = True
    if peeled:  # the short refits of the peeling only rank residuals; the kept tracks get a full fit
        fit = fit_rigid(obs, fit.omega_rad_s, fit.axis, fit.c0, t_ref, drift=fit.drift)
    return obs, fit


def _worse_end_px(fit: RigidFit) -> FloatArray:
    """Each observation's larger end-point residual (px, absolute)."""
    return np.asarray(np.abs(fit.residuals_px.reshape(-1, 2)).max(axis=1), dtype=float)


def without_stray_tracks(obs: Observations, fit: RigidFit) -> Observations | None:
    """``obs`` without the tracks whose median larger end-point residual under ``fit`` exceeds
    ``max(STRAY_MIN_PX, STRAY_FACTOR × the median track's)``; None when there are none, or when
    under 2 tracks would remain. A track that follows no rigid line (a shadow's edge, a track that
    switched edges for good) is off along its whole length, so the per-observation peeling,
    relative to a scale it inflates itself, can leave it in."""
    r = _worse_end_px(fit)
    per_track = np.array([np.median(r[obs.track == j]) for j in range(obs.n_tracks)])
    stray = per_track > max(STRAY_MIN_PX, STRAY_FACTOR * float(np.median(per_track)))
    if not stray.any() or int((~stray).sum()) < 2:
        return None
    return subset(obs, ~stray[obs.track])


def drop_stray_tracks(obs: Observations, fit: RigidFit, t_ref: float) -> tuple[Observations, RigidFit]:
    """The observations without stray tracks (``without_stray_tracks``) and their fit, refitted
    from ``fit``; ``obs`` and ``fit`` when none is dropped."""
    kept = without_stray_tracks(obs, fit)
    if kept is None:
        return obs, fit
    return kept, fit_rigid(kept, fit.omega_rad_s, fit.axis, fit.c0, t_ref, drift=fit.drift)


def split_piecewise_tracks(
    obs: Observations, fit: RigidFit, t_ref: float, gain_out: list[float] | None = None
) -> Observations | None:
    """``obs`` with every track that follows a rigid line only piecewise under ``fit``'s motion cut
    into its pieces; None when no track is cut.

    With the axis near the image plane the edges along the axis are parallel in the image and the
    edges across it move along their own direction, so a track can pass from one edge to another
    (at a silhouette where a face turns edge-on the two coincide) with no jump in angle or offset
    that ``tracking.reject_jumps`` could see. Such a track is two rigid lines, and a slow rotation
    with far-away lines explains the pair better than the true one (benchmark plane_100_clean:
    each of its five tracks of six or more frames followed 2-3 body edges, and the fit collapsed
    to 0.9 deg/s, truth 23.2; with the tracks cut at the true edges' changes, 0.1 % off). The cut
    is tested under ``fit``'s motion (ω, axis, centre and drift held): for each track of
    ``2·SPLIT_MIN_OBS`` or more observations (in time order), the split point where two lines fit
    best; the track is cut there when that lowers the least-squares χ² by over ``SPLIT_DELTA_CHI2``
    (σ² from the fit's robust scale), and its pieces are tested again. ``gain_out``, when given,
    is filled with the summed least-squares gain (px²) of the cuts made."""
    s2 = max(robust_scale_px(fit.residuals_px), SPLIT_MIN_SCALE_PX) ** 2
    track = obs.track.copy()
    n_new = obs.n_tracks
    pending = [np.flatnonzero(obs.track == j) for j in range(obs.n_tracks)]
    cut = False
    gain = 0.0
    while pending:
        idx = pending.pop()
        if len(idx) < 2 * SPLIT_MIN_OBS:
            continue
        idx = idx[np.argsort(obs.t_s[idx], kind="stable")]
        whole = _line_chi2(obs, idx, fit, t_ref)
        gains = [
            whole - _line_chi2(obs, idx[:k], fit, t_ref) - _line_chi2(obs, idx[k:], fit, t_ref)
            for k in range(SPLIT_MIN_OBS, len(idx) - SPLIT_MIN_OBS + 1)
        ]
        k = int(np.argmax(gains))
        if gains[k] / s2 <= SPLIT_DELTA_CHI2:
            continue
        head, tail = idx[: SPLIT_MIN_OBS + k], idx[SPLIT_MIN_OBS + k :]
        track[tail] = n_new
        n_new += 1
        cut = True
        gain += float(gains[k])
        pending += [head, tail]
    if gain_out is not None:
        gain_out[:] = [gain]
    if not cut:
        return None
    _, renumbered = np.unique(track, return_inverse=True)
    return Observations.build(renumbered, obs.t_s, obs.ends_px, obs.K)


def _line_chi2(obs: Observations, idx: np.ndarray, fit: RigidFit, t_ref: float) -> float:
    """The least-squares cost (px²) of the observations ``idx`` as one rigid line under ``fit``'s
    motion (ω, axis, centre and drift held; the line's 4 parameters fitted)."""
    from scipy.optimize import least_squares

    one = Observations.build(np.zeros(len(idx), dtype=int), obs.t_s[idx], obs.ends_px[idx], obs.K)
    p0, d0 = init_structure(one, fit.omega_rad_s, fit.axis, fit.c0, t_ref)
    model = RigidModel(one.track, one.t_s, one.ends_px, one.K, fit.axis, p0, d0, t_ref, fit.drift)
    held = np.r_[fit.omega_rad_s, 0.0, 0.0, fit.c0[:2], fit.velocity[:2] if fit.drift else np.zeros(0)]
    n = model.n_global
    res = least_squares(
        lambda x: model.residuals(np.r_[held, x]),
        np.zeros(4),
        jac=lambda x: model.jacobian(np.r_[held, x])[:, n:],
        method="lm",
        max_nfev=SPLIT_NFEV,
    )
    return float(np.sum(res.fun**2))


def rematch(
    segments_px: list[FloatArray], t_s: FloatArray, fit: RigidFit, obs: Observations, K: FloatArray
) -> Observations | None:
    """Every frame's segments assigned to the nearest fitted line: both ends within
    ``min(REMATCH_MAX_PX, max(REMATCH_MIN_PX, REMATCH_SCALES × robust scale))``, direction within
    ``REMATCH_DEG``, mutual nearest. Bridges missed frames and joins broken tracks.

    Parameters
    ----------
    segments_px : per frame, the segments' ideal (undistorted) end points (S, 2, 2), px.
    t_s : (F,) frame times (s); fit : the rigid fit of ``obs``; K : (3, 3) camera matrix.
    """
    t_ref = float(t_s[0])
    # Tracks that follow no rigid line (a shadow's edge) fit worse than the rest: kept only under
    # 3x the median track's residual (and 1 px).
    r = np.abs(fit.residuals_px.reshape(-1, 2))
    per_track = np.array([np.median(r[obs.track == j]) for j in range(obs.n_tracks)])
    limit = min(3.0 * float(np.median(per_track)), 1.0)
    inlier_tracks = [j for j in range(obs.n_tracks) if per_track[j] < limit]
    if len(inlier_tracks) < 2:
        return None
    gate = min(REMATCH_MAX_PX, max(REMATCH_MIN_PX, REMATCH_SCALES * robust_scale_px(fit.residuals_px)))
    trk, tt, ends = [], [], []
    for f, e in enumerate(segments_px):
        if len(e) == 0:
            continue
        lines = predict_lines(fit, K, float(t_s[f]), t_ref)[inlier_tracks]
        eh = np.concatenate([e, np.ones((*e.shape[:2], 1))], axis=2)
        dist = np.abs(np.einsum("ski,li->slk", eh, lines)).max(axis=2)  # (S, L)
        d = e[:, 1] - e[:, 0]
        d = d / np.linalg.norm(d, axis=1, keepdims=True)
        cosang = np.abs(d @ np.column_stack([-lines[:, 1], lines[:, 0]]).T)
        dist[cosang < np.cos(np.radians(REMATCH_DEG))] = np.inf
        for s in range(len(e)):
            j = int(np.argmin(dist[s]))
            if dist[s, j] < gate and int(np.argmin(dist[:, j])) == s:
                trk.append(j)
                tt.append(t_s[f])
                ends.append(e[s])
    if not trk:
        return None
    trk_a = np.array(trk)
    counts = np.bincount(trk_a, minlength=len(inlier_tracks))
    good = np.flatnonzero(counts >= MIN_TRACK_OBS)
    if len(good) < 2:
        return None
    remap = np.full(len(inlier_tracks), -1)
    remap[good] = np.arange(len(good))
    keep = remap[trk_a] >= 0
    return Observations.build(remap[trk_a[keep]], np.array(tt)[keep], np.array(ends)[keep], K)
