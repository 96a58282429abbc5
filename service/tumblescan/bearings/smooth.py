"""Track fits: a weighted least-squares motion model through each track's fixes.

``p(t) = p + v τ (+ ½ a τ²)``, ``τ = t − t_ref``, minimising ``Σ_f r_fᵀ C_f⁻¹ r_f`` over the
track's fixes (``C_f`` each fix's covariance), with ``t_ref`` the frame time nearest the middle
of the track. ECEF tracks are taken as free-falling (orbital): their acceleration is gravity
plus the Earth's rotation, computed from the fitted state. Otherwise the constant-acceleration
model is kept when its acceleration is significant (``aᵀ Cov_a⁻¹ a`` above the 99 % point of
χ²₃), else the constant-velocity one. Fixes whose residual Mahalanobis² exceeds 25 (a wrong pair that
entered the track) are left out of a second fit. The covariance is that of the fit,
``(Σ_f Aᵀ C_f⁻¹ A)⁻¹``, so a track's position at ``t_ref`` can be much better than one frame's.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._typing import FloatArray, IntArray
from .geometry import MU_EARTH_M3_S2, OMEGA_EARTH_RAD_S

CHI2_3_99 = 11.34
OUTLIER_M2 = 25.0  # a fix's residual Mahalanobis² (3 dof) beyond which it is left out
MIN_FIXES = 3


def _design(tau: FloatArray, order: int) -> FloatArray:
    """(n, 3, 3·order) rows mapping the state (p, v[, a]) to positions at ``tau``."""
    eye = np.eye(3)
    blocks = [np.broadcast_to(eye, (tau.size, 3, 3)), tau[:, None, None] * eye]
    if order == 3:
        blocks.append(0.5 * (tau**2)[:, None, None] * eye)
    return np.concatenate(blocks[:order], axis=2)


def _fit(tau: FloatArray, p: FloatArray, W: FloatArray, order: int) -> tuple[FloatArray, FloatArray, FloatArray]:
    """State, its covariance and each fix's residual Mahalanobis² for one model."""
    A = _design(tau, order)
    At_W = np.swapaxes(A, 1, 2) @ W
    N = np.sum(At_W @ A, axis=0)
    b = np.sum(At_W @ p[..., None], axis=0)[:, 0]
    cov = np.linalg.pinv(N)
    x = cov @ b
    r = p - (A @ x)
    m2 = np.einsum("ni,nij,nj->n", r, W, r)
    return x, cov, m2


def earth_acceleration(p_ecef_m: FloatArray, v_ecef_m_s: FloatArray) -> FloatArray:
    """Acceleration (m/s²) of a free body in ECEF: central gravity, Coriolis and centrifugal,
    ``−μ p/|p|³ − 2 ω × v − ω × (ω × p)``."""
    w = np.array([0.0, 0.0, OMEGA_EARTH_RAD_S])
    r = float(np.linalg.norm(p_ecef_m))
    return np.asarray(
        -MU_EARTH_M3_S2 * p_ecef_m / r**3 - 2.0 * np.cross(w, v_ecef_m_s) - np.cross(w, np.cross(w, p_ecef_m))
    )


