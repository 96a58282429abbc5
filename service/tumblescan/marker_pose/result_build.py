"""Assembling the result document from the identification and the graph."""

from __future__ import annotations

import numpy as np

from .._typing import FloatArray
from .geometry import quat_wxyz, ypr_deg
from .graph import GraphResult
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
    first = int(np.argmax(~np.isnan(graph.R[:, 0, 0])))
    R0, t0 = graph.R[first], graph.t[first]
    q = quat_wxyz(np.where(np.isnan(graph.R), np.eye(3), graph.R))
    R_launch = np.einsum("ji,fjk->fik", R0, np.nan_to_num(graph.R))
    t_launch = (np.nan_to_num(graph.t) - t0) @ R0
    q_launch = quat_wxyz(np.where(np.isnan(graph.R), np.eye(3), R_launch))
    ypr = ypr_deg(np.where(np.isnan(graph.R), np.eye(3), R_launch))
    poses = []
    for f in range(F):
        have = not np.isnan(graph.R[f, 0, 0])
        poses.append(
            FramePose(
                frame=int(data.frames[f]),
                t=float(data.t_s[f]),
                status=graph.status[f],
                n_markers=int(n_markers[f]),
                T_world_body=PoseValue(q_wxyz=q[f].tolist(), t_m=graph.t[f].tolist()) if have else None,
                cov=graph.cov[f].tolist() if have and not np.isnan(graph.cov[f, 0, 0]) else None,
                T_launch_body=PoseValue(q_wxyz=q_launch[f].tolist(), t_m=t_launch[f].tolist()) if have else None,
                ypr_deg=ypr[f].tolist() if have else None,
                residual_rms_m=float(rms_frame[f]) if n_markers[f] else None,
            )
        )
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
        coverage=float(np.sum(assoc.measured & dense) / max(int(dense.sum()), 1)),
        warnings=warnings,
        timing_s=timing,
    )


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
