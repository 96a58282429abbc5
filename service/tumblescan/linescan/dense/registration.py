"""Rigid registration of consecutive frames (Open3D): the inter-frame rotations that the cone
initializer (method.md section 5) turns into a first motion estimate.

Per frame: voxel downsampling, normals oriented towards the sensor, FPFH features. Per pair
``(k, k+1)``: RANSAC on feature matches (global, no initial guess needed), then point-to-plane
ICP. Later passes skip RANSAC and start ICP from the transform the current motion predicts,
after each frame has been re-timed to its mean time (so the in-frame smear is gone).

The target may be symmetric (a box with two equal panels is, under 180 degree turns): a
global registration can then return the true rotation composed with a symmetry. Such pairs
usually show as rotation angles far from the others' (the cone's rotation angle is the same
for every pair) and are refused by :func:`consistent_pairs`; when they are the majority (a
fast symmetric tumbler), :mod:`tumblescan.consensus` finds the pairs one motion explains.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ..._open3d import load_open3d, one_thread
from ..._typing import FloatArray

if TYPE_CHECKING:
    import open3d as o3d


# Voxel size as a fraction of the target's extent (its bounding-box diagonal in the first frame).
VOXEL_FRACTION = 1 / 60
# A pair whose rotation angle differs from the median by more than this is inconsistent.
MAX_ANGLE_DEVIATION_RAD = np.radians(10.0)
RANSAC_ITERATIONS = 100_000
RANSAC_CONFIDENCE = 0.999
ICP_ITERATIONS = 50


@dataclass(frozen=True)
class PairTransforms:
    """``p(frame k+1) = R[k] p(frame k) + t[k]`` for each consecutive pair; ``fitness`` is the
    share of frame-k points with a partner within the ICP distance, ``rmse_m`` their RMS."""

    R: FloatArray  # (P, 3, 3)
    t: FloatArray  # (P, 3)
    fitness: FloatArray  # (P,)
    rmse_m: FloatArray  # (P,)


def extent_m(frames_xyz: list[FloatArray]) -> float:
    """The target's size: the largest frame's bounding-box diagonal, metres."""
    return max((float(np.linalg.norm(np.ptp(f, axis=0))) for f in frames_xyz if len(f)), default=0.0)


def register_consecutive(
    frames_xyz: list[FloatArray],
    *,
    voxel_m: float,
    initial: PairTransforms | None = None,
    seed: int = 0,
) -> PairTransforms:
    """Register frame ``k`` onto frame ``k+1`` for every ``k``.

    frames_xyz: one ``(n_k, 3)`` array per frame, metres, sensor frame. voxel_m: downsampling
    voxel. initial: start ICP from these transforms instead of a global RANSAC search.
    """
    with one_thread():  # repeatable: see one_thread
        return _register(frames_xyz, voxel_m=voxel_m, initial=initial, seed=seed)


def _register(
    frames_xyz: list[FloatArray], *, voxel_m: float, initial: PairTransforms | None, seed: int
) -> PairTransforms:
    o3d = load_open3d()
    o3d.utility.random.seed(seed)
    prepared = [_prepare(f, voxel_m, features=initial is None) for f in frames_xyz]
    Rs, ts, fit, rmse = [], [], [], []
    for k in range(len(frames_xyz) - 1):
        (src, src_f), (dst, dst_f) = prepared[k], prepared[k + 1]
        if initial is None:
            guess = _global(src, dst, src_f, dst_f, voxel_m)
        else:
            guess = np.eye(4)
            guess[:3, :3], guess[:3, 3] = initial.R[k], initial.t[k]
        icp = o3d.pipelines.registration.registration_icp(
            src,
            dst,
            2 * voxel_m,
            guess,
            o3d.pipelines.registration.TransformationEstimationPointToPlane(),
            o3d.pipelines.registration.ICPConvergenceCriteria(max_iteration=ICP_ITERATIONS),
        )
        T = np.asarray(icp.transformation)
        Rs.append(T[:3, :3])
        ts.append(T[:3, 3])
        fit.append(icp.fitness)
        rmse.append(icp.inlier_rmse)
    return PairTransforms(np.array(Rs), np.array(ts), np.array(fit), np.array(rmse))


def consistent_pairs(pairs: PairTransforms) -> NDArray[np.bool_]:
    """Pairs whose rotation angle is near the median angle (see the module docstring)."""
    angles = np.arccos(np.clip((np.trace(pairs.R, axis1=1, axis2=2) - 1) / 2, -1.0, 1.0))
    return np.asarray(np.abs(angles - np.median(angles)) <= MAX_ANGLE_DEVIATION_RAD)


def _prepare(xyz: FloatArray, voxel_m: float, *, features: bool) -> tuple[o3d.geometry.PointCloud, Any]:
    o3d = load_open3d()

    pcd = o3d.geometry.PointCloud()
    pcd.points = o3d.utility.Vector3dVector(xyz)
    pcd = pcd.voxel_down_sample(voxel_m)
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2 * voxel_m, max_nn=30))
    pcd.orient_normals_towards_camera_location(np.zeros(3))
    if not features:
        return pcd, None
    fpfh = o3d.pipelines.registration.compute_fpfh_feature(
        pcd, o3d.geometry.KDTreeSearchParamHybrid(radius=5 * voxel_m, max_nn=100)
    )
    return pcd, fpfh


def _global(src: Any, dst: Any, src_f: Any, dst_f: Any, voxel_m: float) -> FloatArray:
    o3d = load_open3d()

    reg = o3d.pipelines.registration
    result = reg.registration_ransac_based_on_feature_matching(
        src,
        dst,
        src_f,
        dst_f,
        True,
        1.5 * voxel_m,
        reg.TransformationEstimationPointToPoint(False),
        3,
        [reg.CorrespondenceCheckerBasedOnEdgeLength(0.9), reg.CorrespondenceCheckerBasedOnDistance(1.5 * voxel_m)],
        reg.RANSACConvergenceCriteria(RANSAC_ITERATIONS, RANSAC_CONFIDENCE),
    )
    return np.asarray(result.transformation, dtype=float)
