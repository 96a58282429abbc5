"""Per-frame marker identification and pose: which track is which marker, which observations are
outliers, and each frame's Kabsch pose.

Tracks carry identities between frames, forward and then backward; a frame whose tracks do not
give 3 consistent markers is identified from scratch by its distance signature (``labelling``).
New tracks join the marker they sit on after ``CONFIRM_FRAMES`` consistent frames; two points on
one marker (a glint starting next to a sphere) leave both out of that frame. A frame fails when
its robust fit fails the chi-square test (``labelling.fit_robust``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._typing import BoolArray, FloatArray, IntArray
from .labelling import Fit, Gates, _nearest, fit_robust, search
from .markers_io import MarkerInput

CONFIRM_FRAMES = 1  # a new track is used once it sat on the same marker this many frames in a row
MISS_FRAMES = 3  # a track that missed its marker this many frames in a row loses its identity
PREDICT_FRAMES = 5  # a pose this recent predicts where the markers are
RECENT_FRAMES = 25  # a search result must be within reach of a pose this recent
SCRATCH_FRAMES = 3  # frames a 3-point identification from scratch must repeat in (layouts over 4 markers)
BACKWARD_CONTEXT = 50  # frames after a left-out frame the backward pass runs through
STEP_M = 0.02  # how far a marker may move per frame [m] (1 m/s at 50 Hz)
LIKELIHOOD_RATIO_CHI2 = 2.0 * np.log(100.0)

# Per-observation status.
INLIER, REJECTED, CONFLICT, UNASSIGNED = 0, 1, 2, 3


@dataclass
class Association:
    """What identification found.

    obs_marker (N,): marker index of each inlier observation (-1 otherwise); obs_status (N,):
    INLIER, REJECTED (residual or chi-square), CONFLICT (two points on one marker) or UNASSIGNED;
    R (F, 3, 3), t (F, 3): each frame's Kabsch pose (NaN where none); measured (F,): 3 or more
    inlier markers and a passing chi-square; chi2 (F,); identity_changes: tracks relabelled."""

    obs_marker: IntArray
    obs_status: IntArray
    R: FloatArray
    t: FloatArray
    measured: BoolArray
    chi2: FloatArray
    ambiguous: BoolArray
    identity_changes: int = 0
    label_disagreements: int = 0
    searches: int = 0
    warnings: list[str] = field(default_factory=list)


class _Tracks:
    """Identity state per track: its marker, a pending marker with its streak, its misses."""

    def __init__(self, n: int) -> None:
        self.marker = np.full(n, -1, dtype=np.int64)
        self.pending = np.full(n, -1, dtype=np.int64)
        self.streak = np.zeros(n, dtype=np.int64)
        self.misses = np.zeros(n, dtype=np.int64)
        self.last_frame = -(10**9)
        self.scratch_key: tuple[tuple[int, int], ...] = ()
        self.scratch_count = 0
        self.last_R = np.eye(3)
        self.last_t = np.zeros(3)


def associate(data: MarkerInput, layout_m: FloatArray, gates: Gates) -> Association:
    """Identify every frame's markers against ``layout_m`` (M, 3) and fit each frame's pose: a
    forward pass, then a backward one for the frames the forward pass left out (before the first
    identification, or ambiguous until a later frame told the tracks apart)."""
    fwd = _associate_pass(data, layout_m, gates)
    # The backward pass sees each frame the forward pass left out, with the frames after it.
    todo = np.flatnonzero(~fwd.measured & ~fwd.ambiguous)
    if not len(todo):
        return fwd
    window = np.zeros(data.n_frames + BACKWARD_CONTEXT + 1, dtype=np.int64)
    np.add.at(window, todo, 1)
    np.add.at(window, todo + BACKWARD_CONTEXT + 1, -1)
    frames = np.flatnonzero(np.cumsum(window)[: data.n_frames] > 0)
    sub, sub_obs = _subset_reversed(data, frames)
    # Tracks start with the identity the forward pass first gave them: a stretch of 3 markers
    # before a 4th one showed up is then identified by its tracks.
    first = np.full(len(data.track_names), -1, dtype=np.int64)
    inl = np.flatnonzero(fwd.obs_marker >= 0)[::-1]  # written last = the earliest
    first[data.obs_track[inl]] = fwd.obs_marker[inl]
    bwd = _associate_pass(sub, layout_m, gates, first)
    back = frames[::-1]  # sub's frame i is data's frame back[i]
    take = bwd.measured & ~bwd.ambiguous & ~fwd.measured[back] & ~fwd.ambiguous[back]
    dst = back[take]
    fwd.R[dst], fwd.t[dst], fwd.chi2[dst] = bwd.R[take], bwd.t[take], bwd.chi2[take]
    fwd.measured[dst] = True
    obs_sub = take[sub.obs_frame]
    src_obs = np.flatnonzero(obs_sub)
    fwd.obs_marker[sub_obs[src_obs]] = bwd.obs_marker[src_obs]
    fwd.obs_status[sub_obs[src_obs]] = bwd.obs_status[src_obs]
    fwd.searches += bwd.searches
    return fwd


def _subset_reversed(data: MarkerInput, frames: IntArray) -> tuple[MarkerInput, IntArray]:
    """The observations of ``frames`` (indices, increasing) with time running backwards, and each
    observation's index in ``data``."""
    from dataclasses import replace

    keep = np.zeros(data.n_frames, dtype=bool)
    keep[frames] = True
    obs = np.flatnonzero(keep[data.obs_frame])[::-1]
    new_index = np.full(data.n_frames, -1, dtype=np.int64)
    new_index[frames[::-1]] = np.arange(len(frames))
    sub = replace(
        data,
        frames=data.frames[frames[::-1]],
        t_s=data.t_s[frames[::-1]],
        obs_frame=new_index[data.obs_frame[obs]],
        obs_track=data.obs_track[obs],
        xyz_m=data.xyz_m[obs],
        obs_label=np.full(len(obs), -1, dtype=np.int64),
    )
    return sub, obs