def fit_track(
    t_s: FloatArray, p_job_m: FloatArray, cov_m2: FloatArray, *, orbital: bool = False
) -> dict[str, Any] | None:
    """The fit of one track's fixes (n,), (n, 3), (n, 3, 3); None below ``MIN_FIXES``.

    ``orbital`` (ECEF positions of a free-falling target): the acceleration is not fitted but
    computed from the fitted state (gravity and the Earth's rotation), evaluated at ``t_ref``."""
    if t_s.size < MIN_FIXES:
        return None
    t_ref = float(t_s[np.argmin(np.abs(t_s - t_s.mean()))])
    tau = t_s - t_ref
    W: FloatArray = np.asarray(np.linalg.pinv(cov_m2), dtype=np.float64)
    if orbital:
        return _fit_orbital(t_ref, tau, p_job_m, W)
    use = np.ones(t_s.size, dtype=bool)
    for _ in range(2):
        order = 3 if use.sum() >= 4 else 2
        x, cov, m2 = _fit(tau[use], p_job_m[use], W[use], order)
        if order == 3:
            a, cov_a = x[6:9], cov[6:9, 6:9]
            if float(a @ np.linalg.pinv(cov_a) @ a) < CHI2_3_99:
                order = 2
                x, cov, m2 = _fit(tau[use], p_job_m[use], W[use], 2)
        r_all = p_job_m - _design(tau, order) @ x
        m2_all = np.einsum("ni,nij,nj->n", r_all, W, r_all)
        keep = m2_all <= OUTLIER_M2
        if keep.sum() < MIN_FIXES or np.array_equal(keep, use):
            break
        use = keep
    dof = 3 * int(use.sum()) - 3 * order
    return {
        "t_ref": t_ref,
        "model": "constant_acceleration" if order == 3 else "constant_velocity",
        "position_m": x[0:3].tolist(),
        "velocity_m_s": x[3:6].tolist(),
        "acceleration_m_s2": x[6:9].tolist() if order == 3 else None,
        "cov_m2": cov[0:3, 0:3].tolist(),
        "velocity_cov_m2_s2": cov[3:6, 3:6].tolist(),
        "chi2": float(m2.sum()),
        "dof": dof,
        "fixes_used": int(use.sum()),
    }


def _fit_orbital(t_ref: float, tau: FloatArray, p: FloatArray, W: FloatArray) -> dict[str, Any]:
    """Constant-velocity fit of the fixes with the known acceleration taken out, iterated."""
    a = np.zeros(3)
    use = np.ones(tau.size, dtype=bool)
    for _ in range(4):
        shifted = p - 0.5 * (tau**2)[:, None] * a
        x, cov, m2 = _fit(tau[use], shifted[use], W[use], 2)
        a = earth_acceleration(x[0:3], x[3:6])
        r = shifted - _design(tau, 2) @ x
        keep = np.einsum("ni,nij,nj->n", r, W, r) <= OUTLIER_M2
        if keep.sum() >= MIN_FIXES:
            use = keep
    return {
        "t_ref": t_ref,
        "model": "orbital",
        "position_m": x[0:3].tolist(),
        "velocity_m_s": x[3:6].tolist(),
        "acceleration_m_s2": a.tolist(),
        "cov_m2": cov[0:3, 0:3].tolist(),
        "velocity_cov_m2_s2": cov[3:6, 3:6].tolist(),
        "chi2": float(m2.sum()),
        "dof": 3 * int(use.sum()) - 6,
        "fixes_used": int(use.sum()),
    }


def fit_tracks(
    t_s: list[float],
    frame_index: list[int],
    p_job_m: list[FloatArray],
    cov_m2: list[FloatArray],
    ids: list[IntArray],
    *,
    orbital: bool = False,
) -> list[dict[str, Any]]:
    """``tracks[]`` of the result: one fit per track with at least ``MIN_FIXES`` fixes."""
    if not ids or sum(a.size for a in ids) == 0:
        return []
    tid = np.concatenate(ids)
    t = np.concatenate([np.full(a.size, ts) for a, ts in zip(ids, t_s, strict=True)])
    fr = np.concatenate([np.full(a.size, fi) for a, fi in zip(ids, frame_index, strict=True)])
    p = np.concatenate(p_job_m)
    c = np.concatenate(cov_m2)
    order = np.argsort(tid, kind="stable")
    out = []
    for members in np.split(order, np.flatnonzero(np.diff(tid[order])) + 1):
        fit = fit_track(t[members], p[members], c[members], orbital=orbital)
        if fit is not None:
            out.append({"id": f"K{int(tid[members[0]])}", "frames": fr[members].tolist(), **fit})
    return out
