"""Covariance of a least-squares fit from its whitened Jacobian."""

from __future__ import annotations

import numpy as np

from .._typing import FloatArray


def covariance(J: FloatArray, n_params: int) -> FloatArray:
    """``(J^T J)^+`` restricted to the first ``n_params`` unknowns (pseudo-inverse by SVD)."""
    _, s, Vt = np.linalg.svd(J, full_matrices=False)
    keep = s > s[0] * 1e-12
    V = Vt[keep].T[:n_params]
    return np.asarray((V / s[keep] ** 2) @ V.T, dtype=float)