def _associate_pass(
    data: MarkerInput, layout_m: FloatArray, gates: Gates, track_marker: IntArray | None = None
) -> Association:
    F, N = data.n_frames, len(data.xyz_m)
    out = Association(
        obs_marker=np.full(N, -1, dtype=np.int64),
        obs_status=np.full(N, UNASSIGNED, dtype=np.int64),
        R=np.full((F, 3, 3), np.nan),
        t=np.full((F, 3), np.nan),
        measured=np.zeros(F, dtype=bool),
        chi2=np.full(F, np.nan),
        ambiguous=np.zeros(F, dtype=bool),
    )
    state = _Tracks(len(data.track_names))
    if track_marker is not None:
        state.marker[:] = track_marker
    starts = np.searchsorted(data.obs_frame, np.arange(F + 1))
    for f in range(F):
        idx = np.arange(starts[f], starts[f + 1])
        if len(idx):
            _frame(f, idx, data, layout_m, gates, state, out)
    _label_check(data, out)
    return out


def _frame(
    f: int, idx: IntArray, data: MarkerInput, L: FloatArray, gates: Gates, st: _Tracks, out: Association
) -> None:
    y, tr = data.xyz_m[idx], data.obs_track[idx]
    # 1. The tracks' identities give a first fit (a marker claimed twice is left out).
    known = st.marker[tr].copy()
    claimed = np.bincount(known[known >= 0], minlength=len(L))
    known[(known >= 0) & (claimed[np.maximum(known, 0)] > 1)] = -1
    assign = np.full(len(idx), -1, dtype=np.int64)
    fit = None
    use = known >= 0
    if use.sum() >= 3:
        fit = fit_robust(L[known[use]], y[use], gates)
        gap = abs(int(data.frames[f]) - st.last_frame)
        if fit is None or not fit.ok or fit.inlier.sum() < 3 or (gap <= RECENT_FRAMES and not _near_pose(fit, st, gap)):
            fit = None  # a jump from the last pose: identities swapped (a near-symmetric layout)
        else:
            assign[np.flatnonzero(use)[fit.inlier]] = known[use][fit.inlier]
    if fit is not None and use.all() and fit.inlier.all():
        # Every point on its track's marker and the frame consistent: nothing more to decide.
        out.R[f], out.t[f], out.chi2[f], out.measured[f] = fit.R, fit.t, fit.chi2, True
        st.last_frame, st.last_R, st.last_t = int(data.frames[f]), fit.R, fit.t
        out.obs_status[idx] = INLIER
        out.obs_marker[idx] = known
        st.misses[tr] = 0
        return
    fresh = False
    if fit is not None and (fit.inlier.sum() < use.sum() or (fit.inlier.sum() == 3 and len(idx) > 3)):
        # A track left out may have swapped identity, and 3 markers cannot show an outlier among
        # them: the frame's signature over all its points may explain more, or the same better.
        out.searches += 1
        n_fit = int(fit.inlier.sum())
        track_assign = np.full(len(idx), -1, dtype=np.int64)
        track_assign[np.flatnonzero(use)[fit.inlier]] = known[use][fit.inlier]
        gap = abs(int(data.frames[f]) - st.last_frame)
        hyps = [
            h
            for h in search(y, L, gates)
            if not np.array_equal(h[0], track_assign) and (gap > RECENT_FRAMES or _near_pose(h[1], st, gap))
        ]
        top = max([n_fit, *(int(np.sum(h[0] >= 0)) for h in hyps)])
        rivals = sorted(
            [(fit.chi2, track_assign, fit)] * (n_fit == top)
            + [(h[1].chi2, h[0], h[1]) for h in hyps if np.sum(h[0] >= 0) == top],
            key=lambda c: c[0],
        )
        best_is_tracks = rivals[0][1] is track_assign
        if len(rivals) > 1 and not best_is_tracks and rivals[1][0] - rivals[0][0] <= LIKELIHOOD_RATIO_CHI2:
            # Several subsets explain the frame about as well: which point is the outlier (or
            # which marker is which) cannot be told, so the frame is left out.
            _misses(st, tr, np.full(len(idx), -1))
            out.obs_status[idx] = REJECTED
            out.ambiguous[f] = True
            return
        if rivals[0][1] is not track_assign:
            assign, fit = rivals[0][1].copy(), rivals[0][2]
            fresh = True
    if fit is None:
        gap = abs(int(data.frames[f]) - st.last_frame)
        hyps = _predicted(y, L, gates, st, gap) if gap <= PREDICT_FRAMES else []
        if not hyps:
            out.searches += 1
            hyps = [h for h in search(y, L, gates) if gap > RECENT_FRAMES or _near_pose(h[1], st, gap)]
        chosen = _choose(hyps, st.marker[tr])
        # From scratch, 3 points of a layout of more than 4 markers are too weak a signature (a
        # gross error can make another triangle fit): wait for a 4th marker or a recent pose.
        scratch = gap > RECENT_FRAMES and not np.any(st.marker[tr] >= 0)
        if chosen is not None and scratch and len(L) > 4 and np.sum(chosen[0] >= 0) < 4:
            # ... unless the same tracks get the same markers in SCRATCH_FRAMES frames in a row.
            key = tuple(sorted(zip(tr[chosen[0] >= 0].tolist(), chosen[0][chosen[0] >= 0].tolist(), strict=True)))
            st.scratch_count = st.scratch_count + 1 if key == st.scratch_key else 1
            st.scratch_key = key
            if st.scratch_count < SCRATCH_FRAMES:
                chosen = None
        if chosen is None:
            _misses(st, tr, assign)
            return
        assign, fit = chosen
        fresh = True
    # 3. Other points join the marker they sit on (new tracks after a streak); two on one marker: both out.
    q = L @ fit.R.T + fit.t
    d = np.linalg.norm(y[:, None] - q[None], axis=-1)
    near = d < gates.gate_m
    crowded = near.sum(axis=0) > 1
    conflict = np.any(near & crowded[None], axis=1)
    assign[conflict] = -1
    taken = np.zeros(len(L), dtype=bool)
    taken[assign[assign >= 0]] = True
    for i in np.flatnonzero((assign < 0) & ~conflict):
        m = int(np.argmin(d[i]))
        if not near[i, m] or taken[m]:
            continue
        t_i = tr[i]
        if fresh or st.marker[t_i] == m:
            assign[i] = m
        else:
            st.streak[t_i] = st.streak[t_i] + 1 if st.pending[t_i] == m else 1
            st.pending[t_i] = m
            if st.streak[t_i] >= CONFIRM_FRAMES:
                assign[i] = m
        if assign[i] >= 0:
            taken[m] = True
    # 4. The frame's final fit and chi-square test over every assigned point; points just outside
    #    the gate of a free marker get a second look from the refined pose.
    used = assign >= 0
    final = fit_robust(L[assign[used]], y[used], gates) if used.sum() >= 3 else None
    if final is not None and final.ok:
        final, assign, used = _second_look(y, L, gates, assign, conflict, final)
    status = np.where(conflict, CONFLICT, UNASSIGNED)
    if final is not None:
        ui = np.flatnonzero(used)
        assign[ui[~final.inlier]] = -1
        status[ui[~final.inlier]] = REJECTED
        if final.ok and final.inlier.sum() >= 3:
            out.R[f], out.t[f], out.chi2[f], out.measured[f] = final.R, final.t, final.chi2, True
            st.last_frame, st.last_R, st.last_t = int(data.frames[f]), final.R, final.t
            status[assign >= 0] = INLIER
            out.obs_marker[idx] = assign
        else:
            status[used] = REJECTED
            assign[:] = -1
    out.obs_status[idx] = status
    # 5. Identities carried to the next frame.
    for i in np.flatnonzero(assign >= 0):
        t_i = tr[i]
        if st.marker[t_i] >= 0 and st.marker[t_i] != assign[i]:
            out.identity_changes += 1
        st.marker[t_i], st.misses[t_i], st.streak[t_i], st.pending[t_i] = assign[i], 0, 0, -1
    _misses(st, tr, assign)


