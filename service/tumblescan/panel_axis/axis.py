"""A 3D direction from image lines: each line back-projects to a plane through the camera, and
every plane holds the lines' common 3D direction.

With unit plane normals ``n_i`` and direction ``d``: ``d = argmin Σ w_i (n_i·d)² / σ_i(d)²`` over
``|d| = 1`` — the smallest eigenvector of ``M = Σ w_i n_i n_iᵀ / σ_i²``. For two planes this is the
paper's ``n_1 × n_2`` (eq. 9-12); for N it is the weighted least-squares null direction. ``σ_i``
is the standard deviation of ``n_i·d`` propagated from the line's offset and angle variances; the
``w_i`` are Huber weights (IRLS). The covariance in the tangent plane of ``d`` is
``diag(1/(λ_1-λ_0), 1/(λ_2-λ_0))`` in the other two eigenvectors, times ``max(1, χ²/dof)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._typing import FloatArray
from ..imaging.camera import PinholeCamera
from ..imaging.lines import EdgeLine

HUBER_K = 2.0
REJECT_K = 5.0


@dataclass(frozen=True)
class PlaneObs:
    """One image line as a plane through the camera: unit ``normal`` (camera frame) and its
    derivatives with respect to the line's offset (px) and angle (rad) at its centroid."""

    normal: FloatArray
    dn_doffset: FloatArray
    dn_dangle: FloatArray
    var_offset_px2: float
    var_angle_rad2: float

    def sigma2(self, d: FloatArray) -> float:
        """Variance of ``normal·d`` for a unit direction ``d``."""
        return float((self.dn_doffset @ d) ** 2 * self.var_offset_px2 + (self.dn_dangle @ d) ** 2 * self.var_angle_rad2)


def plane_obs(
    camera: PinholeCamera, centroid_px: FloatArray, angle_rad: float, var_offset: float, var_angle: float
) -> PlaneObs:
    """The plane of the ideal image line through ``centroid_px`` at ``angle_rad`` (direction
    ``(cos, sin)``), with derivatives by central differences."""

    def normal(offset: float, angle: float) -> FloatArray:
        t = np.array([np.cos(angle), np.sin(angle)])
        nn = np.array([-t[1], t[0]])
        c = centroid_px + offset * np.array([-np.sin(angle_rad), np.cos(angle_rad)])
        return camera.plane_normal(np.array([nn[0], nn[1], -nn @ c]))

    n0 = normal(0.0, angle_rad)
    h_off, h_ang = 1e-3, 1e-6
    dn_off = (normal(h_off, angle_rad) - normal(-h_off, angle_rad)) / (2 * h_off)
    dn_ang = (normal(0.0, angle_rad + h_ang) - normal(0.0, angle_rad - h_ang)) / (2 * h_ang)
    return PlaneObs(n0, dn_off, dn_ang, var_offset, var_angle)


def line_plane(camera: PinholeCamera, line: EdgeLine) -> PlaneObs:
    """The plane of a fitted (ideal-coordinate) image line."""
    angle = float(np.arctan2(line.direction[1], line.direction[0]))
    return plane_obs(camera, line.centroid_px, angle, line.var_offset_px2, line.var_angle_rad2)


@dataclass(frozen=True)
class DirectionFit:
    """``direction`` (3,) unit; ``basis`` (2, 3) the tangent directions; ``cov_tangent_rad2`` (2, 2)
    in that basis; ``residuals`` the normalised ``n_i·d/σ_i``; ``weights`` the final Huber weights."""

    direction: FloatArray
    basis: FloatArray
    cov_tangent_rad2: FloatArray
    chi2: float
    dof: int
    residuals: FloatArray
    weights: FloatArray

    @property
    def sigma_rad(self) -> float:
        """The largest 1σ of the tangent covariance."""
        return float(np.sqrt(np.linalg.eigvalsh(self.cov_tangent_rad2).max()))


class PlaneStack:
    """The planes' arrays, for vectorised residuals."""

    def __init__(self, planes: list[PlaneObs]) -> None:
        self.N = np.array([p.normal for p in planes])
        self.D_off = np.array([p.dn_doffset for p in planes])
        self.D_ang = np.array([p.dn_dangle for p in planes])
        self.v_off = np.array([p.var_offset_px2 for p in planes])
        self.v_ang = np.array([p.var_angle_rad2 for p in planes])

    def sigma2(self, d: FloatArray) -> FloatArray:
        return np.maximum((self.D_off @ d) ** 2 * self.v_off + (self.D_ang @ d) ** 2 * self.v_ang, 1e-30)


