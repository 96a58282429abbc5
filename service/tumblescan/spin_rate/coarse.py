"""A coarse rate from a Lomb-Scargle periodogram (irregular sampling) of the target's orientation."""

from __future__ import annotations

import numpy as np

from .._typing import FloatArray


def lomb_scargle_peaks(t_s: FloatArray, angle_rad: FloatArray, omegas: FloatArray, n_peaks: int = 3) -> list[float]:
    """The rates (rad/s) of the ``n_peaks`` highest local maxima of the periodogram of ``cos 2ψ``
    and ``sin 2ψ`` over ``omegas`` (ψ: the target's second-moment orientation, which repeats twice
    per turn of a seen-from-the-axis target), highest first; empty under 4 samples. Only an
    initialiser: with under one turn its peaks are broad, and a target that looks alike after half
    a turn puts a peak at twice the rate."""
    from scipy.signal import lombscargle

    if len(t_s) < 4 or len(omegas) == 0:
        return []
    power = np.zeros(len(omegas))
    for sig in (np.cos(2 * angle_rad), np.sin(2 * angle_rad)):
        if np.ptp(sig) > 1e-9:
            power += lombscargle(t_s, sig - sig.mean(), 2 * omegas, normalize=True)
    padded = np.r_[-np.inf, power, -np.inf]
    is_peak = (padded[1:-1] >= padded[:-2]) & (padded[1:-1] > padded[2:])
    order = [int(k) for k in np.argsort(-power) if is_peak[k]]
    return [float(omegas[k]) for k in order[:n_peaks]]


def mask_orientation(mask: np.ndarray) -> float:
    """The orientation (rad) of a mask's principal second moment."""
    v, u = np.nonzero(mask)
    du, dv = u - u.mean(), v - v.mean()
    return float(0.5 * np.arctan2(2 * np.mean(du * dv), np.mean(du * du) - np.mean(dv * dv)))
