"""Calibrated rig cameras and the projection of body points through them (levels B and C).

Camera model (OpenCV): a point ``p_world`` goes to the camera frame by
``p_cam = R_world_cam^T (p_world - t_world_cam)`` (camera axes x right, y down, z forward), then
``x = X/Z, y = Y/Z``, ``r^2 = x^2 + y^2``,
``x_d = x (1 + k1 r^2 + k2 r^4 + k3 r^6) + 2 p1 x y + p2 (r^2 + 2 x^2)``,
``y_d = y (1 + k1 r^2 + k2 r^4 + k3 r^6) + p1 (r^2 + 2 y^2) + 2 p2 x y``,
``u = fx x_d + s y_d + cx``, ``v = fy y_d + cy``. Pixel centres are at integer coordinates
((0, 0) is the centre of the top-left pixel).

Pose perturbations are world-side, as in the result's covariance: ``R = exp([dtheta]x) R0``,
``t = t0 + dp``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._typing import FloatArray, IntArray
from .geometry import skew


@dataclass(frozen=True)
class RigCamera:
    """One calibrated camera: ``K`` (3, 3) [px], ``dist`` (5,) OpenCV k1 k2 p1 p2 k3,
    ``R_world_cam`` (3, 3) and ``t_world_cam`` (3,) [m] (camera to world), image size [px] and the
    1-sigma error of a tag corner per image axis [px]."""

    id: str
    width_px: int
    height_px: int
    K: FloatArray
    dist: FloatArray
    R_world_cam: FloatArray
    t_world_cam: FloatArray
    pixel_sigma_px: float


@dataclass(frozen=True)
class RigArrays:
    """The cameras stacked for vectorized projection: K (C, 3, 3), dist (C, 5), R_cam_world (C, 3, 3),
    t_world_cam (C, 3), sigma (C,) [px]."""

    K: FloatArray
    dist: FloatArray
    R_cam_world: FloatArray
    t_world_cam: FloatArray
    sigma_px: FloatArray

    @staticmethod
    def of(cameras: list[RigCamera]) -> RigArrays:
        return RigArrays(
            K=np.array([c.K for c in cameras], dtype=float),
            dist=np.array([c.dist for c in cameras], dtype=float),
            R_cam_world=np.array([c.R_world_cam.T for c in cameras], dtype=float),
            t_world_cam=np.array([c.t_world_cam for c in cameras], dtype=float),
            sigma_px=np.array([c.pixel_sigma_px for c in cameras], dtype=float),
        )


def distort_pixels(xy: FloatArray, K: FloatArray, dist: FloatArray) -> FloatArray:
    """Normalized image points ``xy`` (..., 2) to pixels (..., 2) through ``K`` (..., 3, 3) and
    ``dist`` (..., 5) (broadcast over the leading axes)."""
    x, y = xy[..., 0], xy[..., 1]
    k1, k2, p1, p2, k3 = (dist[..., i] for i in range(5))
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    u = K[..., 0, 0] * xd + K[..., 0, 1] * yd + K[..., 0, 2]
    v = K[..., 1, 1] * yd + K[..., 1, 2]
    return np.stack([u, v], axis=-1)


def to_camera(p_world_m: FloatArray, cam: IntArray, rig: RigArrays) -> FloatArray:
    """World points (N, P, 3) seen by cameras ``cam`` (N,) -> camera-frame points (N, P, 3) [m]."""
    return np.asarray((p_world_m - rig.t_world_cam[cam][:, None]) @ np.transpose(rig.R_cam_world[cam], (0, 2, 1)))


def project(p_cam_m: FloatArray, cam: IntArray, rig: RigArrays) -> FloatArray:
    """Camera-frame points (N, P, 3) of cameras ``cam`` (N,) -> pixels (N, P, 2)."""
    z = p_cam_m[..., 2:3]
    xy = p_cam_m[..., :2] / z
    return distort_pixels(xy, rig.K[cam][:, None], rig.dist[cam][:, None])


def project_with_jacobian(p_cam_m: FloatArray, cam: IntArray, rig: RigArrays) -> tuple[FloatArray, FloatArray]:
    """Pixels (N, P, 2) of camera-frame points (N, P, 3) and their Jacobian d(u, v)/d(p_cam)
    (N, P, 2, 3), analytic: the distortion's derivatives (module docstring's model) chained with
    ``d(x, y)/d(X, Y, Z) = [[1/Z, 0, -X/Z^2], [0, 1/Z, -Y/Z^2]]``."""
    X, Y, Z = p_cam_m[..., 0], p_cam_m[..., 1], p_cam_m[..., 2]
    x, y = X / Z, Y / Z
    K = rig.K[cam][:, None]
    d = rig.dist[cam][:, None]
    k1, k2, p1, p2, k3 = (d[..., i] for i in range(5))
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    dradial_dr2 = k1 + r2 * (2.0 * k2 + 3.0 * r2 * k3)
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    dxd_dx = radial + 2.0 * x * x * dradial_dr2 + 2.0 * p1 * y + 6.0 * p2 * x
    dxd_dy = 2.0 * x * y * dradial_dr2 + 2.0 * p1 * x + 2.0 * p2 * y
    dyd_dx = 2.0 * x * y * dradial_dr2 + 2.0 * p1 * x + 2.0 * p2 * y
    dyd_dy = radial + 2.0 * y * y * dradial_dr2 + 6.0 * p1 * y + 2.0 * p2 * x
    fx, s, fy = K[..., 0, 0], K[..., 0, 1], K[..., 1, 1]
    uv = np.stack([fx * xd + s * yd + K[..., 0, 2], fy * yd + K[..., 1, 2]], axis=-1)
    # d(u, v)/d(x, y)
    A = np.empty((*x.shape, 2, 2))
    A[..., 0, 0] = fx * dxd_dx + s * dyd_dx
    A[..., 0, 1] = fx * dxd_dy + s * dyd_dy
    A[..., 1, 0] = fy * dyd_dx
    A[..., 1, 1] = fy * dyd_dy
    B = np.zeros((*x.shape, 2, 3))
    B[..., 0, 0] = B[..., 1, 1] = 1.0 / Z
    B[..., 0, 2] = -x / Z
    B[..., 1, 2] = -y / Z
    return uv, A @ B


def world_points(R_world_body: FloatArray, t_world_m: FloatArray, p_body_m: FloatArray) -> FloatArray:
    """Body points (N, P, 3) under per-row poses R (N, 3, 3), t (N, 3) -> world (N, P, 3) [m]."""
    return np.einsum("nij,npj->npi", R_world_body, p_body_m) + t_world_m[:, None]


def body_to_pixels(
    R_world_body: FloatArray, t_world_m: FloatArray, p_body_m: FloatArray, cam: IntArray, rig: RigArrays
) -> FloatArray:
    """Body points (N, P, 3) under per-row poses (N, 3, 3), (N, 3), seen by cameras ``cam`` (N,)
    -> pixels (N, P, 2)."""
    return project(to_camera(world_points(R_world_body, t_world_m, p_body_m), cam, rig), cam, rig)


def projection_jacobian(
    R_world_body: FloatArray, t_world_m: FloatArray, p_body_m: FloatArray, cam: IntArray, rig: RigArrays
) -> tuple[FloatArray, FloatArray]:
    """Pixels (N, P, 2) of body points and their Jacobian (N, P, 2, 6) with respect to the pose
    perturbation (dtheta_world [rad], dp_world [m]).

    ``d p_world = -[R p_body]x dtheta + dp``, ``d p_cam = R_cam_world d p_world``, then the
    projection's own Jacobian (``project_with_jacobian``)."""
    q = p_body_m @ np.transpose(R_world_body, (0, 2, 1))
    p_cam = to_camera(q + t_world_m[:, None], cam, rig)
    uv, dproj = project_with_jacobian(p_cam, cam, rig)
    # d(u, v)/d(dtheta, dp) = dproj R_cam_world [-[q]x, I]
    dproj_world = dproj @ rig.R_cam_world[cam][:, None]  # (N, P, 2, 3)
    J = np.empty((*q.shape[:2], 2, 6))
    J[..., :3] = -(dproj_world @ skew(q))
    J[..., 3:] = dproj_world
    return uv, J


