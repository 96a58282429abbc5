"""Checking a result against a simulation's truth: per frame ``e = (log(R_t R_e^T), p_t - p_e)``,
the efficiency ratio ``sqrt(mean e^T C^-1 e / 6)`` against the per-frame bound, the worst frame's
Mahalanobis distance, coverage, NEES of the reported covariance, drift and 3-sigma errors."""

from __future__ import annotations

from collections import Counter
from typing import Any

import numpy as np

from .geometry import launch_frame, log_so3, matrix_from_quat_wxyz, skew
from .result import FramePose, MarkerPoseResult


def evaluate(result: MarkerPoseResult, truth: dict[str, Any]) -> dict[str, float]:
    """Scores of ``result`` against ``truth`` (both as written by ``simulate``)."""
    ids = truth["layout"]["ids"]
    p_true = np.array(truth["layout"]["xyz"])
    given = result.layout.source == "given"
    # The estimate's body frame in the true body frame: the layout's own, or the launch frame of
    # the markers the estimate named M1-M3 (found through the track associations).
    R_c, o_c = np.eye(3), np.zeros(3)
    if not given or result.body_frame == "launch":
        if given:
            p3 = [p_true[ids.index(m)] for m in result.layout.frame_markers]
        else:
            to_true = _marker_map(result, truth)
            p3 = [p_true[ids.index(to_true[m])] for m in result.layout.frame_markers]
        R_c, o_c = launch_frame(*p3)
    key = "crlb" if given else "crlb_self_calibrated"
    frames = {f["frame"]: f for f in truth["frames"]}
    d2, nees, errs, bound_frames, covered = [], [], [], 0, 0
    unbounded: list[float] = []  # measured frames without 3 true inliers: error against the own covariance
    for pose in result.poses:
        tf = frames[pose.frame]
        if tf[key] is None:
            if pose.status == "measured" and pose.T_world_body is not None and pose.cov is not None:
                e = _error(tf, pose, R_c, o_c)
                unbounded.append(float(np.sqrt(e @ np.linalg.solve(np.array(pose.cov), e))))
            continue
        bound_frames += 1
        if pose.status != "measured" or pose.T_world_body is None:
            continue
        covered += 1
        e = _error(tf, pose, R_c, o_c)
        A = np.eye(6)
        A[3:, :3] = -skew(matrix_from_quat_wxyz(np.array(tf["q_wxyz"])) @ o_c)
        C = A @ np.array(tf[key]) @ A.T
        d2.append(float(e @ np.linalg.solve(C, e)))
        if pose.cov is not None:
            nees.append(float(e @ np.linalg.solve(np.array(pose.cov), e)))
        errs.append(e)
    E = np.array(errs) if errs else np.zeros((1, 6))
    half = len(E) // 2
    return {
        "ratio": float(np.sqrt(np.mean(d2) / 6.0)) if d2 else float("nan"),
        "worst_mahalanobis": float(np.sqrt(np.max(d2))) if d2 else float("nan"),
        "coverage": covered / max(bound_frames, 1),
        "nees_over_6": float(np.mean(nees) / 6.0) if nees else float("nan"),
        "rot_3sigma_deg": float(np.degrees(3 * np.sqrt(np.mean(np.sum(E[:, :3] ** 2, axis=1)) / 3))),
        "pos_3sigma_mm": float(1000 * 3 * np.sqrt(np.mean(np.sum(E[:, 3:] ** 2, axis=1)) / 3)),
        "max_rot_deg": float(np.degrees(np.max(np.linalg.norm(E[:, :3], axis=1)))),
        # Drift: the mean error of the last half against the first (0 when nothing accumulates).
        "drift_deg": float(np.degrees(np.linalg.norm(E[half:, :3].mean(axis=0) - E[:half, :3].mean(axis=0))))
        if half
        else 0.0,
        "unbounded_measured": float(len(unbounded)),
        "unbounded_worst_sigma": max(unbounded, default=0.0),
        "drift_mm": float(1000 * np.linalg.norm(E[half:, 3:].mean(axis=0) - E[:half, 3:].mean(axis=0)))
        if half
        else 0.0,
    }


def _error(tf: dict[str, Any], pose: FramePose, R_c: np.ndarray, o_c: np.ndarray) -> np.ndarray:
    """``(log(R_t R_e^T), p_t - p_e)`` of one frame, the truth re-expressed in the estimate's body frame."""
    assert pose.T_world_body is not None
    R_true = matrix_from_quat_wxyz(np.array(tf["q_wxyz"]))
    R_e = matrix_from_quat_wxyz(np.array(pose.T_world_body.q_wxyz))
    t_t = np.array(tf["t_m"]) + R_true @ o_c
    return np.asarray(np.r_[log_so3(R_true @ R_c @ R_e.T), t_t - np.array(pose.T_world_body.t_m)])


def _marker_map(result: MarkerPoseResult, truth: dict[str, Any]) -> dict[str, str]:
    """Estimated marker id -> true marker id, by the majority of the tracks associated with it."""
    votes: dict[str, Counter[str]] = {}
    for track, est in result.associations.items():
        true = truth["tracks"].get(track)
        if est is not None and true is not None:
            votes.setdefault(est, Counter())[true] += 1
    return {est: c.most_common(1)[0][0] for est, c in votes.items()}
