"""The rigid-body fit: one rotation (axis, rate, phase) shared by every line track, perspective-correct.

Model (digest §5.1): a body line through ``p`` with direction ``d`` (reference frame at
``t_ref``) is at time t the 3D line through ``X(t) = c(t) + R(t)·p`` along ``D(t) = R(t)·d``,
``R(t) = Rot(a, ω (t - t_ref))``, ``c(t) = c0 + v (t - t_ref)``. Its image is the line
``l(t) = (K X) × (K D)``; the residual of an observed end point ``e`` is its signed distance
``eᵀl / ‖l₁₂‖`` (px). Depth is a gauge: ``c0_z = 1`` (all lengths in units of the range).

Initial values come from a scan: for a trial (ω, a) each track's plane normals ``n_i = Kᵀ l_i``,
turned back to the reference frame, must all be orthogonal to the line's ``d``; the smallest
eigenvalue of their scatter is the track's cost (variable projection, linear in the structure).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from .._typing import FloatArray, IntArray
from ..geometry.rotations import cross3, tangent_basis
from ..numerics.block_lm import block_lm, block_moments, block_starts
from .rigid_model import RigidModel
from .rotation import rot


@dataclass(frozen=True)
class Observations:
    """Line observations: track index (O,), time (O,, s), end points (O, 2, 2, ideal px), plane normals (O, 3)."""

    track: IntArray
    t_s: FloatArray
    ends_px: FloatArray
    normals: FloatArray
    K: FloatArray

    @staticmethod
    def build(track: IntArray, t_s: FloatArray, ends_px: FloatArray, K: FloatArray) -> Observations:
        order = np.argsort(track, kind="stable")
        track, t_s, ends_px = track[order], t_s[order], ends_px[order]
        e = np.concatenate([ends_px, np.ones((*ends_px.shape[:2], 1))], axis=2)
        n = np.cross(e[:, 0], e[:, 1]) @ K  # Kᵀ l, row-wise
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        return Observations(track, t_s, ends_px, n, K)

    @property
    def n_tracks(self) -> int:
        return int(self.track.max()) + 1 if len(self.track) else 0

    @cached_property
    def track_starts(self) -> IntArray:
        """The index of each track's first observation (``track`` is sorted)."""
        return block_starts(self.track)

    @cached_property
    def K_inv(self) -> FloatArray:
        return np.asarray(np.linalg.inv(self.K), dtype=float)


@dataclass(frozen=True)
class RigidFit:
    """A converged rigid fit: rate (rad/s, ≥ 0), unit axis, centre, line structure and statistics."""

    omega_rad_s: float
    axis: FloatArray
    c0: FloatArray
    velocity: FloatArray
    lines_p: FloatArray
    lines_d: FloatArray
    cost: float
    residuals_px: FloatArray
    weights: FloatArray
    sigma_omega_rad_s: float
    cov_axis_rad2: FloatArray
    rms_px: float
    success: bool
    drift: bool = False


def fibonacci_sphere(n: int) -> FloatArray:
    """``n`` nearly uniform unit vectors on the sphere."""
    k = np.arange(n) + 0.5
    z = 1 - 2 * k / n
    phi = np.pi * (1 + 5**0.5) * k
    r = np.sqrt(1 - z**2)
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), z])


_UPPER_4X4 = np.triu_indices(4)