def _second_look(
    y: FloatArray, L: FloatArray, gates: Gates, assign: IntArray, conflict: BoolArray, fit: Fit
) -> tuple[Fit, IntArray, BoolArray]:
    """Add unassigned points within twice the gate of a free marker as the fit places it, if the
    fit with them passes (a noisy pose can put a marker just beyond the gate)."""
    used = assign >= 0
    inl = np.flatnonzero(used)[fit.inlier]
    taken = np.zeros(len(L), dtype=bool)
    taken[assign[inl]] = True
    d = np.linalg.norm(y[:, None] - (L @ fit.R.T + fit.t)[None], axis=-1)
    trial = assign.copy()
    trial[np.flatnonzero(used)[~fit.inlier]] = -1
    added = False
    for i in np.flatnonzero((assign < 0) & ~conflict):
        m = int(np.argmin(np.where(taken, np.inf, d[i])))
        if not taken[m] and d[i, m] < 2.0 * gates.gate_m:
            trial[i], taken[m], added = m, True, True
    if not added:
        return fit, assign, used
    t_used = trial >= 0
    better = fit_robust(L[trial[t_used]], y[t_used], gates)
    if better is None or not better.ok or better.inlier.sum() <= fit.inlier.sum():
        return fit, assign, used
    return better, trial, t_used


