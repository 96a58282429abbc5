"""Multi-frame association: pairs that other frames support win the ambiguous frames.

Two stations cannot tell apart targets that share an epipolar plane (a plane through the
baseline): every cross pair of their rays meets. Time can: as the targets leave the shared
plane, the wrong pairs' χ² grows. So each station's detections are first linked into angle
tracks (the same KD-tree + assignment linker as the 3D tracks, on the unit sphere), every
pair of station tracks is scored by its likelihood ratio summed over the frames,
``Σ_f (χ²_f − G)`` plus a penalty ``G`` for each frame where both tracks are seen but their
rays fail the gate, and a one-to-one assignment of station tracks picks the pairs. Each frame
is then assigned again with those pairs favoured; a pair that wins only thanks to other
frames is flagged ``corrected_by_track``.
"""

from __future__ import annotations

import numpy as np

from .._typing import FloatArray, IntArray
from .assign import assign_sparse
from .associate import Candidates, FrameFixes, assign_frame
from .epipolar import rays_job
from .geometry import Station
from .inputs import Frame
from .tracks import link_tracks


def station_tracks(frames: list[Frame], station: Station, s: int, max_rate_rad_s: float) -> list[IntArray]:
    """Angle-track number of each of station ``s``'s detections, frame by frame."""
    u = [rays_job(fr.detections[s], station) for fr in frames]
    sig = [
        np.maximum(fr.detections[s].sigma_az_rad * np.cos(fr.detections[s].el_rad), fr.detections[s].sigma_el_rad)
        for fr in frames
    ]
    cov = [(g**2)[:, None, None] * np.eye(3) / 3.0 for g in sig]
    return link_tracks(
        [fr.t_s for fr in frames], u, cov, max_speed_m_s=max_rate_rad_s, max_accel_m_s2=0.01, max_gap_frames=2
    )


def associate_frames(
    frames: list[Frame],
    stations: tuple[Station, Station],
    cands: list[Candidates],
    *,
    gate: float,
    ambiguity_margin: float,
    max_rate_rad_s: float,
) -> list[FrameFixes]:
    """Every frame's targets, with ambiguous frames resolved by the station-track pairing."""
    # 1. Angle tracks at each station.
    t1 = station_tracks(frames, stations[0], 0, max_rate_rad_s)
    t2 = station_tracks(frames, stations[1], 1, max_rate_rad_s)
    n_t1 = 1 + max((int(a.max()) for a in t1 if a.size), default=-1)
    n_t2 = 1 + max((int(a.max()) for a in t2 if a.size), default=-1)
    # 2. Each station-track pair's likelihood ratio over the frames.
    e1 = np.concatenate([t1[f][c.i1] for f, c in enumerate(cands)]).astype(np.int64)
    e2 = np.concatenate([t2[f][c.i2] for f, c in enumerate(cands)]).astype(np.int64)
    llr = np.concatenate([c.fix.chi2 - gate for c in cands])
    keys, inverse = np.unique(e1 * max(n_t2, 1) + e2, return_inverse=True)
    score = np.bincount(inverse, llr, keys.size)
    n_edges = np.bincount(inverse, minlength=keys.size)
    k1, k2 = keys // max(n_t2, 1), keys % max(n_t2, 1)
    seen1 = _presence(t1, n_t1)
    seen2 = _presence(t2, n_t2)
    both = np.einsum("nf,nf->n", seen1[k1].astype(float), seen2[k2].astype(float))
    score = score + gate * (both - n_edges)
    chosen = assign_sparse(k1, k2, score, n_t1, n_t2)
    pair_ok = np.zeros(keys.size, dtype=bool)
    pair_ok[chosen] = True
    # 3. Each frame again, the chosen track pairs favoured.
    out = []
    start = 0
    for fr, c in zip(frames, cands, strict=True):
        n = c.i1.size
        favoured = pair_ok[inverse[start : start + n]]
        start += n
        bonus: FloatArray = np.where(favoured, ambiguity_margin, 0.0)
        out.append(
            assign_frame(
                c,
                len(fr.detections[0]),
                len(fr.detections[1]),
                gate=gate,
                ambiguity_margin=ambiguity_margin,
                bonus=bonus,
            )
        )
    return out


def _presence(tracks: list[IntArray], n: int) -> np.ndarray:
    """(n tracks, frames) bool: where each track has a detection."""
    seen = np.zeros((n, len(tracks)), dtype=bool)
    for f, ids in enumerate(tracks):
        seen[ids, f] = True
    return seen