def scan_cost(
    obs: Observations,
    omegas: FloatArray,
    axes: FloatArray,
    c0: FloatArray,
    t_ref: float,
    radius: float,
    clip_px: float = 3.0,
    window_deg: float | None = None,
) -> FloatArray:
    """The scan's cost (len(omegas), len(axes)) in px²: for a trial (ω, a), each track's planes
    ``(m_i, n_i·c0)`` (the back-projected planes, turned back to the reference frame) must share one
    line; the two smallest eigenvectors of their 4x4 scatter are two homogeneous points on it
    (linear), then each end point's
    distance to that line re-projected at its time, squared and clipped at ``clip_px``, is summed.
    With ``window_deg`` only the observations within that much rotation of ``t_ref`` count (the
    cost per observation, times their total): a short arc has wider basins for the search."""
    starts = obs.track_starts
    n = obs.normals
    q = n @ c0
    dt = obs.t_s - t_ref
    a = axes[:, None, :]
    # Rodrigues split once: n turned by θ about a is n_par + n_perp cos θ + (a × n) sin θ.
    n_par = a * (axes @ n.T)[..., None]  # (A, O, 3)
    n_perp = n[None] - n_par
    a_x_n = cross3(a, n[None])
    K_inv = obs.K_inv
    c0_skew = np.array([[0.0, -c0[2], c0[1]], [c0[2], 0.0, -c0[0]], [-c0[1], c0[0], 0.0]])  # v @ c0_skew = v × c0
    iu, ju = _UPPER_4X4
    u, v = obs.ends_px[None, :, :, 0], obs.ends_px[None, :, :, 1]
    out = np.empty((len(omegas), len(axes)))
    for k, w in enumerate(omegas):
        cos = np.cos(w * dt)[None, :, None]
        sin = np.sin(w * dt)[None, :, None]
        keep = np.ones(len(dt)) if window_deg is None else (w * dt <= np.radians(window_deg)).astype(float)
        # Conditioning: the structure is within ``radius`` of the centre, so scale X = radius·X'.
        m = (n_par + n_perp * cos - a_x_n * sin) * (radius * keep)[None, :, None]
        pi = np.concatenate([m, np.broadcast_to((q * keep)[None, :, None], (*m.shape[:2], 1))], axis=2)
        S_upper = np.add.reduceat(pi[..., iu] * pi[..., ju], starts, axis=1)  # (A, T, 10): S is symmetric
        S = np.empty((*S_upper.shape[:2], 4, 4))
        S[..., iu, ju] = S_upper
        S[..., ju, iu] = S_upper
        _, V = np.linalg.eigh(S)
        # The line through X_k = R p_k + s_k c0 (two homogeneous points, p_k = radius·V[:3, k]) is
        # seen along X_1 × X_2 = R (p_1 × p_2) + R (s_2 p_1 - s_1 p_2) × c0, its image K^-T of that.
        p1, p2 = V[..., :3, 0] * radius, V[..., :3, 1] * radius  # (A, T, 3)
        s1, s2 = V[..., 3, 0, None], V[..., 3, 1, None]
        moment = _turn_split(a, cross3(p1, p2)[:, obs.track], cos, sin)
        offset = _turn_split(a, (s2 * p1 - s1 * p2)[:, obs.track], cos, sin)
        line = (moment + offset @ c0_skew) @ K_inv  # (A, O, 3): image lines, row-wise K^-T
        r = line[..., None, 0] * u + line[..., None, 1] * v + line[..., None, 2]
        r = r / np.maximum(np.hypot(line[..., 0], line[..., 1]), 1e-300)[..., None]
        used = max(float(keep.sum()), 1.0)
        out[k] = (np.minimum(r**2, clip_px**2) * keep[None, :, None]).sum(axis=(1, 2)) * len(dt) / used
    return out


def _turn_split(a: FloatArray, v: FloatArray, cos: FloatArray, sin: FloatArray) -> FloatArray:
    """Rodrigues for axes ``a`` (A, 1, 3), vectors ``v`` (A, O, 3), the angles' ``cos``, ``sin`` (1, O, 1)."""
    return np.asarray(v * cos + cross3(a, v) * sin + a * (np.sum(a * v, axis=-1, keepdims=True) * (1 - cos)))


def init_structure(
    obs: Observations, omega: float, axis: FloatArray, c0: FloatArray, t_ref: float
) -> tuple[FloatArray, FloatArray]:
    """Each line's direction ``d`` (smallest eigenvector of its turned-back normals) and point ``p``
    (least squares of ``m_i·p = -n_i·c``, p orthogonal to d)."""
    R_back = rot(axis, -omega * (obs.t_s - t_ref))
    m = np.einsum("oij,oj->oi", R_back, obs.normals)
    P, D = [], []
    for j in range(obs.n_tracks):
        sel = obs.track == j
        mj = m[sel]
        _, vecs = np.linalg.eigh(mj.T @ mj)
        d = vecs[:, 0]
        f1, f2 = tangent_basis(d)
        B = np.column_stack([f1, f2])
        y = np.linalg.lstsq(mj @ B, -obs.normals[sel] @ c0, rcond=None)[0]
        P.append(B @ y)
        D.append(d)
    return np.array(P), np.array(D)