def _predicted(y: FloatArray, L: FloatArray, gates: Gates, st: _Tracks, gap: int) -> list[tuple[IntArray, Fit]]:
    """The points on the markers as the last measured pose places them (gate widened by the gap)."""
    from scipy.optimize import linear_sum_assignment

    assign = _nearest(y, L @ st.last_R.T + st.last_t, gates.gate_m + STEP_M * gap, linear_sum_assignment)
    used = assign >= 0
    if used.sum() < 3:
        return []
    fit = fit_robust(L[assign[used]], y[used], gates)
    if fit is None or not fit.ok:
        return []
    assign[np.flatnonzero(used)[~fit.inlier]] = -1
    return [(assign, fit)]


def _near_pose(fit: Fit, st: _Tracks, gap: int) -> bool:
    """Whether a pose is within reach of the last measured one ``gap`` frames earlier."""
    cos_angle = (float(np.trace(fit.R @ st.last_R.T)) - 1.0) / 2.0
    angle = float(np.arccos(min(1.0, max(-1.0, cos_angle))))
    return angle <= np.radians(10.0 + 3.0 * gap) and float(np.linalg.norm(fit.t - st.last_t)) <= 0.05 + STEP_M * gap


def _choose(hyps: list[tuple[IntArray, Fit]], known: IntArray) -> tuple[IntArray, Fit] | None:
    """One hypothesis, or None when the frame is ambiguous: several hypotheses are kept only if
    exactly one agrees with the tracks' identities; relabelling a track needs 4 or more inliers."""

    def agrees(assign: IntArray) -> bool:
        both = (assign >= 0) & (known >= 0)
        return bool(np.all(assign[both] == known[both]))

    if len(hyps) > 1:
        agreeing = [h for h in hyps if agrees(h[0])]
        if len(agreeing) == 1:
            hyps = agreeing
        elif hyps[1][1].chi2 - hyps[0][1].chi2 > LIKELIHOOD_RATIO_CHI2:
            hyps = hyps[:1]  # the best explains the frame 100 times better than the next
        else:
            return None
    if not hyps:
        return None
    assign, fit = hyps[0]
    if not agrees(assign) and np.sum(assign >= 0) < 4:
        return None
    return assign, fit


def _misses(st: _Tracks, tr: IntArray, assign: IntArray) -> None:
    lost = tr[(assign < 0) & (st.marker[tr] >= 0)]
    st.misses[lost] += 1
    st.marker[lost[st.misses[lost] >= MISS_FRAMES]] = -1


def _label_check(data: MarkerInput, out: Association) -> None:
    """Count tracker labels that disagree with the identified marker (labels are verified, never trusted)."""
    if not data.label_names or data.layout is None:
        return
    ids = {name: i for i, name in enumerate(data.layout.ids)}
    lab = np.array([ids.get(name, -2) for name in data.label_names])
    has = (data.obs_label >= 0) & (out.obs_marker >= 0)
    bad = int(np.sum(lab[data.obs_label[has]] != out.obs_marker[has]))
    out.label_disagreements = bad
    if bad:
        out.warnings.append(f"{bad} tracker labels disagree with the identified markers (labels were not used)")
