"""Candidate pairs by the epipolar angle: the angle of a ray about the baseline.

Every plane that contains the baseline holds both rays of a true pair, so a true pair has
the same angle ``ψ`` about the baseline at both stations. Sorting one station's ψ and
binary-searching a noise-scaled window around the other's finds all candidates in
O(n log n), and ``χ²_ψ = wrap(ψ1 − ψ2)² / (σ_ψ1² + σ_ψ2²)`` (1 dof) gates them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._typing import FloatArray, IntArray
from .geometry import Station, unit_vectors, wrap_rad
from .inputs import Detections


@dataclass(frozen=True)
class Basis:
    """Baseline direction ``b`` and two axes ``e1``, ``e2`` perpendicular to it (job frame)."""

    b: FloatArray
    e1: FloatArray
    e2: FloatArray


def baseline_basis(stations: tuple[Station, Station]) -> Basis:
    """``b = (s2 − s1)/|s2 − s1|``, ``e1`` = local "up" at the midpoint made orthogonal to b,
    ``e2 = b × e1``."""
    s1, s2 = stations[0].p_job_m, stations[1].p_job_m
    b = (s2 - s1) / np.linalg.norm(s2 - s1)
    up = 0.5 * (stations[0].R_job_from_enu[:, 2] + stations[1].R_job_from_enu[:, 2])
    e1 = up - (up @ b) * b
    if np.linalg.norm(e1) < 1e-6:  # a vertical baseline: any perpendicular will do
        e1 = np.cross(b, [1.0, 0.0, 0.0]) if abs(b[0]) < 0.9 else np.cross(b, [0.0, 1.0, 0.0])
    e1 = e1 / np.linalg.norm(e1)
    return Basis(b=b, e1=e1, e2=np.cross(b, e1))


def rays_job(det: Detections, station: Station) -> FloatArray:
    """Unit lines of sight in the job frame, (n, 3)."""
    return unit_vectors(det.az_rad, det.el_rad) @ station.R_job_from_enu.T


def epipolar_angles(det: Detections, station: Station, basis: Basis) -> tuple[FloatArray, FloatArray]:
    """``ψ`` (rad) of each detection and its variance ``σ_ψ²`` (rad²).

    ``σ_ψ² = [(n_ψ·t_A)² σ_A² cos²E + (n_ψ·t_E)² σ_E²] / |u⊥|²`` with ``n_ψ = −sinψ e1 + cosψ e2``
    and ``t_A``, ``t_E`` the unit tangents of the line of sight along azimuth and elevation.
    """
    M = station.R_job_from_enu
    u = rays_job(det, station)
    u_perp = u - np.outer(u @ basis.b, basis.b)
    x, y = u_perp @ basis.e1, u_perp @ basis.e2
    psi = np.arctan2(y, x)
    n_psi = np.outer(-np.sin(psi), basis.e1) + np.outer(np.cos(psi), basis.e2)
    sa, ca, se, ce = np.sin(det.az_rad), np.cos(det.az_rad), np.sin(det.el_rad), np.cos(det.el_rad)
    t_A = np.stack([ca, -sa, np.zeros_like(sa)], axis=-1) @ M.T
    t_E = np.stack([-se * sa, -se * ca, ce], axis=-1) @ M.T
    gA = np.einsum("ij,ij->i", n_psi, t_A)
    gE = np.einsum("ij,ij->i", n_psi, t_E)
    norm2 = np.maximum(x * x + y * y, 1e-30)
    var = (gA**2 * det.sigma_az_rad**2 * ce**2 + gE**2 * det.sigma_el_rad**2) / norm2
    return psi, var


def candidate_pairs(
    psi1: FloatArray, var1: FloatArray, psi2: FloatArray, var2: FloatArray, gate: float
) -> tuple[IntArray, IntArray, FloatArray]:
    """All (i, j) with ``χ²_ψ ≤ gate``, found by a sorted search; returns i, j and χ²_ψ.

    Rays almost along the baseline have a huge σ_ψ; they are compared with every ray of the
    other station instead of widening everyone's window.
    """
    n1, n2 = psi1.size, psi2.size
    if n1 == 0 or n2 == 0:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty, np.zeros(0)
    wide = var2 > 100.0 * np.median(var2) + 1e-30
    narrow = np.flatnonzero(~wide)
    parts_i: list[IntArray] = []
    parts_j: list[IntArray] = []
    if narrow.size:
        order = narrow[np.argsort(psi2[narrow])]
        ps = psi2[order]
        ext = np.concatenate([ps - 2 * np.pi, ps, ps + 2 * np.pi])
        ext_idx = np.concatenate([order, order, order])
        half = np.minimum(np.sqrt(gate * (var1 + var2[narrow].max())), np.pi * (1 - 1e-9))
        lo = np.searchsorted(ext, psi1 - half, side="left")
        hi = np.searchsorted(ext, psi1 + half, side="right")
        counts = hi - lo
        i = np.repeat(np.arange(n1), counts)
        start = np.repeat(lo - (np.cumsum(counts) - counts), counts)
        parts_i.append(i)
        parts_j.append(ext_idx[start + np.arange(i.size)])
    wide_idx = np.flatnonzero(wide)
    if wide_idx.size:
        parts_i.append(np.repeat(np.arange(n1), wide_idx.size))
        parts_j.append(np.tile(wide_idx, n1))
    i = np.concatenate(parts_i)
    j = np.concatenate(parts_j)
    chi2 = wrap_rad(psi1[i] - psi2[j]) ** 2 / (var1[i] + var2[j])
    keep = chi2 <= gate
    return i[keep], j[keep], chi2[keep]
