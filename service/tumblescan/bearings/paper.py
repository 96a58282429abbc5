"""The paper's method (Yue, Li and Gao 2022), kept for comparison (``method="paper"``).

Per frame: every cross pair's rays are projected on the horizontal plane and intersected;
the heights above the crossing from each station differ by ``Δh`` (the "elevation
difference"); each station-1 detection takes the station-2 detection of least ``Δh`` (no
one-to-one rule), within a noise-scaled gate. The position is the crossing with the mean
height. Across frames, each track's direction vectors are histogrammed (18 × 18 bins of
20° × 10°), the fullest bin seeds a Gaussian-kernel Mean Shift (radius 10°), and points whose
vectors mostly miss the densest direction are replaced by a least-squares line fit.

All bearings are first rotated into one local East-North-Up frame (the one at the middle of
the baseline for ``ecef`` jobs), as the paper's model needs one horizontal plane.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._typing import BoolArray, FloatArray, IntArray
from .geometry import R_ecef_from_enu, Station, unit_vectors, wrap_rad
from .inputs import Detections

HIST_BINS = (18, 18)


@dataclass(frozen=True)
class CommonFrame:
    """The local ENU the paper works in: origin (job frame) and its axes."""

    origin_job_m: FloatArray
    R_job_from_enu: FloatArray


def common_frame(stations: tuple[Station, Station], job_frame: str) -> CommonFrame:
    """Identity for ``local_enu``; the ENU at the baseline's midpoint for ``ecef``."""
    if job_frame == "local_enu":
        return CommonFrame(np.zeros(3), np.eye(3))
    import pymap3d

    mid = 0.5 * (stations[0].p_job_m + stations[1].p_job_m)
    lat, lon, _ = pymap3d.ecef2geodetic(*mid)
    return CommonFrame(mid, R_ecef_from_enu(float(lat), float(lon)))


def _common_angles(det: Detections, station: Station, cf: CommonFrame) -> tuple[FloatArray, FloatArray]:
    u = unit_vectors(det.az_rad, det.el_rad) @ station.R_job_from_enu.T @ cf.R_job_from_enu
    return np.arctan2(u[:, 0], u[:, 1]), np.arcsin(np.clip(u[:, 2], -1.0, 1.0))


@dataclass(frozen=True)
class PaperPairs:
    """The paper's matches in one frame (common ENU positions)."""

    i1: IntArray
    i2: IntArray
    p_enu_m: FloatArray


def paper_match(
    stations: tuple[Station, Station],
    cf: CommonFrame,
    dets: tuple[Detections, Detections],
    *,
    gate_sigma: float = 5.0,
    chunk: int = 256,
) -> PaperPairs:
    """Elevation-difference matching (eq. 3-6): argmin Δh per station-1 detection.

    ``r1 = (Δx cosA2 − Δy sinA2)/sin(A1 − A2)``, ``r2 = (Δx cosA1 − Δy sinA1)/sin(A1 − A2)``,
    ``z_i' = z_i + r_i tanE_i``, ``Δh = |z1' − z2'|``; a pair is admissible when both ranges
    are positive and ``Δh ≤ gate_sigma · σ_Δh`` (σ_Δh propagated from the four angle σs).
    """
    s1 = cf.R_job_from_enu.T @ (stations[0].p_job_m - cf.origin_job_m)
    s2 = cf.R_job_from_enu.T @ (stations[1].p_job_m - cf.origin_job_m)
    A1, E1 = _common_angles(dets[0], stations[0], cf)
    A2, E2 = _common_angles(dets[1], stations[1], cf)
    n1, n2 = A1.size, A2.size
    best = np.full(n1, -1, dtype=np.int64)
    pos = np.zeros((n1, 3))
    if n1 == 0 or n2 == 0:
        return PaperPairs(best[:0], best[:0], pos[:0])
    dx, dy = s2[0] - s1[0], s2[1] - s1[1]
    for lo in range(0, n1, chunk):
        a1, e1 = A1[lo : lo + chunk, None], E1[lo : lo + chunk, None]
        sa1, se1 = dets[0].sigma_az_rad[lo : lo + chunk, None], dets[0].sigma_el_rad[lo : lo + chunk, None]
        a2, e2, sa2, se2 = A2[None, :], E2[None, :], dets[1].sigma_az_rad[None, :], dets[1].sigma_el_rad[None, :]
        with np.errstate(divide="ignore", invalid="ignore"):
            D = np.sin(a1 - a2)
            c12 = np.cos(a1 - a2)
            r1 = (dx * np.cos(a2) - dy * np.sin(a2)) / D
            r2 = (dx * np.cos(a1) - dy * np.sin(a1)) / D
            t1, t2 = np.tan(e1), np.tan(e2)
            h = (s1[2] + r1 * t1) - (s2[2] + r2 * t2)
            dr1_a1 = -r1 * c12 / D
            dr1_a2 = (-dx * np.sin(a2) - dy * np.cos(a2) + r1 * c12) / D
            dr2_a1 = (-dx * np.sin(a1) - dy * np.cos(a1) - r2 * c12) / D
            dr2_a2 = r2 * c12 / D
            var = (
                ((dr1_a1 * t1 - dr2_a1 * t2) * sa1) ** 2
                + ((dr1_a2 * t1 - dr2_a2 * t2) * sa2) ** 2
                + (r1 / np.cos(e1) ** 2 * se1) ** 2
                + (r2 / np.cos(e2) ** 2 * se2) ** 2
            )
            dh = np.abs(h)
            ok = (r1 > 0) & (r2 > 0) & np.isfinite(dh) & (dh <= gate_sigma * np.sqrt(var))
        dh = np.where(ok, dh, np.inf)
        k = np.argmin(dh, axis=1)
        rows = np.arange(k.size)
        found = np.isfinite(dh[rows, k])
        idx = np.flatnonzero(found)
        best[lo + idx] = k[idx]
        rr1, rr2 = r1[idx, k[idx]], r2[idx, k[idx]]
        z1 = s1[2] + rr1 * t1[idx, 0]
        z2 = s2[2] + rr2 * t2[0, k[idx]]
        a = a1[idx, 0]
        pos[lo + idx] = np.stack([s1[0] + rr1 * np.sin(a), s1[1] + rr1 * np.cos(a), 0.5 * (z1 + z2)], axis=1)
    i1 = np.flatnonzero(best >= 0)
    return PaperPairs(i1, best[i1], pos[i1])


