"""Assembling the result document from the identification and the graph."""

from __future__ import annotations

import numpy as np

from .._typing import FloatArray, IntArray
from .geometry import quat_wxyz, ypr_deg
from .graph import STATUS_MEASURED, GraphResult
from .identify import CONFLICT, REJECTED, Association
from .markers_io import MarkerInput
from .options import MarkerPoseOptions
from .result import (
    FramePose,
    GraphInfo,
    LayoutInfo,
    LayoutMarker,
    MarkerPoseResult,
    PoseValue,
    Rejection,
    Residuals,
    Segment,
)

MAX_REJECTIONS_LISTED = 1000


def build_result(
    data: MarkerInput,
    assoc: Association,
    graph: GraphResult,
    ids: list[str],
    options: MarkerPoseOptions,
    body_frame: str,
    sigma: float,
    warnings: list[str],
    timing: dict[str, float],
) -> MarkerPoseResult:
    F = data.n_frames
    inl = assoc.obs_marker >= 0
    n_markers = np.bincount(data.obs_frame[inl], minlength=F)
    # Residuals of every inlier against the final poses.
    k = data.obs_frame
    pred = np.einsum("nij,nj->ni", graph.R[k], graph.layout_m[np.maximum(assoc.obs_marker, 0)]) + graph.t[k]
    res = np.linalg.norm(data.xyz_m - pred, axis=1)
    ok = inl & np.isfinite(res)
    rms_frame = np.sqrt(np.bincount(k[ok], res[ok] ** 2, minlength=F) / np.maximum(np.bincount(k[ok], minlength=F), 1))
    rms = np.where(n_markers > 0, rms_frame, np.nan)
    poses = frame_poses(data.frames, data.t_s, graph.status, graph.R, graph.t, graph.cov, n_markers, rms_m=rms)
    per_marker = {
        ids[m]: float(np.sqrt(np.mean(res[ok & (assoc.obs_marker == m)] ** 2)))
        for m in range(len(ids))
        if np.any(ok & (assoc.obs_marker == m))
    }
    rejected = [
        Rejection(
            frame=int(data.frames[k[i]]),
            track=data.track_names[data.obs_track[i]],
            residual_m=_nearest_residual(data.xyz_m[i], graph, int(k[i])),
            reason="residual" if assoc.obs_status[i] == REJECTED else "conflict",
        )
        for i in np.flatnonzero((assoc.obs_status == REJECTED) | (assoc.obs_status == CONFLICT))[:MAX_REJECTIONS_LISTED]
    ]
    info = dict(graph.info)
    info.setdefault("landmarks", len(ids))
    info.setdefault("dof", 0)
    dense = np.bincount(data.obs_frame, minlength=F) >= 3
    posed = np.array([status == STATUS_MEASURED for status in graph.status])
    frame_markers = ids[:3]
    return MarkerPoseResult(
        method=options.method,
        body_frame=body_frame,
        point_sigma_m=sigma,
        motion_prior=options.motion_prior,
        poses=poses,
        layout=LayoutInfo(
            source="given" if data.layout is not None else "estimated",
            frame_markers=frame_markers,
            markers=[
                LayoutMarker(id=ids[m], xyz=graph.layout_m[m].tolist(), sigma_m=float(graph.layout_sigma_m[m]))
                for m in range(len(ids))
            ],
        ),
        associations=_associations(data, assoc, ids),
        segments=_segments(data, assoc, "chain" if options.method == "paper" else "layout"),
        graph=GraphInfo(**info),
        residuals=Residuals(
            rms_m=float(np.sqrt(np.mean(res[ok] ** 2))) if ok.any() else 0.0,
            per_marker_rms_m=per_marker,
            rejected=rejected,
        ),
        # Measured as the graph says: the paper's chain leaves out identified frames it cannot chain.
        coverage=float(np.sum(posed & dense) / max(int(dense.sum()), 1)),
        warnings=warnings,
        timing_s=timing,
    )


