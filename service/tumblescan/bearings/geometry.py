"""Bearings geometry: station frames, lines of sight, angle Jacobians and the Fisher information.

A station ``i`` sits at ``s_i`` (job frame, m) with ``R_job_from_enu`` its local East-North-Up
axes. A target at ``p`` is seen at ``d = R_job_from_enuᵀ (p − s_i) = (e, n, u)``, azimuth
``A = atan2(e, n)`` (from North, clockwise) and elevation ``E = atan2(u, √(e² + n²))``.
Every function is vectorised over a leading axis of targets (or candidate pairs).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np

from .._typing import BoolArray, FloatArray

MU_EARTH_M3_S2 = 3.986004418e14  # WGS84 GM
OMEGA_EARTH_RAD_S = 7.2921150e-5  # the Earth's rotation rate


@dataclass(frozen=True)
class Station:
    """One station: id, position and ENU axes in the job frame, default 1σ angle errors."""

    id: str
    p_job_m: FloatArray  # (3,)
    R_job_from_enu: FloatArray  # (3, 3), columns e, n, u
    sigma_az_rad: float
    sigma_el_rad: float
    position_sigma_m: float = 0.0
    geodetic: tuple[float, float, float] | None = None  # lat_deg, lon_deg, height_m (ecef jobs)


def R_ecef_from_enu(lat_deg: float, lon_deg: float) -> FloatArray:
    """The ENU -> ECEF rotation at a geodetic latitude and longitude (columns e, n, u)."""
    phi, lam = np.radians(lat_deg), np.radians(lon_deg)
    sp, cp, sl, cl = np.sin(phi), np.cos(phi), np.sin(lam), np.cos(lam)
    return np.array([[-sl, -sp * cl, cp * cl], [cl, -sp * sl, cp * sl], [0.0, cp, sp]])


def geodetic_to_ecef(lat_deg: float, lon_deg: float, height_m: float) -> FloatArray:
    """WGS84 geodetic -> ECEF metres (pymap3d)."""
    import pymap3d

    return np.array(pymap3d.geodetic2ecef(lat_deg, lon_deg, height_m), dtype=float)


def unit_vectors(az_rad: FloatArray, el_rad: FloatArray) -> FloatArray:
    """Lines of sight in a station's ENU, ``(cosE sinA, cosE cosA, sinE)``, shape (n, 3)."""
    ce = np.cos(el_rad)
    return np.stack([ce * np.sin(az_rad), ce * np.cos(az_rad), np.sin(el_rad)], axis=-1)


def wrap_rad(x: FloatArray) -> FloatArray:
    """Angles wrapped into [-π, π)."""
    return (np.asarray(x) + np.pi) % (2.0 * np.pi) - np.pi


def bearings_of(p_job_m: FloatArray, station: Station) -> tuple[FloatArray, FloatArray]:
    """Azimuth and elevation (rad) of points ``p_job_m`` (n, 3) seen from ``station``."""
    d = (p_job_m - station.p_job_m) @ station.R_job_from_enu
    return np.arctan2(d[:, 0], d[:, 1]), np.arctan2(d[:, 2], np.hypot(d[:, 0], d[:, 1]))