def fit_rigid(
    obs: Observations, omega0: float, axis0: FloatArray, c0: FloatArray, t_ref: float, *, drift: bool = False,
    max_nfev: int = 60, passes: int = 2, uncertainty: bool = True,
) -> RigidFit:  # fmt: skip
    """Robust (Cauchy) least squares of the rigid model from a start; σ from the Jacobian.

    Parameters
    ----------
    obs : the line observations (ideal px).
    omega0 : float, starting rate (rad/s); axis0 : (3,) unit starting axis (camera frame).
    c0 : (3,) starting centre with ``c0_z = 1``; t_ref : float, reference time (s).
    drift : also fit a centre velocity in the image plane.
    passes : robust passes (the second rescales the Cauchy loss to the first one's residuals).
    uncertainty : compute σ_ω and the axis covariance; without, both are NaN (for the short fits
        of the search and the peeling, which only rank residuals and costs).
    """
    p0, d0 = init_structure(obs, omega0, axis0, c0, t_ref)
    model = RigidModel(obs.track, obs.t_s, obs.ends_px, obs.K, axis0, p0, d0, t_ref, drift)
    x0 = np.concatenate([[omega0, 0.0, 0.0, c0[0], c0[1]], np.zeros(2 if drift else 0), np.zeros(4 * obs.n_tracks)])
    # Cauchy loss by iteratively re-weighted Levenberg-Marquardt (MINPACK's iteration follows the
    # rate-tilt valley of short arcs far faster than a trust region with a robust loss), each
    # track's 4 line parameters eliminated per step (``block_lm``: a Schur complement instead of
    # MINPACK's dense QR of the whole Jacobian).
    row_track = np.repeat(obs.track, 2)
    scale = 1.0
    w = np.ones(2 * len(obs.track))
    res = None
    for _ in range(passes + 1):
        sw = np.sqrt(w)

        def fun(x: FloatArray, sw: FloatArray = sw) -> FloatArray:
            return sw * model.residuals(x)

        def jac(x: FloatArray, sw: FloatArray = sw) -> tuple[FloatArray, FloatArray]:
            J_global, J_line = model.jacobian_blocks(x)
            return sw[:, None] * J_global, sw[:, None] * J_line

        res = block_lm(fun, jac, x0, row_track, model.n_global, max_nfev=max_nfev, gauge=model.gauge)
        x0 = res.x
        r = model.residuals(x0)
        scale = cauchy_scale_px(r)
        w = 1.0 / (1.0 + (r / scale) ** 2)
    assert res is not None
    omega, a, c, v, p, d = model.unpack(x0)
    if omega < 0:  # the same motion: spin vector ω·a
        omega, a = -omega, -a
    sigma_omega, cov_axis = _uncertainty(model, x0, r, w) if uncertainty else (float("nan"), np.full((2, 2), np.nan))
    return RigidFit(
        omega_rad_s=omega, axis=a, c0=c, velocity=v, lines_p=p, lines_d=d, cost=cauchy_cost(r, scale), residuals_px=r,
        weights=w, sigma_omega_rad_s=sigma_omega, cov_axis_rad2=cov_axis,
        rms_px=float(np.sqrt(np.sum(w * r**2) / max(np.sum(w), 1e-9))), success=bool(res.success), drift=drift,
    )  # fmt: skip


def _uncertainty(model: RigidModel, x: FloatArray, r: FloatArray, w: FloatArray) -> tuple[float, FloatArray]:
    """σ_ω (rad/s) and the axis tangents' covariance (2, 2) (rad²) of a converged fit at ``x``,
    with residuals ``r`` (2·O,) px and Cauchy weights ``w`` (2·O,): the larger of the Gauss-Newton,
    cluster-robust and track-jackknife σ (``covariances``)."""
    cov_gn, cov_cluster, sigma_jk = covariances(model, x, r, w)
    # Cluster-robust (sandwich) covariance with one cluster per track: an edge's bias (shading, PSF,
    # a neighbouring edge) persists from frame to frame, which the independent-noise σ ignores.
    # The larger of the two is reported.
    cov = np.where(np.diag(cov_cluster)[:, None] > np.diag(cov_gn)[:, None], cov_cluster, cov_gn)
    return max(float(np.sqrt(max(cov[0, 0], 0.0))), sigma_jk), np.asarray(cov[1:3, 1:3], dtype=float)


def covariances(model: RigidModel, x: FloatArray, r: FloatArray, w: FloatArray) -> tuple[FloatArray, FloatArray, float]:
    """The global parameters' Gauss-Newton covariance ``s² S⁺`` and cluster-robust (one cluster per
    track) covariance ``S⁺ (Σ s_j s_jᵀ) S⁺ · G/(G-1)``, both (n_global, n_global), and the track
    jackknife's σ_ω (rad/s), at a converged ``x`` with residuals ``r`` (2·O,) px and weights ``w``.

    Each track's 4 line parameters are eliminated (``TrackSchur``). ω and the axis do not move along
    the scale gauge (``RigidModel.gauge``), so their (co)variances are the same whichever
    generalised inverse of the full normal matrix is taken."""
    J_global, J_line = model.jacobian_blocks(x)
    sw = np.sqrt(w)
    schur = TrackSchur.build(sw[:, None] * J_global, sw[:, None] * J_line, sw * r, np.repeat(model.track, 2))
    G = schur.n_tracks
    s2 = float(np.sum(w * r**2) / max(np.sum(w) - model.n_global - 4 * G, 1.0))
    S_inv = np.linalg.pinv(schur.S, rcond=1e-10, hermitian=True)
    cov_cluster = S_inv @ (schur.s_parts.T @ schur.s_parts) @ S_inv * G / max(G - 1, 1)
    return np.asarray(S_inv * s2, dtype=float), cov_cluster, schur.jackknife_sigma()


