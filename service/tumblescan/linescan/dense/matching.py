"""Correspondences between surfels of different frames and their centroid-to-plane residuals.

For a source surfel ``a_s`` of one frame and the nearest planar surfel ``a_t`` of another
(within a gate, facing the same way), the residual is

    r = n(x) . (a_s(x) - a_t(x)),    n = mean of the two normals (symmetric objective),
    var r = v_s / N_s + v_t / N_t + d^2 (v_ns + v_nt) / 4

before the common scale ``s`` (see :mod:`.refine`), and the fit's robust loss is Cauchy on
``r / sqrt(var r)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..._typing import FloatArray, IntArray
from ..sensor import SensorNoise
from .data import DenseData
from .mapping import LineMapping
from .surfels import Surfels, normal_variance

CAUCHY_C = 2.385  # Cauchy constant for 95 % efficiency under Gaussian noise
MAX_NORMAL_ANGLE_COS = np.cos(np.radians(45.0))


@dataclass(frozen=True)
class Matches:
    src: IntArray  # source surfel of each residual
    dst: IntArray  # target surfel


def match(
    data: DenseData,
    mapping: LineMapping,
    surf: Surfels,
    src: IntArray,
    partner: IntArray,
    gate_m: float,
) -> Matches:
    """Nearest planar surfel of the partner frame for each (source, partner) pair, if it lies
    within ``gate_m`` and faces the same way as the source's own surfel."""
    anchor_ref = mapping.apply(surf.anchor_obs, surf.line)
    normal_ref = mapping.rotate(surf.normal_obs, surf.line)
    usable = surf.planar[src]
    src, partner = src[usable], partner[usable]
    mapped = anchor_ref[src]
    src_all, dst_all = [], []
    for b in range(data.n_frames):
        sel = np.flatnonzero(partner == b)
        targets = np.flatnonzero((data.cell_frame == b) & surf.planar)
        if len(sel) == 0 or len(targets) == 0:
            continue
        dist, nn = cKDTree(anchor_ref[targets]).query(mapped[sel], k=1, distance_upper_bound=gate_m, workers=-1)
        ok = np.isfinite(dist)
        dst = targets[nn[ok]]
        s = sel[ok]
        facing = np.einsum("ni,ni->n", normal_ref[src[s]], normal_ref[dst]) > MAX_NORMAL_ANGLE_COS
        src_all.append(src[s[facing]])
        dst_all.append(dst[facing])
    src_c = np.concatenate(src_all) if src_all else np.zeros(0, np.int64)
    dst_c = np.concatenate(dst_all) if dst_all else np.zeros(0, np.int64)
    return Matches(src_c, dst_c)


@dataclass(frozen=True)
class Linearized:
    r: FloatArray  # centroid-to-plane residuals (m), then any members' and grazing groups' (terms.py)
    J: FloatArray  # their derivatives w.r.t. the free parameters
    var: FloatArray  # model variance of each residual (m^2), before the common scale


def residuals(mapping: LineMapping, surf: Surfels, m: Matches) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Centroid-to-plane residuals, the plane normals at ``T`` and the squared in-plane offsets.

    The plane's normal is the mean of both surfels' (a symmetric objective): the normal's
    noise times the in-plane offset between the centroids is the largest term of a residual's
    variance, and the mean halves it."""
    p = mapping.apply(surf.anchor_obs[m.src], surf.line[m.src])
    q = mapping.apply(surf.anchor_obs[m.dst], surf.line[m.dst])
    n = mapping.rotate(surf.normal_obs[m.dst], surf.line[m.dst]) + mapping.rotate(
        surf.normal_obs[m.src], surf.line[m.src]
    )
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    d = p - q
    r = np.einsum("ni,ni->n", n, d)
    return np.asarray(r), n, np.asarray(np.einsum("ni,ni->n", d, d) - r**2)


def linearize(data: DenseData, mapping: LineMapping, surf: Surfels, m: Matches, noise: SensorNoise) -> Linearized:
    xyz, line = surf.anchor_obs[m.src], surf.line[m.src]
    r, n, offset2 = residuals(mapping, surf, m)
    J = mapping.normal_derivative(n, xyz, line) - mapping.normal_derivative(n, surf.anchor_obs[m.dst], surf.line[m.dst])
    # The source centroid's noise along the normal, seen from the source's own sensor; the
    # target centroid's; and the normal's tilt over the offset between the two.
    n_src_obs = np.einsum("nji,nj->ni", mapping.Rt[line], n)
    var = (
        normal_variance(noise, xyz, n_src_obs) / surf.count[m.src]
        + surf.var_m2[m.dst] / surf.count[m.dst]
        + offset2 * (surf.normal_var_rad2[m.src] + surf.normal_var_rad2[m.dst]) / 4
    )
    return Linearized(np.asarray(r), J, np.asarray(var))


def cauchyweights(e: FloatArray, scale: float) -> FloatArray:
    return np.asarray(1.0 / (1.0 + (e / (CAUCHY_C * scale)) ** 2))


def robust_sigma(r: FloatArray) -> float:
    return float(1.4826 * np.median(np.abs(r))) if len(r) else 0.0


def cauchy_cost(e: FloatArray, scale: float) -> float:
    c2 = (CAUCHY_C * scale) ** 2
    return float(0.5 * c2 * np.sum(np.log1p(e**2 / c2)))


def weights(lin: Linearized) -> tuple[FloatArray, float]:
    """Weights ``cauchy(e / s) / var`` of the normalized residuals ``e = r / sqrt(var)``, and ``s``."""
    e = lin.r / np.sqrt(lin.var)
    scale = max(robust_sigma(e), 1e-12)
    return cauchyweights(e, scale) / lin.var, scale


def partners(
    data: DenseData, src: IntArray, rng: np.random.Generator, *, window: int | None, k: int
) -> tuple[IntArray, IntArray]:
    """``k`` random other frames for each source surfel (within ``window`` frames of its own, if
    given): the pairs as parallel arrays ``(source, partner frame)``."""
    F = data.n_frames
    reach = F - 1 if window is None else min(window, F - 1)
    own = data.cell_frame[src]
    if window is None and k >= F - 1:
        # Every other frame, in order: nothing left to chance.
        b = (own[:, None] + np.arange(1, F)[None, :]) % F
        return np.repeat(src, F - 1), b.ravel()
    offsets = np.concatenate([-np.arange(reach, 0, -1), np.arange(1, reach + 1)])
    out_src, out_partner = [], []
    for _ in range(min(k, 2 * reach)):
        b = own + offsets[rng.integers(0, len(offsets), len(src))]
        # Offsets past either end fold back inside (a frame never pairs with itself).
        b = np.where(b < 0, -b, b)
        b = np.where(b >= F, 2 * (F - 1) - b, b)
        ok = (b != own) & (b >= 0) & (b < F)
        out_src.append(src[ok])
        out_partner.append(b[ok])
    return np.concatenate(out_src), np.concatenate(out_partner)