def tag_corners_body(T_body_tag: FloatArray, size_m: float) -> FloatArray:
    """The four corners of each tag's black square in the body frame (T, 4, 3), in the order
    TL, TR, BR, BL (tag frame: x right, y up as printed, z out of the face; as ArUco and
    ``SOLVEPNP_IPPE_SQUARE``). T_body_tag: (T, 4, 4); size_m: edge of the black square [m]."""
    h = 0.5 * size_m
    local = np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])
    return np.einsum("tij,pj->tpi", T_body_tag[:, :3, :3], local) + T_body_tag[:, None, :3, 3]


def pose_information_px(
    R_world_body: FloatArray,
    t_world_m: FloatArray,
    corners_body_m: FloatArray,
    cam: IntArray,
    rig: RigArrays,
) -> FloatArray:
    """Fisher information (6, 6) of one pose from tag corners seen by cameras: ``sum J^T J / sigma^2``
    over every corner's 2 pixel coordinates. corners_body_m (N, 4, 3): the tags seen; cam (N,):
    which camera saw each. Order (dtheta_world [rad], dp_world [m])."""
    n = len(cam)
    _, J = projection_jacobian(
        np.broadcast_to(R_world_body, (n, 3, 3)), np.broadcast_to(t_world_m, (n, 3)), corners_body_m, cam, rig
    )
    w = 1.0 / rig.sigma_px[cam] ** 2
    return np.asarray(np.einsum("n,npai,npaj->ij", w, J, J))
