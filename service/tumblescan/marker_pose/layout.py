"""Bootstrapping the layout when none is given: seed it from the first frame whose tracks stay
rigid, then grow it by the tracks that are rigid in the body frame (and moved in the world, so a
static reflection while the body rests is not taken for a marker). The graph then refines the
layout jointly with every pose (bundle adjustment)."""

from __future__ import annotations

from dataclasses import replace
from itertools import combinations

import numpy as np

from .._typing import FloatArray
from .errors import TooFewFramesError
from .geometry import launch_frame
from .identify import UNASSIGNED, Association, associate
from .labelling import Gates
from .markers_io import MarkerInput

SEED_WINDOW = 15  # frames over which seed tracks must keep their distances
MIN_FRAMES = 10  # a new marker is seen in this many measured frames first
SPREAD_SIGMA = 3.0  # a new marker's body coordinates scatter at most this much (pose error included)
MAX_ROUNDS = 6  # identify, refine and grow the layout at most this many times
DRIFT_ALPHA = 1e-3  # false-alarm rate of the test that a new marker's track slides over the body


def bootstrap_layout(data: MarkerInput, gates: Gates) -> tuple[FloatArray, tuple[int, int, int]]:
    """The layout (M, 3) in the launch frame of its first three markers, and those three (gauge)."""
    layout, gauge = _seed(data, gates)
    for _ in range(MAX_ROUNDS):
        assoc = associate(data, layout, gates)
        # Every marker from all frames it was identified in (the seed came from one frame), less
        # the grown ones that turn out to slide over the body now that the poses are better, then
        # the tracks that are new markers.
        refined = _refine(data, assoc.R, assoc.t, assoc.obs_marker, layout)
        keep = ~_sliding_markers(data, assoc, len(layout), gates)
        grown = _grow(data, assoc.R, assoc.t, assoc.measured, assoc.obs_status, refined[keep], gates)
        moved = float(np.max(np.linalg.norm(refined - layout, axis=1)))
        layout = grown
        if keep.all() and len(grown) == len(refined) and moved < 0.1 * gates.sigma_m:
            break
    else:  # the rounds ran out: the last round's new markers are checked for sliding all the same
        assoc = associate(data, layout, gates)
        layout = layout[~_sliding_markers(data, assoc, len(layout), gates)]
    return layout, gauge


def drop_unseen(data: MarkerInput, layout: FloatArray, assoc: Association) -> tuple[FloatArray, Association]:
    """A bootstrapped layout without the grown markers no measured frame identified (a near
    duplicate whose track its neighbour claims): such a marker has no factor in the graph, so no
    estimate and no covariance (GTSAM has no variable to marginalize). The seed's three hold the
    gauge and stay. The association is renumbered to match."""
    use = (assoc.obs_marker >= 0) & assoc.measured[data.obs_frame]
    seen = np.bincount(assoc.obs_marker[use], minlength=len(layout)) > 0
    seen[:3] = True
    if seen.all():
        return layout, assoc
    new_index = np.where(seen, np.cumsum(seen) - 1, -1)
    obs_marker = np.where(assoc.obs_marker >= 0, new_index[np.maximum(assoc.obs_marker, 0)], -1)
    gone = (assoc.obs_marker >= 0) & (obs_marker < 0)
    obs_status = np.where(gone, UNASSIGNED, assoc.obs_status)
    return layout[seen], replace(assoc, obs_marker=obs_marker, obs_status=obs_status)


def _refine(data: MarkerInput, R: FloatArray, t: FloatArray, obs_marker: np.ndarray, layout: FloatArray) -> FloatArray:
    """Each marker's body coordinates averaged over its inlier observations, in the launch frame of
    markers 1-3 again."""
    use = obs_marker >= 0
    k = data.obs_frame[use]
    body = np.einsum("nji,nj->ni", R[k], data.xyz_m[use] - t[k])
    M = len(layout)
    counts = np.bincount(obs_marker[use], minlength=M)
    sums = np.zeros((M, 3))
    np.add.at(sums, obs_marker[use], body)
    out = np.where(counts[:, None] > 0, sums / np.maximum(counts, 1)[:, None], layout)
    R_l, o_l = launch_frame(out[0], out[1], out[2])
    return np.asarray((out - o_l) @ R_l)


def _seed(data: MarkerInput, gates: Gates) -> tuple[FloatArray, tuple[int, int, int]]:
    starts = np.searchsorted(data.obs_frame, np.arange(data.n_frames + 1))
    tol = gates.gate_m * np.sqrt(2.0)
    for f in range(data.n_frames):
        idx = np.arange(starts[f], starts[f + 1])
        if len(idx) < 3:
            continue
        tr = data.obs_track[idx]
        later = np.arange(starts[f], starts[min(f + SEED_WINDOW, data.n_frames)])
        rigid = np.ones((len(idx), len(idx)), dtype=bool)
        for a, b in combinations(range(len(idx)), 2):
            pa = _positions(data, later, tr[a])
            pb = _positions(data, later, tr[b])
            common = sorted(set(pa) & set(pb))
            if len(common) < SEED_WINDOW // 2:
                rigid[a, b] = rigid[b, a] = False
                continue
            d = np.array([np.linalg.norm(pa[c] - pb[c]) for c in common])
            rigid[a, b] = rigid[b, a] = bool(np.max(np.abs(d - np.median(d))) < tol)
        for size in range(len(idx), 2, -1):
            for subset in combinations(range(len(idx)), size):
                if all(rigid[a, b] for a, b in combinations(subset, 2)):
                    p = data.xyz_m[idx[list(subset)]]
                    i1, i2, i3 = max(combinations(range(size), 3), key=lambda c: _area(p[list(c)]))
                    if _area(p[[i1, i2, i3]]) < (10 * gates.sigma_m) ** 2:
                        continue
                    R, o = launch_frame(p[i1], p[i2], p[i3])
                    body = (p - o) @ R
                    order = [i1, i2, i3] + [i for i in range(size) if i not in (i1, i2, i3)]
                    return body[order], (0, 1, 2)
    raise TooFewFramesError(
        "no frame has 3 markers that stay rigid: the layout cannot be bootstrapped", field="observations"
    )