def angle_jacobian(p_job_m: FloatArray, station: Station) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Predicted (A, E) in rad and ``H = ∂(A, E)/∂p`` (n, 2, 3) in rad/m.

    ``∂A/∂d = (n, −e, 0)/ρ²``, ``∂E/∂d = (−e u/(r²ρ), −n u/(r²ρ), ρ/r²)``, ``H = [∂A; ∂E] Mᵀ``.
    """
    d = (p_job_m - station.p_job_m) @ station.R_job_from_enu
    e, n, u = d[:, 0], d[:, 1], d[:, 2]
    rho2 = e * e + n * n
    rho = np.sqrt(rho2)
    r2 = rho2 + u * u
    zero = np.zeros_like(e)
    dA = np.stack([n / rho2, -e / rho2, zero], axis=-1)
    dE = np.stack([-e * u / (r2 * rho), -n * u / (r2 * rho), rho / r2], axis=-1)
    H = np.stack([dA, dE], axis=1) @ station.R_job_from_enu.T
    return np.arctan2(e, n), np.arctan2(u, rho), H


def weight_matrices(
    H: FloatArray, sigma_az_rad: FloatArray, sigma_el_rad: FloatArray, position_sigma_m: float
) -> FloatArray:
    """``W = R⁻¹`` (n, 2, 2) with ``R = diag(σ_A², σ_E²) + σ_s² H Hᵀ`` (the survey error seen as angles)."""
    n = H.shape[0]
    R = np.zeros((n, 2, 2))
    R[:, 0, 0] = np.broadcast_to(sigma_az_rad, n) ** 2
    R[:, 1, 1] = np.broadcast_to(sigma_el_rad, n) ** 2
    if position_sigma_m > 0.0:
        R += position_sigma_m**2 * np.einsum("nij,nkj->nik", H, H)
    det = R[:, 0, 0] * R[:, 1, 1] - R[:, 0, 1] * R[:, 1, 0]
    W = np.empty_like(R)
    W[:, 0, 0] = R[:, 1, 1] / det
    W[:, 1, 1] = R[:, 0, 0] / det
    W[:, 0, 1] = -R[:, 0, 1] / det
    W[:, 1, 0] = -R[:, 1, 0] / det
    return W


@dataclass(frozen=True)
class Observation:
    """Measured angles (rad) and their 1σ (rad) at one station, one row per candidate."""

    az_rad: FloatArray
    el_rad: FloatArray
    sigma_az_rad: FloatArray
    sigma_el_rad: FloatArray


def information(
    p_job_m: FloatArray, stations: tuple[Station, Station], obs: tuple[Observation, Observation]
) -> FloatArray:
    """Fisher information ``J = Σ_i H_iᵀ R_i⁻¹ H_i`` (n, 3, 3) in 1/m² at ``p_job_m`` (n, 3)."""
    J = np.zeros((p_job_m.shape[0], 3, 3))
    for st, ob in zip(stations, obs, strict=True):
        _, _, H = angle_jacobian(p_job_m, st)
        W = weight_matrices(H, ob.sigma_az_rad, ob.sigma_el_rad, st.position_sigma_m)
        J += np.swapaxes(H, 1, 2) @ (W @ H)
    return J


def closest_approach(
    s1: FloatArray, u1: FloatArray, s2: FloatArray, u2: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Ranges along each ray to the common perpendicular and its midpoint.

    ``r1 = (β ε − δ)/(1 − β²)``, ``r2 = (ε − β δ)/(1 − β²)`` with ``β = u1·u2``,
    ``δ = u1·(s1 − s2)``, ``ε = u2·(s1 − s2)``; ``u1``, ``u2`` (n, 3) unit vectors in the job frame.
    """
    w = s1 - s2
    beta = np.einsum("ij,ij->i", u1, u2)
    delta = u1 @ w
    eps = u2 @ w
    den = np.maximum(1.0 - beta * beta, 1e-300)
    r1 = (beta * eps - delta) / den
    r2 = (eps - beta * delta) / den
    mid = 0.5 * (s1 + r1[:, None] * u1 + s2 + r2[:, None] * u2)
    return r1, r2, mid


@dataclass(frozen=True)
class Fix:
    """ML triangulation of n candidate pairs."""

    p_job_m: FloatArray  # (n, 3)
    cov_m2: FloatArray  # (n, 3, 3)
    chi2: FloatArray  # (n,)  4 angle residuals, 1 dof
    range_m: FloatArray  # (n, 2)
    parallax_rad: FloatArray  # (n,)
    ok: BoolArray  # (n,)  finite and in front of both stations


RowsT = TypeVar("RowsT")


def take_rows(rows: RowsT, keep: Any) -> RowsT:
    """A copy of a dataclass of per-row arrays (``Fix``, ``FrameFixes``) with the rows ``keep``."""
    arrays = {
        f.name: getattr(rows, f.name)[keep]
        for f in dataclasses.fields(rows)  # type: ignore[arg-type]
        if isinstance(getattr(rows, f.name), np.ndarray)
    }
    return dataclasses.replace(rows, **arrays)  # type: ignore[type-var]


