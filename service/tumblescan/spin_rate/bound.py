"""The Cramér-Rao bound on the spin rate from corner tracks (digest §5.2)."""

from __future__ import annotations

import numpy as np

from .._typing import FloatArray
from ..imaging.camera import PinholeCamera
from .rotation import rot


def rate_crb(
    camera: PinholeCamera,
    axis_camera: FloatArray,
    omega_rad_s: float,
    c_cam_m: FloatArray,
    Q_m: FloatArray,
    t_s: FloatArray,
    visible: np.ndarray,
    sigma_px: float,
) -> float:
    """σ_ω (rad/s) of ``x_ij = π(K(c + Rot(a, ω t_i)·Q_j))`` seen where ``visible`` (frames, points),
    with isotropic pixel noise ``sigma_px``.

    Unknowns ω, the axis (2 angles), c (3) and every Q_j (3); ``F = JᵀJ/σ²`` by central
    differences and ``σ_ω = sqrt(F⁺_ωω)`` (the pseudo-inverse absorbs the scale and the shift along a).
    """
    a = np.asarray(axis_camera, dtype=float)
    theta0, phi0 = float(np.arccos(np.clip(a[2], -1, 1))), float(np.arctan2(a[1], a[0]))
    x0 = np.concatenate([[omega_rad_s, theta0, phi0], c_cam_m, np.asarray(Q_m).ravel()])

    def project(x: FloatArray) -> FloatArray:
        th, ph = x[1], x[2]
        ax = np.array([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)])
        Rs = rot(ax, x[0] * np.asarray(t_s))
        Q = x[6:].reshape(-1, 3)
        p = np.einsum("fij,nj->fni", Rs, Q) + x[3:6]
        uv = camera.project(p.reshape(-1, 3)).reshape(len(t_s), -1, 2)
        return np.asarray(uv[visible].ravel(), dtype=float)

    steps = np.maximum(np.abs(x0) * 1e-6, 1e-7)
    J = np.empty((2 * int(np.count_nonzero(visible)), len(x0)))
    for k in range(len(x0)):
        dx = np.zeros_like(x0)
        dx[k] = steps[k]
        J[:, k] = (project(x0 + dx) - project(x0 - dx)) / (2 * steps[k])
    F = J.T @ J / sigma_px**2
    return float(np.sqrt(max(np.linalg.pinv(F, rcond=1e-12)[0, 0], 0.0)))
