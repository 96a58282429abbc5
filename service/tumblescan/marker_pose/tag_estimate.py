"""marker-pose-graph, levels B and C: target poses from tag corners seen by calibrated cameras.

Per frame, the joint multi-camera fit of ``tag_pose`` (maximum likelihood for Gaussian corners,
covariance from its Jacobian); then, with ``motion_prior: constant_velocity``, level A's GTSAM
white-noise-acceleration graph over those per-frame poses and covariances (it smooths and
bridges short gaps). Without a motion prior the per-frame fits are the answer: every frame is
registered to the tags' known layout, so nothing accumulates.
"""

from __future__ import annotations

import time

import numpy as np

from .._typing import FloatArray, Progress, no_progress
from .graph import STATUS_MEASURED, STATUS_MISSING, auto_psd, motion_graph, typical_sigma
from .options import TagPoseOptions
from .result import (
    DetectionInfo,
    GraphInfo,
    LayoutInfo,
    LayoutMarker,
    MarkerPoseResult,
    Rejection,
    Residuals,
    Segment,
)
from .result_build import MAX_REJECTIONS_LISTED, frame_poses
from .tag_pose import FrameFit, fit_tag_poses
from .tags_io import TagInput


def estimate_tag_poses(
    data: TagInput,
    options: TagPoseOptions | None = None,
    progress: Progress = no_progress,
    *,
    level: str = "B",
    detection: DetectionInfo | None = None,
    timing: dict[str, float] | None = None,
) -> MarkerPoseResult:
    """Estimate every frame's pose from validated level-B input (``tags_io``)."""
    options = options or TagPoseOptions()
    timing = dict(timing or {})
    warnings = list(data.warnings)
    sigma = np.array([options.pixel_sigma_px or c.pixel_sigma_px for c in data.cameras])
    progress("per-frame fits", 0.3)
    clock = time.perf_counter()
    fit = fit_tag_poses(data, sigma, options.outlier_sigma)
    if options.estimate_pixel_sigma and fit.measured.any():
        estimated = residual_sigma_px(fit)
        warnings.append(
            f"corner sigma estimated from the residuals: {estimated:.3f} px per axis "
            f"(declared {np.median(sigma):.3f} px); the covariances use it"
        )
        sigma = np.full(len(data.cameras), estimated)
        fit = fit_tag_poses(data, sigma, options.outlier_sigma)
    elif fit.dof > 0 and not 0.25 <= fit.chi2 / fit.dof <= 4.0:
        warnings.append(
            f"the corner residuals are {np.sqrt(fit.chi2 / fit.dof):.2f} x the declared pixel_sigma: "
            "the covariances are off by that factor (estimate_pixel_sigma: true estimates it)"
        )
    timing["per_frame_s"] = time.perf_counter() - clock
    if fit.ambiguous.any():
        warnings.append(
            f"{int(fit.ambiguous.sum())} frames fitted two poses about equally (a small tag seen alone can flip): "
            "the one nearest the previous frame's was kept; their covariances do not include the other"
        )
    R, t, cov = fit.R, fit.t, fit.cov
    status = [STATUS_MEASURED if m else STATUS_MISSING for m in fit.measured]
    n_corners = 4 * int(fit.inlier.sum())
    info: dict[str, object] = {
        "nodes": int(fit.measured.sum()),
        "landmarks": len(data.tag_ids),
        "factors": {"corner": n_corners, "motion": 0},
        "iterations": fit.iterations,
        "chi2_final": fit.chi2,
        "dof": fit.dof,
        "solver": "per-frame Gauss-Newton (multi-camera PnP)",
        "time_s": timing["per_frame_s"],
    }
    if options.motion_prior == "constant_velocity" and fit.measured.sum() >= 3:
        progress("graph", 0.6)
        q_rot, q_trans = auto_psd(data.t_s, R, t, fit.measured, typical_sigma(cov, 0), typical_sigma(cov, 3))
        R, t, cov, status, minfo = motion_graph(
            data.t_s,
            R,
            t,
            cov,
            fit.measured,
            q_rot=options.angular_accel_psd or q_rot,
            q_trans=options.accel_psd or q_trans,
            max_bridge_frames=options.max_bridge_frames,
            frame_numbers=data.frames,
            robust="none",
            robust_k=3.0,
            marginals=options.marginals,
        )
        info.update(
            nodes=minfo["nodes"],
            factors={"corner": n_corners, "pose": minfo["factors"]["pose"], "motion": minfo["factors"]["motion"]},
            iterations=fit.iterations + minfo["iterations"],
            solver="per-frame Gauss-Newton + gtsam LM (constant velocity)",
            psd=minfo["psd"],
            time_s=timing["per_frame_s"] + minfo["time_s"],
        )
        timing["graph_s"] = minfo["time_s"]
    elif options.motion_prior == "constant_velocity":
        warnings.append("fewer than 3 measured frames: the motion prior was not applied")
    if not options.marginals:
        cov = np.full_like(cov, np.nan)
    progress("result", 0.9)
    return _result(data, fit, R, t, cov, status, info, options, sigma, warnings, timing, level, detection)