def frame_poses(
    frames: IntArray,
    t_s: FloatArray,
    status: list[str],
    R_world_body: FloatArray,
    t_world_m: FloatArray,
    cov: FloatArray,
    n_markers: IntArray,
    *,
    rms_m: FloatArray | None = None,
    rms_px: FloatArray | None = None,
    n_tags: IntArray | None = None,
) -> list[FramePose]:
    """One ``FramePose`` per frame: the pose in the world and in the launch frame (the body frame
    at the first frame with a pose), its covariance, and the frame's residual RMS (NaN: none).

    frames (F,) int, t_s (F,) [s], status (F,), R_world_body (F, 3, 3) and t_world_m (F, 3) with
    NaN rows where a frame has no pose, cov (F, 6, 6), n_markers (F,) int; rms_m or rms_px (F,)
    for levels A or B/C; n_tags (F,) int for levels B/C."""
    have = ~np.isnan(R_world_body[:, 0, 0])
    first = int(np.argmax(have))
    R0, t0 = R_world_body[first], t_world_m[first]
    Rs = np.where(have[:, None, None], R_world_body, np.eye(3))
    R_launch = np.einsum("ji,fjk->fik", R0, Rs)
    q, q_launch, ypr = quat_wxyz(Rs), quat_wxyz(R_launch), ypr_deg(R_launch)
    t_launch = (np.nan_to_num(t_world_m) - t0) @ R0

    def value(a: FloatArray | None, f: int) -> float | None:
        return None if a is None or np.isnan(a[f]) else float(a[f])

    return [
        FramePose(
            frame=int(frames[f]),
            t=float(t_s[f]),
            status=status[f],
            n_markers=int(n_markers[f]),
            T_world_body=PoseValue(q_wxyz=q[f].tolist(), t_m=t_world_m[f].tolist()) if have[f] else None,
            cov=cov[f].tolist() if have[f] and not np.isnan(cov[f, 0, 0]) else None,
            T_launch_body=PoseValue(q_wxyz=q_launch[f].tolist(), t_m=t_launch[f].tolist()) if have[f] else None,
            ypr_deg=ypr[f].tolist() if have[f] else None,
            residual_rms_m=value(rms_m, f),
            n_tags=None if n_tags is None else int(n_tags[f]),
            residual_rms_px=value(rms_px, f),
        )
        for f in range(len(frames))
    ]


def _nearest_residual(y: FloatArray, graph: GraphResult, f: int) -> float | None:
    if np.isnan(graph.R[f, 0, 0]):
        return None
    q = graph.layout_m @ graph.R[f].T + graph.t[f]
    return float(np.min(np.linalg.norm(q - y, axis=1)))


def _associations(data: MarkerInput, assoc: Association, ids: list[str]) -> dict[str, str | None]:
    out: dict[str, str | None] = dict.fromkeys(data.track_names)
    inl = assoc.obs_marker >= 0
    pairs = np.unique(np.column_stack([data.obs_track[inl], assoc.obs_marker[inl]]), axis=0, return_counts=True)
    best: dict[int, tuple[int, int]] = {}
    for (tr, m), n in zip(pairs[0], pairs[1], strict=True):
        if int(n) > best.get(int(tr), (0, -1))[0]:
            best[int(tr)] = (int(n), int(m))
    for tr, (_, m) in best.items():
        out[data.track_names[tr]] = ids[m]
    return out


def _segments(data: MarkerInput, assoc: Association, linked_by: str) -> list[Segment]:
    """Runs of frames whose tracks continue from one frame to the next (the paper's segments)."""
    starts = np.searchsorted(data.obs_frame, np.arange(data.n_frames + 1))
    segs: list[Segment] = []
    first = prev_frame = int(data.frames[0])
    prev: set[int] = set()
    for f in range(data.n_frames):
        tracks = set(data.obs_track[starts[f] : starts[f + 1]].tolist())
        num = int(data.frames[f])
        if f and (not (tracks & prev) or num != prev_frame + 1):
            segs.append(Segment(frames=[first, prev_frame], linked_by=linked_by))
            first = num
        prev, prev_frame = tracks, num
    segs.append(Segment(frames=[first, prev_frame], linked_by=linked_by))
    return segs