def _positions(data: MarkerInput, later: np.ndarray, track: int) -> dict[int, FloatArray]:
    sel = later[data.obs_track[later] == track]
    return {int(data.obs_frame[i]): data.xyz_m[i] for i in sel}


def _area(p: FloatArray) -> float:
    return float(0.5 * np.linalg.norm(np.cross(p[1] - p[0], p[2] - p[0])))


def _grow(
    data: MarkerInput,
    R: FloatArray,
    t: FloatArray,
    measured: np.ndarray,
    status: np.ndarray,
    layout: FloatArray,
    gates: Gates,
) -> FloatArray:
    """Add the tracks seen in measured frames that are rigid in the body frame and moved in the world."""
    free = (status == UNASSIGNED) & measured[data.obs_frame]
    k = data.obs_frame[free]
    body = np.einsum("nji,nj->ni", R[k], data.xyz_m[free] - t[k])
    world = data.xyz_m[free]
    new = list(layout)
    tracks = data.obs_track[free]
    for tr in np.unique(tracks):
        sel = tracks == tr
        if sel.sum() < MIN_FRAMES:
            continue
        b, w = body[sel], world[sel]
        mean = b.mean(axis=0)
        # Rigid in the body: the scatter is the noise (pose error included); moved in the world.
        spread = float(np.sqrt(np.mean(np.sum((b - mean) ** 2, axis=1)) / 3.0))
        moved = float(np.max(np.linalg.norm(w - w.mean(axis=0), axis=1)))
        if spread > SPREAD_SIGMA * gates.sigma_m or moved < 10 * gates.sigma_m:
            continue
        if _slides(b, data.t_s[k[sel]], gates.sigma_m):
            continue
        if min(np.linalg.norm(np.array(new) - mean, axis=1)) < 2 * gates.gate_m:
            continue
        new.append(mean)
    return np.array(new)


def _sliding_markers(data: MarkerInput, assoc: Association, M: int, gates: Gates) -> np.ndarray:
    """(M,) bool: the grown markers (not the seed's three, which hold the gauge) most of whose
    observations come from tracks that slide over the body. A glint can be grown on the first
    round's poses (from the seed's three markers, noisy enough to hide its slide); a later round's
    poses show it."""
    R, t, obs_marker = assoc.R, assoc.t, assoc.obs_marker
    idx = np.flatnonzero((obs_marker >= 3) & assoc.measured[data.obs_frame])
    if not len(idx):
        return np.zeros(M, dtype=bool)
    sliding = np.zeros(M)
    # Group the observations by (marker, track).
    order = idx[np.lexsort((data.obs_track[idx], obs_marker[idx]))]
    key = obs_marker[order].astype(np.int64) * (int(data.obs_track.max()) + 1) + data.obs_track[order]
    bounds = np.flatnonzero(np.diff(key)) + 1
    for group in np.split(order, bounds):
        if len(group) < MIN_FRAMES:
            continue
        k = data.obs_frame[group]
        body = np.einsum("nji,nj->ni", R[k], data.xyz_m[group] - t[k])
        if _slides(body, data.t_s[k], gates.sigma_m):
            sliding[obs_marker[group[0]]] += len(group)
    return np.asarray(sliding > 0.5 * np.bincount(obs_marker[idx], minlength=M))


def _slides(body: FloatArray, t_s: FloatArray, sigma_m: float) -> bool:
    """Whether a track's body coordinates (n, 3) drift over its times (n,) [s]: the slope of their
    straight-line fit is significant against the scatter about it (an F test at DRIFT_ALPHA).

    A glint sliding over a sphere at a few cm/s stays within ``SPREAD_SIGMA`` of its mean for the
    half second it lasts, and its mean lies a few cm from the sphere, beyond the duplicate gate: the
    scatter alone would make it a marker. No marker moves on a rigid body, so a trend is the tell."""
    n = len(t_s)
    dt = t_s - t_s.mean()
    sxx = float(dt @ dt)
    if n < 4 or sxx <= 0.0:
        return False
    centred = body - body.mean(axis=0)
    slope = dt @ centred / sxx  # (3,) [m/s]
    scatter = float(np.sum((centred - np.outer(dt, slope)) ** 2)) / (3 * (n - 2))
    scatter = max(scatter, (1e-3 * sigma_m) ** 2)  # noiseless input: a trend of rounding is none
    from scipy.stats import f

    return float(slope @ slope) * sxx / (3.0 * scatter) > float(f.isf(DRIFT_ALPHA, 3, 3 * (n - 2)))
