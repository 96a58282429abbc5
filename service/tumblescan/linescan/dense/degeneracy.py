"""Motions the frames barely separate, and estimates too imprecise to trust: said in warnings.

Spin and precession about nearly one axis (``l_s`` within a few degrees of ``+-l_p``) turn the
target as one rotation about that axis at ``w_s + w_p (l_s . l_p)``: the frames fix that
rotation, not how it splits between spin and precession, and a fit reports a split the noise
chose. So does a precession that turns through only a few degrees while the frames are taken.
Such a motion is reported with the spin-only model's answer beside it, and called unreliable.
A precise-looking answer is only as good as its reported sigma: one whose sigma exceeds a
third of the accuracy the method aims at (0.1 deg on the axes, 0.05 deg/s on the rates) is
called imprecise, so that a miss of those limits is not silent.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from ..._typing import FloatArray
from ...geometry.rotations import axis_from_angles
from ..options import FramesOptions
from ..sensor import SensorNoise
from ..validation import axis_sigma_rad
from .data import DenseData
from .refine import DenseFit, refine_dense

# Axes (or one and the other's opposite) closer than this, or closer than this many of their
# combined sigmas, are "nearly parallel".
NEAR_PARALLEL_DEG = 5.0
NEAR_PARALLEL_SIGMAS = 3.0
# Precession through less than this over the frames' time span is "very slow".
SLOW_PRECESSION_DEG = 10.0
# The accuracy the method aims at (issue "real shapes"); a 1-sigma above a third of it is imprecise.
AXIS_LIMIT_DEG = 0.1
RATE_LIMIT_DEG_S = 0.05
IMPRECISE_SIGMAS = 3.0


def precession_p_value(x: FloatArray, cov: FloatArray) -> float:
    """The p-value of "no precession" for a spin-precession 9-vector ``x`` with covariance ``cov``.

    A pure spin is either ``w_p = 0`` or a precession about the spin axis itself (the two turn
    the target as one rotation). So two Wald tests, and the larger p-value: of ``w_p`` alone, and
    of the precession's part across the spin axis, ``v = w_p (l_p - (l_p . l_s) l_s)`` (2 degrees
    of freedom, ``v^T C_v^+ v ~ chi2(2)`` with ``C_v = G C G^T`` and ``G = dv/dx`` by central
    differences). Near parallel axes ``w_p`` alone can look significant while the fit cannot tell
    its axis from the spin axis; ``v`` then is not.
    """
    z = abs(float(x[5])) / float(np.sqrt(cov[5, 5])) if cov[5, 5] > 0 else np.inf
    p_rate = float(2 * stats.norm.sf(z))
    v = _across_spin(x)
    G = np.empty((3, 6))
    for k in range(6):
        h = 1e-7 * max(abs(float(x[k])), 1.0)
        step = np.zeros(len(x))
        step[k] = h
        G[:, k] = (_across_spin(x + step) - _across_spin(x - step)) / (2 * h)
    C_v = G @ cov[:6, :6] @ G.T
    chi2 = float(v @ np.linalg.pinv(C_v, rcond=1e-9, hermitian=True) @ v)
    return max(p_rate, float(stats.chi2.sf(chi2, 2)))


def _across_spin(x: FloatArray) -> FloatArray:
    """The precession vector's part across the spin axis, ``w_p (l_p - (l_p . l_s) l_s)`` (rad/s)."""
    l_s, l_p = axis_from_angles(x[0], x[1]), axis_from_angles(x[3], x[4])
    return np.asarray(x[5] * (l_p - (l_p @ l_s) * l_s), dtype=float)


def degenerate_warnings(data: DenseData, fit: DenseFit, opts: FramesOptions, noise: SensorNoise) -> list[str]:
    """Warnings for a spin-precession ``fit`` whose spin and precession the frames barely separate
    (see the module docstring), each with the spin-only model's answer refined on ``data``;
    empty when the motion is well separated or already spin-only."""
    if fit.spin_only:
        return []
    x = fit.x
    l_s, l_p = axis_from_angles(x[0], x[1]), axis_from_angles(x[3], x[4])
    cos_nu = float(np.clip(l_s @ l_p, -1.0, 1.0))
    apart_deg = float(np.degrees(np.arccos(abs(cos_nu))))
    sigma_deg = float(np.degrees(np.hypot(axis_sigma_rad(x, fit.cov, 0, 1), axis_sigma_rad(x, fit.cov, 3, 4))))
    span_s = float(np.ptp(data.tau_s))
    swept_deg = float(np.degrees(abs(x[5]) * span_s))
    reasons = []
    if apart_deg < max(NEAR_PARALLEL_DEG, NEAR_PARALLEL_SIGMAS * sigma_deg):
        side = "parallel" if cos_nu > 0 else "anti-parallel"
        reasons.append(f"spin and precession axes {apart_deg:.1f} deg from {side} (sigma {sigma_deg:.2g} deg)")
    if swept_deg < SLOW_PRECESSION_DEG:
        reasons.append(f"the precession turns only {swept_deg:.1f} deg over the {span_s:.3g} s of frames")
    if not reasons:
        return []
    # The one rotation the frames do fix: about the spin axis at the combined rate.
    start = x.copy()
    start[2] = x[2] + x[5] * cos_nu
    start[3:6] = 0.0
    alt = refine_dense(data, start, spin_only=True, config=opts.dense, noise=noise, seed=opts.seed)
    axis = axis_from_angles(alt.x[0], alt.x[1])
    return [
        f"near-degenerate motion ({'; '.join(reasons)}): how the rotation splits between spin and precession "
        f"is unreliable. The spin-only model gives spin axis ({axis[0]:.4f}, {axis[1]:.4f}, {axis[2]:.4f}) at "
        f"{np.degrees(alt.x[2]):.4f} deg/s (residuals {alt.scale:.2f} times their expected size, against "
        f"{fit.scale:.2f} for the reported motion)"
    ]


def imprecision_warning(x: FloatArray, cov: FloatArray, *, spin_only: bool) -> str | None:
    """A warning naming the parameters whose reported 1-sigma exceeds a third of the method's
    accuracy limits (``AXIS_LIMIT_DEG``, ``RATE_LIMIT_DEG_S``), or None."""
    sigmas = {
        "spin axis": (np.degrees(axis_sigma_rad(x, cov, 0, 1)), AXIS_LIMIT_DEG, "deg"),
        "spin rate": (np.degrees(np.sqrt(max(cov[2, 2], 0.0))), RATE_LIMIT_DEG_S, "deg/s"),
    }
    if not spin_only:
        sigmas["precession axis"] = (np.degrees(axis_sigma_rad(x, cov, 3, 4)), AXIS_LIMIT_DEG, "deg")
        sigmas["precession rate"] = (np.degrees(np.sqrt(max(cov[5, 5], 0.0))), RATE_LIMIT_DEG_S, "deg/s")
    loose = [f"{name} +-{sd:.2g} {unit}" for name, (sd, limit, unit) in sigmas.items() if IMPRECISE_SIGMAS * sd > limit]
    if not loose:
        return None
    return (
        f"imprecise estimate: {', '.join(loose)} (1 sigma); three sigmas exceed {AXIS_LIMIT_DEG:g} deg on the axes "
        f"or {RATE_LIMIT_DEG_S:g} deg/s on the rates (slow precession, few frames, or little flat surface in view)"
    )
