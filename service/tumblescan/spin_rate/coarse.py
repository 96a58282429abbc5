"""A coarse rate from a Lomb-Scargle periodogram (irregular sampling) of the target's orientation."""

from __future__ import annotations

import numpy as np

from .._typing import FloatArray


def lomb_scargle_rate(t_s: FloatArray, angle_rad: FloatArray, omegas: FloatArray) -> float | None:
    """The rate (rad/s) at the periodogram's peak of ``cos 2ψ`` and ``sin 2ψ`` (ψ: the target's
    second-moment orientation, which repeats twice per turn of a seen-from-the-axis target); None
    under 4 samples. Only an initialiser: with under one turn its peak is broad."""
    from scipy.signal import lombscargle

    if len(t_s) < 4 or len(omegas) == 0:
        return None
    power = np.zeros(len(omegas))
    for sig in (np.cos(2 * angle_rad), np.sin(2 * angle_rad)):
        if np.ptp(sig) > 1e-9:
            power += lombscargle(t_s, sig - sig.mean(), 2 * omegas, normalize=True)
    return float(omegas[int(np.argmax(power))])


def mask_orientation(mask: np.ndarray) -> float:
    """The orientation (rad) of a mask's principal second moment."""
    v, u = np.nonzero(mask)
    du, dv = u - u.mean(), v - v.mean()
    return float(0.5 * np.arctan2(2 * np.mean(du * dv), np.mean(du * du) - np.mean(dv * dv)))
