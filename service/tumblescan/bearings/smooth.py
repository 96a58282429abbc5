"""Track fits: a weighted least-squares motion model through each track's fixes.

``p(t) = p + v τ (+ ½ a τ²)``, ``τ = t − t_ref``, minimising ``Σ_f r_fᵀ C_f⁻¹ r_f`` over the
track's fixes (``C_f`` each fix's covariance), with ``t_ref`` the frame time nearest the middle
of the track. ECEF tracks are taken as free-falling (orbital): their acceleration is gravity
plus the Earth's rotation, computed from the fitted state. Otherwise the constant-acceleration
model is kept when its acceleration is significant (``aᵀ Cov_a⁻¹ a`` above the 99 % point of
χ²₃), else the constant-velocity one. Fixes whose residual Mahalanobis² exceeds 25 (a wrong
pair that entered the track) are left out of a second fit. The covariance is that of the fit,
``(Σ_f Aᵀ C_f⁻¹ A)⁻¹``, so a track's position at ``t_ref`` can be much better than one frame's.
All tracks are fitted at once (normal equations summed per track, batched solves).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._typing import BoolArray, FloatArray, IntArray
from .geometry import MU_EARTH_M3_S2, OMEGA_EARTH_RAD_S, inv_sym

CHI2_3_99 = 11.34
OUTLIER_M2 = 25.0  # a fix's residual Mahalanobis² (3 dof) beyond which it is left out
MIN_FIXES = 3


def earth_acceleration(p_ecef_m: FloatArray, v_ecef_m_s: FloatArray) -> FloatArray:
    """Acceleration (m/s²) of free bodies in ECEF, rows (n, 3): central gravity, Coriolis and
    centrifugal, ``−μ p/|p|³ − 2 ω × v − ω × (ω × p)``."""
    w = np.array([0.0, 0.0, OMEGA_EARTH_RAD_S])
    r = np.linalg.norm(p_ecef_m, axis=1, keepdims=True)
    return np.asarray(
        -MU_EARTH_M3_S2 * p_ecef_m / r**3 - 2.0 * np.cross(w, v_ecef_m_s) - np.cross(w, np.cross(w, p_ecef_m))
    )


@dataclass(frozen=True)
class _Fixes:
    """Every fix of the tracks to fit, sorted by track (``start`` marks each track's first)."""

    track: IntArray
    start: IntArray
    tau: FloatArray
    p: FloatArray
    W: FloatArray


def _design(tau: FloatArray, order: int) -> FloatArray:
    """(n, 3, 3·order) rows mapping the state (p, v[, a]) to positions at ``tau``."""
    eye = np.eye(3)
    blocks = [np.broadcast_to(eye, (tau.size, 3, 3)), tau[:, None, None] * eye, 0.5 * (tau**2)[:, None, None] * eye]
    return np.concatenate(blocks[:order], axis=2)


def _fit(fx: _Fixes, p: FloatArray, use: BoolArray, order: int) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Per track: state (T, 3·order), its covariance (T, d, d); per fix: residual Mahalanobis²."""
    A = _design(fx.tau, order)
    At_W = np.swapaxes(A, 1, 2) @ fx.W * use[:, None, None]
    N = np.add.reduceat(At_W @ A, fx.start, axis=0)
    b = np.add.reduceat((At_W @ p[..., None])[..., 0], fx.start, axis=0)
    cov = _inv(N)
    x = (cov @ b[..., None])[..., 0]
    r = p - (A @ x[fx.track][..., None])[..., 0]
    return x, cov, np.einsum("ni,nij,nj->n", r, fx.W, r)


def _inv(N: FloatArray) -> FloatArray:
    if N.shape[1] == 3:
        return inv_sym(N)
    with np.errstate(all="ignore"):
        try:
            return np.asarray(np.linalg.inv(N))
        except np.linalg.LinAlgError:
            return np.asarray(np.linalg.pinv(N))


def _fit_local(fx: _Fixes, use: BoolArray, n_used: IntArray) -> tuple[FloatArray, FloatArray, FloatArray, BoolArray]:
    """Constant velocity, or constant acceleration where it is significant. Returns the state
    padded to 9 (acceleration 0 for CV), its covariance (T, 9, 9), the per-fix Mahalanobis²
    and which tracks kept the acceleration."""
    x2, c2, m2 = _fit(fx, fx.p, use, 2)
    x3, c3, m3 = _fit(fx, fx.p, use, 3)
    a, ca = x3[:, 6:9], c3[:, 6:9, 6:9]
    with np.errstate(all="ignore"):
        sig = np.einsum("ti,tij,tj->t", a, inv_sym(ca), a)
    ca_kept = (n_used >= 4) & np.isfinite(sig) & (sig >= CHI2_3_99)
    x = np.zeros((x2.shape[0], 9))
    cov = np.zeros((x2.shape[0], 9, 9))
    x[:, :6], cov[:, :6, :6] = x2, c2
    x[ca_kept], cov[ca_kept] = x3[ca_kept], c3[ca_kept]
    return x, cov, np.where(ca_kept[fx.track], m3, m2), ca_kept


def _fit_orbital(fx: _Fixes, use: BoolArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Constant velocity with the known acceleration taken out, iterated."""
    a = np.zeros((fx.start.size, 3))
    for _ in range(4):
        shifted = fx.p - 0.5 * (fx.tau**2)[:, None] * a[fx.track]
        x2, c2, m2 = _fit(fx, shifted, use, 2)
        a = earth_acceleration(x2[:, 0:3], x2[:, 3:6])
    x = np.concatenate([x2, a], axis=1)
    cov = np.zeros((x.shape[0], 9, 9))
    cov[:, :6, :6] = c2
    return x, cov, m2


def fit_tracks(
    t_s: list[float],
    frame_index: list[int],
    p_job_m: list[FloatArray],
    cov_m2: list[FloatArray],
    ids: list[IntArray],
    *,
    orbital: bool = False,
) -> list[dict[str, Any]]:
    """``tracks[]`` of the result: one fit per track with at least ``MIN_FIXES`` fixes.

    ``orbital`` (ECEF positions of free-falling targets): the acceleration is not fitted but
    computed from the fitted state (gravity and the Earth's rotation) at ``t_ref``."""
    if not ids or sum(a.size for a in ids) == 0:
        return []
    tid = np.concatenate(ids)
    t = np.concatenate([np.full(a.size, ts) for a, ts in zip(ids, t_s, strict=True)])
    frames = np.concatenate([np.full(a.size, fi) for a, fi in zip(ids, frame_index, strict=True)])
    counts = np.bincount(tid)
    keep = counts[tid] >= MIN_FIXES
    if not keep.any():
        return []
    order = np.flatnonzero(keep)[np.argsort(tid[keep], kind="stable")]
    labels, track = np.unique(tid[order], return_inverse=True)
    start = np.flatnonzero(np.r_[True, np.diff(track) > 0])
    # t_ref: the frame time nearest each track's mean time.
    t_o = t[order]
    mean = np.add.reduceat(t_o, start) / np.diff(np.r_[start, t_o.size])
    dist = np.abs(t_o - mean[track])
    nearest = np.lexsort((dist, track))[start]
    t_ref = t_o[nearest]
    fx = _Fixes(
        track=track,
        start=start,
        tau=t_o - t_ref[track],
        p=np.concatenate(p_job_m)[order],
        W=inv_sym(np.concatenate(cov_m2)[order]),
    )
    # Fit, leave out the fixes far off it, fit again.
    use = np.ones(order.size, dtype=bool)
    for _ in range(2):
        n_used = np.add.reduceat(use.astype(np.int64), start)
        if orbital:
            x, cov, m2 = _fit_orbital(fx, use)
            ca_kept = np.zeros(start.size, dtype=bool)
        else:
            x, cov, m2, ca_kept = _fit_local(fx, use, n_used)
        off = m2 > OUTLIER_M2
        enough = np.add.reduceat((~off).astype(np.int64), start) >= MIN_FIXES
        new_use = ~off | ~enough[track]
        if np.array_equal(new_use, use):
            break
        use = new_use
    n_used = np.add.reduceat(use.astype(np.int64), start)
    chi2 = np.add.reduceat(m2 * use, start)
    model = np.where(ca_kept, "constant_acceleration", "constant_velocity") if not orbital else None
    out = []
    for k in range(start.size):
        seg = slice(start[k], start[k + 1] if k + 1 < start.size else order.size)
        n_params = 9 if (not orbital and ca_kept[k]) else 6
        out.append(
            {
                "id": f"K{int(labels[k])}",
                "frames": frames[order[seg]].tolist(),
                "t_ref": float(t_ref[k]),
                "model": "orbital" if model is None else str(model[k]),
                "position_m": x[k, 0:3].tolist(),
                "velocity_m_s": x[k, 3:6].tolist(),
                "acceleration_m_s2": x[k, 6:9].tolist() if (orbital or ca_kept[k]) else None,
                "cov_m2": cov[k, 0:3, 0:3].tolist(),
                "velocity_cov_m2_s2": cov[k, 3:6, 3:6].tolist(),
                "chi2": float(chi2[k]),
                "dof": 3 * int(n_used[k]) - n_params,
                "fixes_used": int(n_used[k]),
            }
        )
    return out
