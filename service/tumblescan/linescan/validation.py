"""Covariance of a fit, the sigmas it implies, and the two-frame-count similarity test.

The covariance of the maximum-likelihood fit is ``s^2 (J^T J)^-1`` with ``J`` the whitened
Jacobian at the solution and ``s^2 = chi^2 / (m - p)`` (so a misdeclared noise level is
corrected by the data). At the true parameters with ``s = 1`` it is the Cramer-Rao bound.

Similarity (paper eq. 11): solutions ``X1`` (all frames) and ``X2`` (the first frames) are
compared through ``g(x) = (l_s, w_s, l_p, w_p, O_p)`` (axes as vectors, so poles and the
azimuth wrap do not matter). Noise-free data use the paper's ``||g1 - g2|| < 1e-3``.

With noise, ``X2`` (fewer frames) uses a subset of ``X1``'s data, so to first order
``Var(X2 - X1) = Sigma2 - Sigma1 <= Sigma2`` (Hausman). A full Mahalanobis distance with
either matrix proved fragile in practice: both are nearly singular along directions the
frames barely separate, where the linearization is poorest, and good solutions were
rejected. The test is therefore per component, with the bound ``Sigma2``:
``d = max_i |dg_i| / sd2_i`` against the two-sided normal quantile at ``alpha / (2 k)``
(Bonferroni over the ``k`` components). It stays conservative for noise and still separates
distinct minima, which differ by many sigma.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._typing import FloatArray
from ..errors import InvalidOptionError
from ..geometry.rotations import axis_from_angles, axis_tangents
from ..numerics.derivatives import complex_step
from ..target.motion import N_PARAMS, canonical_params
from .tracks import MIN_FRAMES

PAPER_EPS = 1e-3
# Below this fitted noise scale (in units of the declared sigma) data count as noise-free.
NOISE_FREE_SCALE = 1e-6


def embed(cov_free: FloatArray, free: tuple[int, ...]) -> FloatArray:
    """A 9x9 covariance with zeros for fixed parameters."""
    full = np.zeros((N_PARAMS, N_PARAMS))
    idx = np.array(free)
    full[np.ix_(idx, idx)] = cov_free
    return full


def axis_sigma_rad(x: FloatArray, cov9: FloatArray, a: int, b: int) -> float:
    """Total angular 1-sigma of the axis ``(x[a], x[b])``: ``sqrt(trace(J C J^T))``."""
    Jl = axis_tangents(x[a], x[b])
    C = cov9[np.ix_([a, b], [a, b])]
    return float(np.sqrt(max(np.trace(Jl @ C @ Jl.T), 0.0)))


def comparison_vector(x: NDArray[Any], spin_only: bool) -> NDArray[Any]:
    """``g(x)``: spin axis, spin rate, [precession axis, precession rate,] centre."""
    l_s = axis_from_angles(x[..., 0], x[..., 1])
    parts = [l_s, x[..., 2:3]]
    if not spin_only:
        parts += [axis_from_angles(x[..., 3], x[..., 4]), x[..., 5:6]]
    parts.append(x[..., 6:9])
    return np.concatenate(parts, axis=-1)


@dataclass(frozen=True)
class Similarity:
    passed: bool
    distance: float
    threshold: float
    test: str


def similarity(
    x1: FloatArray,
    x2: FloatArray,
    cov2: FloatArray,
    *,
    free: tuple[int, ...],
    noise_scale: float,
    alpha: float,
) -> Similarity:
    """Compare two canonical 9-vectors given the unscaled 9x9 covariance of the second
    (the one from fewer frames); see the module docstring."""
    spin_only = 5 not in free
    dg = comparison_vector(x1, spin_only) - comparison_vector(x2, spin_only)
    if noise_scale < NOISE_FREE_SCALE:
        d = float(np.linalg.norm(dg))
        return Similarity(d < PAPER_EPS, d, PAPER_EPS, "fixed")
    G = complex_step(lambda xs: comparison_vector(xs, spin_only), x2, free).T  # (k, len(free))
    idx = np.array(free)
    var = np.einsum("ij,jk,ik->i", G, cov2[np.ix_(idx, idx)], G) * noise_scale**2
    d = float(np.max(np.abs(dg) / np.sqrt(np.maximum(var, 1e-300))))
    from scipy import stats  # here, not at the top: the result model imports this module

    threshold = float(stats.norm.isf(alpha / (2 * len(dg))))
    return Similarity(d < threshold, d, threshold, "covariance")


def canonical_cov(x: FloatArray, cov9: FloatArray) -> FloatArray:
    """Covariance after :func:`canonical_params`, whose Jacobian is diagonal with entries
    +-1 (axis flips negate ``b`` and ``w``); the signs are read off a tiny step."""
    h = 1e-6
    step = canonical_params(x + h) - canonical_params(x)
    sign = np.sign(np.mod(step + np.pi, 2 * np.pi) - np.pi)
    return np.asarray(cov9 * np.outer(sign, sign), dtype=float)


def validation_frame_count(n_frames: int, requested: int | None) -> int:
    if requested is not None:
        if requested >= n_frames:
            raise InvalidOptionError(
                f"validation_frames={requested} must be fewer than the {n_frames} frames given",
                field="options.validation_frames",
            )
        return requested
    return max(MIN_FRAMES, n_frames - max(1, round(n_frames / 4)))