def residual_sigma_px(fit: FrameFit) -> float:
    """A robust corner sigma per image axis [px] from the inlier residuals: ``1.4826 median|r|``
    (a gross error does not move it), scaled by ``sqrt(n / dof)`` for the 6 pose parameters each
    frame's fit absorbed."""
    use = fit.inlier
    r = np.abs(fit.residual_px[use]).ravel()
    r = r[np.isfinite(r)]
    if len(r) < 8 or fit.dof <= 0:
        return float(np.sqrt(np.mean(r**2))) if len(r) else 1.0
    return float(max(1.4826 * np.median(r) * np.sqrt(len(r) / fit.dof), 1e-3))


def _result(
    data: TagInput,
    fit: FrameFit,
    R: FloatArray,
    t: FloatArray,
    cov: FloatArray,
    status: list[str],
    info: dict[str, object],
    options: TagPoseOptions,
    sigma: FloatArray,
    warnings: list[str],
    timing: dict[str, float],
    level: str,
    detection: DetectionInfo | None,
) -> MarkerPoseResult:
    F = data.n_frames
    k = data.det_frame
    n_tags = np.bincount(k[fit.inlier], minlength=F)
    res2 = np.sum(fit.residual_px**2, axis=-1)  # (N, 4)
    ok = fit.inlier & np.isfinite(res2).all(axis=1)
    rms_frame = np.sqrt(np.bincount(k[ok], res2[ok].sum(axis=1), minlength=F) / np.maximum(4 * n_tags, 1))
    rms_px = np.where(n_tags > 0, rms_frame, np.nan)
    poses = frame_poses(data.frames, data.t_s, status, R, t, cov, 4 * n_tags, rms_px=rms_px, n_tags=n_tags)
    ids = [str(i) for i in data.tag_ids]
    per_tag = {
        ids[j]: float(np.sqrt(np.mean(res2[ok & (data.det_tag == j)])))
        for j in range(len(ids))
        if np.any(ok & (data.det_tag == j))
    }
    rejected_rows = np.flatnonzero(~fit.inlier & fit.measured[k])[:MAX_REJECTIONS_LISTED]
    rejected = [
        Rejection(
            frame=int(data.frames[k[i]]),
            track=f"{data.cameras[data.det_cam[i]].id}/tag{data.tag_ids[data.det_tag[i]]}",
            residual_m=None,
            residual_px=float(np.sqrt(np.max(res2[i]))),
            reason="residual",
        )
        for i in rejected_rows
    ]
    seen = np.bincount(k, minlength=F) > 0
    return MarkerPoseResult(
        level=level,
        method="graph",
        body_frame="layout",
        point_sigma_m=None,
        pixel_sigma_px={c.id: float(s) for c, s in zip(data.cameras, sigma, strict=True)},
        detection=detection,
        motion_prior=options.motion_prior,
        poses=poses,
        layout=LayoutInfo(
            source="given",
            frame_markers=[],
            markers=[
                LayoutMarker(id=ids[j], xyz=data.T_body_tag[j, :3, 3].tolist(), sigma_m=0.0) for j in range(len(ids))
            ],
        ),
        associations={},
        segments=_segments(data, fit),
        graph=GraphInfo(**info),
        residuals=Residuals(
            rms_m=None,
            per_marker_rms_m={},
            rms_px=float(np.sqrt(np.mean(res2[ok]))) if ok.any() else None,
            per_tag_rms_px=per_tag,
            rejected=rejected,
        ),
        coverage=float(np.sum(fit.measured & seen) / max(int(seen.sum()), 1)),
        warnings=warnings,
        timing_s=timing,
    )


def _segments(data: TagInput, fit: FrameFit) -> list[Segment]:
    """Runs of consecutive frame numbers with a measured pose."""
    segs: list[Segment] = []
    start = prev = None
    for f in np.flatnonzero(fit.measured):
        n = int(data.frames[f])
        if prev is None or n != prev + 1:
            if start is not None:
                segs.append(Segment(frames=[start, prev], linked_by="layout"))
            start = n
        prev = n
    if start is not None:
        segs.append(Segment(frames=[start, prev], linked_by="layout"))
    return segs