def triangulate(
    stations: tuple[Station, Station],
    obs: tuple[Observation, Observation],
    *,
    p0_job_m: FloatArray | None = None,
    iterations: int = 10,
) -> Fix:
    """Maximum-likelihood position of each candidate pair by Gauss-Newton on the 4 angles.

    Minimises ``Σ_i r_iᵀ R_i⁻¹ r_i`` with ``r_i = (wrap(A_i − Â_i(p)), E_i − Ê_i(p))``; the
    covariance is ``(Σ_i H_iᵀ R_i⁻¹ H_i)⁻¹`` at the solution. Starts at the midpoint of the
    rays' common perpendicular unless ``p0_job_m`` (n, 3) is given.
    """
    s1, s2 = stations[0].p_job_m, stations[1].p_job_m
    u1 = unit_vectors(obs[0].az_rad, obs[0].el_rad) @ stations[0].R_job_from_enu.T
    u2 = unit_vectors(obs[1].az_rad, obs[1].el_rad) @ stations[1].R_job_from_enu.T
    r1, r2, mid = closest_approach(s1, u1, s2, u2)
    p = mid if p0_job_m is None else p0_job_m.copy()
    n = p.shape[0]
    scale = np.maximum(np.abs(r1), np.abs(r2)) + 1.0
    active = np.ones(n, dtype=bool)
    J = np.zeros((n, 3, 3))
    chi2 = np.zeros(n)
    for it in range(iterations + 1):
        idx = np.flatnonzero(active) if it < iterations else np.arange(n)
        if idx.size == 0:
            idx = np.arange(n)
        pa = p[idx]
        Ja = np.zeros((idx.size, 3, 3))
        ga = np.zeros((idx.size, 3))
        ca = np.zeros(idx.size)
        for st, ob in zip(stations, obs, strict=True):
            A, E, H = angle_jacobian(pa, st)
            res = np.stack([wrap_rad(ob.az_rad[idx] - A), ob.el_rad[idx] - E], axis=-1)
            W = weight_matrices(H, ob.sigma_az_rad[idx], ob.sigma_el_rad[idx], st.position_sigma_m)
            Wr = (W @ res[..., None])[..., 0]
            Ht = np.swapaxes(H, 1, 2)
            Ja += Ht @ (W @ H)
            ga += (Ht @ Wr[..., None])[..., 0]
            ca += np.sum(res * Wr, axis=1)
        J[idx], chi2[idx] = Ja, ca
        if it == iterations:
            break
        step = _solve_sym(Ja, ga)
        step = np.where(np.isfinite(step), step, 0.0)
        p[idx] = pa + step
        small = np.linalg.norm(step, axis=1) <= 1e-10 * scale[idx] + 1e-12
        active[idx[small]] = False
    cov = inv_sym(J)
    d1, d2 = p - s1, p - s2
    range_m = np.stack([np.linalg.norm(d1, axis=1), np.linalg.norm(d2, axis=1)], axis=1)
    cosang = np.einsum("ij,ij->i", d1, d2) / np.maximum(range_m[:, 0] * range_m[:, 1], 1e-300)
    parallax = np.arccos(np.clip(cosang, -1.0, 1.0))
    ahead = (np.einsum("ij,ij->i", d1, u1) > 0.0) & (np.einsum("ij,ij->i", d2, u2) > 0.0)
    ok = ahead & np.isfinite(chi2) & np.all(np.isfinite(cov), axis=(1, 2)) & np.all(np.isfinite(p), axis=1)
    return Fix(p_job_m=p, cov_m2=cov, chi2=chi2, range_m=range_m, parallax_rad=parallax, ok=ok)


def crlb(p_job_m: FloatArray, stations: tuple[Station, Station], obs: tuple[Observation, Observation]) -> FloatArray:
    """The single-frame Cramér-Rao bound ``C = J⁻¹`` (n, 3, 3) in m² at the true positions."""
    return inv_sym(information(p_job_m, stations, obs))


def inv_sym(J: FloatArray) -> FloatArray:
    """Inverse of a stack of symmetric matrices (n, 3, 3); a singular one becomes all-inf."""
    with np.errstate(all="ignore"):
        try:
            return np.asarray(np.linalg.inv(J))
        except np.linalg.LinAlgError:
            w, V = np.linalg.eigh(J)
            scale = np.maximum(np.abs(w).max(axis=1, keepdims=True), 1e-300)
            w_inv = np.where(np.abs(w) > 1e-14 * scale, 1.0 / w, np.inf)
            return np.asarray(np.einsum("nij,nj,nkj->nik", V, w_inv, V))


def _solve_sym(J: FloatArray, g: FloatArray) -> FloatArray:
    """``J⁻¹ g`` per row; rows whose J is singular or not finite get a zero step."""
    with np.errstate(all="ignore"):
        bad = ~np.all(np.isfinite(J), axis=(1, 2)) | ~np.all(np.isfinite(g), axis=1)
        Jc = np.where(bad[:, None, None], np.eye(3), J)
        gc = np.where(bad[:, None], 0.0, g)
        try:
            step = np.linalg.solve(Jc, gc[..., None])[..., 0]
        except np.linalg.LinAlgError:
            step = np.einsum("nij,nj->ni", np.nan_to_num(inv_sym(Jc), posinf=0.0, neginf=0.0), gc)
    return np.where(np.isfinite(step), step, 0.0)
