"""Jacobians by complex step: exact to rounding, no step-size trade-off."""

from __future__ import annotations

import numpy as np

from .._typing import FloatArray

STEP = 1e-30  # complex-step size: no cancellation, so any tiny step is exact


def complex_step(fun: object, x: FloatArray, free: tuple[int, ...]) -> FloatArray:
    """Derivatives of ``fun(x)`` w.r.t. ``x[free]``; ``fun`` maps ``(k, 9)`` -> ``(k, ...)``.

    Returns shape ``(len(free), ...)``.
    """
    probes = np.tile(x.astype(complex), (len(free), 1))
    probes[np.arange(len(free)), list(free)] += 1j * STEP
    return np.asarray(fun(probes).imag / STEP, dtype=np.float64)  # type: ignore[operator]
