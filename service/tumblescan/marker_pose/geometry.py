"""Rotations and rigid fits: skew matrices, SO(3) exp/log, Kabsch, quaternions, ZYX angles and
the launch frame built from three markers (the paper's eqs. 2-9, made right-handed).

Conventions: ``R_world_body`` maps body coordinates to world (``p_w = R p_b + t``); rotation
errors are world-side (``R_true = exp([dtheta]x) R_est``).
"""

from __future__ import annotations

import numpy as np

from .._typing import FloatArray


def skew(v: FloatArray) -> FloatArray:
    """``[v]x`` for one vector (3,) or a stack (N, 3) -> (3, 3) or (N, 3, 3)."""
    v = np.asarray(v, dtype=float)
    out = np.zeros((*v.shape[:-1], 3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def exp_so3(w_rad: FloatArray) -> FloatArray:
    """Rodrigues: rotation vector(s) (..., 3) [rad] -> rotation matrices (..., 3, 3)."""
    w = np.asarray(w_rad, dtype=float)
    theta = np.linalg.norm(w, axis=-1)[..., None, None]
    K = skew(w)
    small = theta < 1e-8
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - theta**2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - theta**2 / 24.0, (1.0 - np.cos(safe)) / safe**2)
    return np.eye(3) + a * K + b * (K @ K)


def log_so3(R: FloatArray) -> FloatArray:
    """Rotation matrices (..., 3, 3) -> rotation vectors (..., 3) [rad] (angle in [0, pi])."""
    R = np.asarray(R, dtype=float)
    from scipy.spatial.transform import Rotation

    flat = R.reshape(-1, 3, 3)
    return np.asarray(Rotation.from_matrix(flat).as_rotvec()).reshape(*R.shape[:-2], 3)


def kabsch(p_body_m: FloatArray, y_world_m: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Least-squares rigid fit ``y = R p + t`` (Kabsch/Umeyama without scale; ML for isotropic noise).

    p_body_m: (N, 3) body coordinates [m]; y_world_m: (N, 3) measured world coordinates [m], N >= 3.
    Returns (R_world_body (3, 3), t_world_m (3,)).
    """
    n = len(p_body_m)
    pc = p_body_m.sum(axis=0) / n
    yc = y_world_m.sum(axis=0) / n
    U, _, Vt = np.linalg.svd((p_body_m - pc).T @ (y_world_m - yc))
    R = Vt.T @ U.T
    if _det3(R) < 0:  # a reflection: flip the weakest axis
        Vt[2] *= -1.0
        R = Vt.T @ U.T
    return R, yc - R @ pc


def _det3(M: FloatArray) -> float:
    return float(
        M[0, 0] * (M[1, 1] * M[2, 2] - M[1, 2] * M[2, 1])
        - M[0, 1] * (M[1, 0] * M[2, 2] - M[1, 2] * M[2, 0])
        + M[0, 2] * (M[1, 0] * M[2, 1] - M[1, 1] * M[2, 0])
    )


def kabsch_batch(p_body_m: FloatArray, y_world_m: FloatArray, w: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Many weighted Kabsch fits at once: p, y (F, M, 3), w (F, M) in {0, 1} (1 = use) -> R (F, 3, 3), t (F, 3).

    Every fit needs at least 3 non-collinear weighted points (the caller checks)."""
    ws = w.sum(axis=1)[:, None]
    pc = (w[..., None] * p_body_m).sum(axis=1) / ws
    yc = (w[..., None] * y_world_m).sum(axis=1) / ws
    H = np.einsum("fm,fmi,fmj->fij", w, p_body_m - pc[:, None], y_world_m - yc[:, None])
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(np.transpose(Vt, (0, 2, 1)) @ np.transpose(U, (0, 2, 1))))
    d[d == 0] = 1.0
    D = np.zeros((len(d), 3, 3))
    D[:, 0, 0] = D[:, 1, 1] = 1.0
    D[:, 2, 2] = d
    R = np.transpose(Vt, (0, 2, 1)) @ D @ np.transpose(U, (0, 2, 1))
    return R, yc - np.einsum("fij,fj->fi", R, pc)


def pose_information(R_world_body: FloatArray, p_body_m: FloatArray, sigma_m: float) -> FloatArray:
    """Fisher information (6, 6) of a pose from markers ``p_body_m`` (N, 3) with isotropic noise.

    Order (dtheta_world [rad], dp_world [m]); each marker's Jacobian is ``[-[R p]x, I]``.
    """
    q = p_body_m @ R_world_body.T
    J = np.zeros((len(q), 3, 6))
    J[:, :, :3] = -skew(q)
    J[:, :, 3:] = np.eye(3)
    return np.einsum("nki,nkj->ij", J, J) / sigma_m**2


def quat_wxyz(R: FloatArray) -> FloatArray:
    """Hamilton quaternions, scalar first, of rotation matrices (..., 3, 3), with w >= 0."""
    from scipy.spatial.transform import Rotation

    flat = np.asarray(R).reshape(-1, 3, 3)
    xyzw = np.asarray(Rotation.from_matrix(flat).as_quat())
    q = np.concatenate([xyzw[:, 3:], xyzw[:, :3]], axis=1)
    q *= np.where(q[:, :1] < 0, -1.0, 1.0)
    return q.reshape(*np.shape(R)[:-2], 4)


def matrix_from_quat_wxyz(q_wxyz: FloatArray) -> FloatArray:
    from scipy.spatial.transform import Rotation

    q = np.asarray(q_wxyz, dtype=float).reshape(-1, 4)
    return np.asarray(Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix()).reshape(*np.shape(q_wxyz)[:-1], 3, 3)


def ypr_deg(R: FloatArray) -> FloatArray:
    """ZYX (yaw, pitch, roll) angles [deg] of rotations (..., 3, 3); singular at pitch +-90 deg."""
    from scipy.spatial.transform import Rotation

    flat = np.asarray(R).reshape(-1, 3, 3)
    return np.asarray(Rotation.from_matrix(flat).as_euler("ZYX", degrees=True)).reshape(*np.shape(R)[:-2], 3)


def launch_frame(p1: FloatArray, p2: FloatArray, p3: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The frame of three markers (paper eqs. 2-8, right-handed): origin at their mean, x along
    ``p3 - p1``, z normal to their plane, ``y = z x x``. Returns (R_ref_frame, o_ref_m): the axes
    as columns and the origin, in the coordinates the points are given in."""
    n_x = p3 - p1
    n_z = np.cross(p2 - p1, p3 - p1)
    n_y = np.cross(n_z, n_x)
    R = np.column_stack([n_x / np.linalg.norm(n_x), n_y / np.linalg.norm(n_y), n_z / np.linalg.norm(n_z)])
    return R, (p1 + p2 + p3) / 3.0


def triangle_area_m2(a: FloatArray, b: FloatArray, c: FloatArray) -> float:
    return float(0.5 * np.linalg.norm(np.cross(b - a, c - a)))