def fit_direction(
    planes: list[PlaneObs], *, robust: bool = True, iterations: int = 10, reject: bool = False
) -> DirectionFit:
    """The common direction of the planes' lines (see the module docstring); needs 2 planes or more.
    With ``reject``, planes over 5σ after the fit are dropped and the fit redone (kept when 3 remain)."""
    st = PlaneStack(planes)
    N = st.N
    d = np.linalg.svd(N)[2][-1]
    w = np.ones(len(planes))
    for _ in range(iterations):
        s2 = st.sigma2(d)
        r = N @ d / np.sqrt(s2)
        if robust:
            a = np.abs(r)
            w = np.where(a <= HUBER_K, 1.0, HUBER_K / np.maximum(a, 1e-30))
        M = (N * (w / s2)[:, None]).T @ N
        evals, evecs = np.linalg.eigh(M)
        d_new = evecs[:, 0] * (1.0 if evecs[:, 0] @ d >= 0 else -1.0)
        done = np.linalg.norm(d_new - d) < 1e-12
        d = d_new
        if done:
            break
    s2 = st.sigma2(d)
    r = N @ d / np.sqrt(s2)
    if reject and np.count_nonzero(np.abs(r) <= REJECT_K) >= 3 and np.any(np.abs(r) > REJECT_K):
        w = np.where(np.abs(r) > REJECT_K, 0.0, w)
        for _ in range(iterations):
            M = (N * (w / s2)[:, None]).T @ N
            d = np.linalg.eigh(M)[1][:, 0]
            s2 = st.sigma2(d)
        r = N @ d / np.sqrt(s2)
    M = (N * (w / s2)[:, None]).T @ N
    evals, evecs = np.linalg.eigh(M)
    d = evecs[:, 0]
    basis = evecs[:, 1:].T
    chi2 = float(np.sum(w * r**2))
    used = int(np.count_nonzero(w > 0))
    dof = max(used - 2, 1)
    scale = max(1.0, chi2 / dof) if used > 2 else 1.0
    gaps = np.maximum(evals[1:] - evals[0], 1e-30)
    cov = np.diag(1.0 / gaps) * scale
    return DirectionFit(d, basis, cov, chi2, dof, r, w)


def direction_bound(planes: list[PlaneObs], d_true: FloatArray) -> FloatArray:
    """The Cramér-Rao covariance (3, 3) of the direction at ``d_true`` from these line planes
    (the Fisher information ``Σ n_i n_iᵀ/σ_i²`` restricted to the tangent plane)."""
    d = np.asarray(d_true, dtype=float) / np.linalg.norm(d_true)
    N = np.array([p.normal for p in planes])
    s2 = np.array([max(p.sigma2(d), 1e-30) for p in planes])
    M = (N / s2[:, None]).T @ N
    P = np.eye(3) - np.outer(d, d)
    info = P @ M @ P
    return np.asarray(np.linalg.pinv(info, rcond=1e-15, hermitian=True), dtype=float)


def angle_between_lines_deg(a: FloatArray, b: FloatArray) -> float:
    """Angle (deg) between two lines (directions up to sign), in [0, 90]."""
    c = abs(float(np.dot(a, b) / (np.linalg.norm(a) * np.linalg.norm(b))))
    return float(np.degrees(np.arccos(min(1.0, c))))


# Systematic edge errors (PSF, shading, a thin side face) that do not average out along an edge:
# a shift of the whole edge, and a differential shift of one end against the other.
EDGE_BIAS_PX = 0.01
EDGE_TILT_BIAS_PX = 0.003


def with_edge_bias(fit: DirectionFit, planes: list[PlaneObs], half_lengths_px: list[float]) -> DirectionFit:
    """``fit`` with its covariance widened for a bias of the edge model: noise averages down along
    an edge, a bias does not. Each line gets an independent offset bias of ``EDGE_BIAS_PX`` and an
    angle bias of ``EDGE_TILT_BIAS_PX / half length``; their effect on the direction,
    ``(Σ n_i n_iᵀ/b_i²)⁻¹`` in the tangent plane, is added to the noise covariance. The fit itself
    (its weights) is unchanged."""
    d = fit.direction
    N = np.array([p.normal for p in planes])
    b2 = np.array(
        [
            (p.dn_doffset @ d) ** 2 * EDGE_BIAS_PX**2 + (p.dn_dangle @ d) ** 2 * (EDGE_TILT_BIAS_PX / max(h, 1.0)) ** 2
            for p, h in zip(planes, half_lengths_px, strict=True)
        ]
    )
    info = fit.basis @ ((N / np.maximum(b2, 1e-30)[:, None]).T @ N) @ fit.basis.T
    cov = fit.cov_tangent_rad2 + np.linalg.pinv(info, hermitian=True)
    return DirectionFit(d, fit.basis, cov, fit.chi2, fit.dof, fit.residuals, fit.weights)