def _directions_deg(p: FloatArray, t: FloatArray) -> tuple[FloatArray, FloatArray, IntArray, IntArray]:
    """(α, β) in degrees (eq. 1-2) of every later-minus-earlier vector of a track's points."""
    a, b = np.triu_indices(p.shape[0], k=1)
    order = np.argsort(t)
    a, b = order[a], order[b]
    swap = t[a] > t[b]
    a, b = np.where(swap, b, a), np.where(swap, a, b)
    d = p[b] - p[a]
    alpha = np.degrees(np.arctan2(d[:, 0], d[:, 1]))
    beta = np.degrees(np.arctan2(d[:, 2], np.hypot(d[:, 0], d[:, 1])))
    return alpha, beta, a, b


def _mean_shift_deg(alpha: FloatArray, beta: FloatArray, radius_deg: float) -> tuple[float, float]:
    """The densest direction: the fullest 20° × 10° bin's mean, then Gaussian-kernel Mean Shift."""
    hist, ea, eb = np.histogram2d(alpha, beta, bins=HIST_BINS, range=[[-180.0, 180.0], [-90.0, 90.0]])
    ia, ib = np.unravel_index(int(np.argmax(hist)), hist.shape)
    inside = (alpha >= ea[ia]) & (alpha <= ea[ia + 1]) & (beta >= eb[ib]) & (beta <= eb[ib + 1])
    ca, cb = float(np.mean(alpha[inside])), float(np.mean(beta[inside]))
    for _ in range(100):
        da, db = wrap_rad(np.radians(alpha - ca)) * 180.0 / np.pi, beta - cb
        dist = np.hypot(da, db)
        w = np.where(dist <= radius_deg, np.exp(-0.5 * (dist / radius_deg) ** 2), 0.0)
        if w.sum() == 0:
            break
        sa, sb = float((w * da).sum() / w.sum()), float((w * db).sum() / w.sum())
        ca, cb = ca + sa, cb + sb
        if np.hypot(sa, sb) < 1e-4:
            break
    return ca, cb


def paper_correct(t_s: FloatArray, p_enu_m: FloatArray, *, radius_deg: float = 10.0) -> tuple[FloatArray, BoolArray]:
    """One track's points after the paper's correction, and which were replaced.

    ``t_s`` (n,), ``p_enu_m`` (n, 3) in the common ENU. Bad points (most of their vectors
    outside the densest direction's radius) are moved onto the least-squares line through
    the good ones, ``p(t) = p̄ + v (t − t̄)``."""
    n = t_s.size
    replaced = np.zeros(n, dtype=bool)
    if n < 3:
        return p_enu_m, replaced
    alpha, beta, a, b = _directions_deg(p_enu_m, t_s)
    ca, cb = _mean_shift_deg(alpha, beta, radius_deg)
    outside = np.hypot(wrap_rad(np.radians(alpha - ca)) * 180.0 / np.pi, beta - cb) > radius_deg
    out_count = np.bincount(a, outside, n) + np.bincount(b, outside, n)
    bad = out_count > 0.5 * (n - 1)
    good = ~bad
    if good.sum() < 2 or not bad.any():
        return p_enu_m, replaced
    tg = t_s[good]
    t_bar = tg.mean()
    X = np.stack([np.ones(tg.size), tg - t_bar], axis=1)
    coef, *_ = np.linalg.lstsq(X, p_enu_m[good], rcond=None)
    fitted = coef[0] + np.outer(t_s - t_bar, coef[1])
    p = p_enu_m.copy()
    p[bad] = fitted[bad]
    return p, bad