@dataclass(frozen=True)
class TrackSchur:
    """The weighted normal equations with each track's 4 line parameters eliminated: track j's
    part of the global normal matrix ``S_j = A_j - B_j C_j⁺ B_jᵀ`` (G, n, n) and of the global
    score ``s_j = q_g - B_j C_j⁺ q_l`` (G, n), from ``A_j = J_gᵀ J_g``, ``B_j = J_gᵀ J_l``,
    ``C_j = J_lᵀ J_l``, ``q = Jᵀ r`` over the track's rows."""

    S_parts: FloatArray
    s_parts: FloatArray

    @staticmethod
    def build(JW_global: FloatArray, JW_line: FloatArray, rw: FloatArray, row_track: IntArray) -> TrackSchur:
        """``JW_global`` (R, n), ``JW_line`` (R, 4): the weighted Jacobian's blocks (each row's own
        track's line columns); ``rw`` (R,) weighted residuals (px); ``row_track`` (R,) sorted."""
        _, M = block_moments(JW_global, JW_line, rw, row_track)
        g = JW_global.shape[1]
        A, B, C = M[:, :g, :g], M[:, :g, g:-1], M[:, g:-1, g:-1]
        q_g, q_l = M[:, :g, -1], M[:, g:-1, -1]
        BC = B @ np.linalg.pinv(C, rcond=1e-12, hermitian=True)  # (G, n, 4)
        S_parts = A - BC @ B.transpose(0, 2, 1)
        s_parts = q_g - (BC @ q_l[:, :, None])[:, :, 0]
        return TrackSchur(S_parts, s_parts)

    @property
    def n_tracks(self) -> int:
        return len(self.S_parts)

    @property
    def S(self) -> FloatArray:
        return np.asarray(self.S_parts.sum(axis=0))

    def jackknife_sigma(self) -> float:
        """The delete-one-track jackknife σ of ω (rad/s), each deletion by one Gauss-Newton step.

        At the optimum ``Σ s_j = 0``, so without track j the global parameters move by
        ``Δ_j = (S - S_j)⁺ s_j``, and ``σ² = (G-1)/G · Σ_j (Δ_j,ω - mean Δ_ω)²``. Unlike the sandwich
        ``S⁻¹ (Σ s_j s_jᵀ) S⁻¹`` it weighs a track by what the others lose without it: a few tracks
        that hold the rate (short arcs, few long edges) widen σ as they should. ∞ under 3 tracks."""
        G = self.n_tracks
        if G < 3:
            return float("inf")
        S_without = np.linalg.pinv(self.S - self.S_parts, rcond=1e-10, hermitian=True)  # (G, n, n)
        delta = np.einsum("gk,gk->g", S_without[:, 0], self.s_parts)
        return float(np.sqrt((G - 1) / G * np.sum((delta - delta.mean()) ** 2)))


def robust_scale_px(residuals_px: FloatArray) -> float:
    """1.4826 × the median absolute residual (px): the inliers' σ."""
    return float(1.4826 * np.median(np.abs(residuals_px)))


def cauchy_scale_px(residuals_px: FloatArray) -> float:
    """The Cauchy loss's scale for these residuals: twice their robust σ, at least 0.05 px."""
    return max(2.0 * robust_scale_px(residuals_px), 0.05)


def cauchy_cost(r: FloatArray, scale: float) -> float:
    return float(0.5 * np.sum(scale**2 * np.log1p((r / scale) ** 2)))


def predict_lines(fit: RigidFit, K: FloatArray, t_s: float, t_ref: float) -> FloatArray:
    """Every line's image ``(a, b, c)`` (T, 3) at time ``t_s``, normalised so ``a² + b² = 1``."""
    dt = t_s - t_ref
    R = rot(fit.axis, fit.omega_rad_s * dt)[0]
    X = fit.c0 + fit.velocity * dt + fit.lines_p @ R.T
    D = fit.lines_d @ R.T
    line = np.cross(X @ K.T, D @ K.T)
    return np.asarray(line / np.linalg.norm(line[:, :2], axis=1, keepdims=True), dtype=float)
