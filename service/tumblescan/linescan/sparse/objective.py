"""Least-squares objectives over feature tracks (method.md section 3).

Maximum likelihood (the default): estimate the motion ``x`` and each track's position
``P_j`` at the reference time ``T``, weighting each residual by the sensor noise:

    min  sum_ji || W_ji ( O_p + R(t_ji - T) (P_j - O_p) - y_ji ) ||^2

Pairwise (paper eq. 10): predict each observation from the previous one of its track:

    min  sum_i || O_p + R(t_{i+1} - T) R(t_i - T)^T (y_i - O_p) - y_{i+1} ||^2

Jacobians with respect to the motion are taken by complex step (exact to rounding; the
model is analytic), all 9 directions in one vectorized evaluation; the ``P_j`` blocks are
the analytic ``W R``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..._typing import FloatArray
from ...geometry.rotations import axis_from_angles
from ...numerics.derivatives import complex_step
from ...target.motion import N_PARAMS, predict, rotation_matrices, to_reference, transport
from ..sensor import SensorNoise
from ..tracks import Tracks

ALL_FREE = tuple(range(N_PARAMS))
SPIN_ONLY_FREE = (0, 1, 2, 6, 7, 8)  # precession rate fixed at zero


def body_positions(x: FloatArray, tracks: Tracks, reference_time_s: float) -> FloatArray:
    """Each track's position at ``T``: the mean of its observations mapped back to ``T``."""
    at_ref = to_reference(x, tracks.xyz_m, tracks.t_s - reference_time_s)
    sums = np.zeros((tracks.n_tracks, 3))
    np.add.at(sums, tracks.track, at_ref)
    counts = np.bincount(tracks.track, minlength=tracks.n_tracks)
    return np.asarray(sums / counts[:, None], dtype=float)


@dataclass
class MLProblem:
    """The maximum-likelihood problem over ``z = (x[free], P_1, ..., P_m)``.

    ``base`` holds the values of parameters that are not free. With the spin-only model the
    centre can slide along the spin axis without changing the fit; one gauge row
    ``l_s . (O - gauge_point)`` pins it to the point of the axis nearest ``gauge_point``.
    ``mask`` (bool per observation) removes rejected outliers from the fit.
    """

    tracks: Tracks
    noise: SensorNoise
    reference_time_s: float
    free: tuple[int, ...] = ALL_FREE
    base: FloatArray = field(default_factory=lambda: np.zeros(N_PARAMS))
    gauge_point: FloatArray | None = None
    mask: NDArray[np.bool_] | None = None

    def __post_init__(self) -> None:
        self.tau = self.tracks.t_s - self.reference_time_s
        self.W = self.noise.whitening(self.tracks.xyz_m)
        self.keep = np.ones(len(self.tau), bool) if self.mask is None else self.mask

    @property
    def n_free(self) -> int:
        return len(self.free)

    def pack(self, x: FloatArray, body_m: FloatArray) -> FloatArray:
        return np.concatenate([np.asarray(x)[list(self.free)], body_m.ravel()])

    def unpack(self, z: FloatArray) -> tuple[FloatArray, FloatArray]:
        x = self.base.astype(z.dtype).copy()
        x[list(self.free)] = z[: self.n_free]
        return x, z[self.n_free :].reshape(-1, 3)

    def _gauge(self, x: NDArray[Any]) -> NDArray[Any]:
        assert self.gauge_point is not None
        l_s = axis_from_angles(x[..., 0], x[..., 1])
        return np.asarray(np.sum(l_s * (x[..., 6:9] - self.gauge_point), axis=-1)[..., None])

    def residuals(self, z: FloatArray) -> FloatArray:
        x, body = self.unpack(z)
        r = np.einsum("nij,nj->ni", self.W, predict(x, body[self.tracks.track], self.tau) - self.tracks.xyz_m)
        out = r[self.keep].ravel()
        if self.gauge_point is not None:
            out = np.concatenate([out, self._gauge(x)])
        return np.asarray(out, dtype=float)

    def jacobian(self, z: FloatArray) -> FloatArray:
        x, body = self.unpack(z)
        pts = body[self.tracks.track]
        keep = self.keep
        n, k = int(keep.sum()), self.n_free
        J = np.zeros((3 * n + (self.gauge_point is not None), k + 3 * len(body)))
        # Motion columns: complex step through the forward model, all directions at once.
        d_motion = complex_step(lambda xs: predict(xs, pts, self.tau), x, self.free)  # (k, N, 3)
        J[: 3 * n, :k] = np.einsum("nij,knj->nik", self.W, d_motion)[keep].reshape(3 * n, k)
        # Body columns: d pred / d P_j = R(tau), so W R in the track's block.
        R = rotation_matrices(x, self.tau)
        WR = np.einsum("nij,njk->nik", self.W, R)[keep]
        rows = np.arange(3 * n).reshape(n, 3)
        cols = k + 3 * self.tracks.track[keep][:, None] + np.arange(3)
        J[rows[:, :, None], cols[:, None, :]] = WR
        if self.gauge_point is not None:
            J[-1, :k] = complex_step(self._gauge, x, self.free)[:, 0]
        return J

    # Variable projection: for fixed motion each P_j is a weighted linear least-squares
    # solution, so LM can run over the motion alone (9 unknowns instead of 9 + 3m).
    # With A_i = W_i R_i and the residual A_i P_j + W_i (c_i - y_i), c_i = (I - R_i) O:
    #     P_j = -(sum A^T A)^-1 sum A^T W (c - y)
    # and the Gauss-Newton Jacobian of the projected residual is Kaufman's
    #     J = (I - A (A^T A)^-1 A^T) dr/dx, applied per track.

    def _blocks(self, x: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``A = W R`` per kept observation, ``G_j = sum A^T A`` and the optimal ``P_j``."""
        keep = self.keep
        R = rotation_matrices(x, self.tau[keep])
        A = self.W[keep] @ R
        c = x[6:9] - np.einsum("nij,j->ni", R, x[6:9])
        rhs = np.einsum("nij,nj->ni", self.W[keep], c - self.tracks.xyz_m[keep])
        track = self.tracks.track[keep]
        m = self.tracks.n_tracks
        G = np.zeros((m, 3, 3))
        np.add.at(G, track, A.transpose(0, 2, 1) @ A)
        b = np.zeros((m, 3))
        np.add.at(b, track, np.einsum("nji,nj->ni", A, rhs))
        # Tracks with no kept observation get a harmless identity block.
        empty = np.bincount(track, minlength=m) == 0
        G[empty] = np.eye(3)
        body = -np.linalg.solve(G, b[..., None])[..., 0]
        return A, G, np.asarray(body, dtype=np.float64)

    def body_for(self, x: FloatArray) -> FloatArray:
        """The optimal ``P_j`` for motion ``x`` (full 9-vector)."""
        return self._blocks(x)[2]

    def reduced_residuals(self, xf: FloatArray) -> FloatArray:
        x = self._x_from_free(xf)
        return self.residuals(self.pack(x, self.body_for(x)))

    def reduced_jacobian(self, xf: FloatArray) -> FloatArray:
        x = self._x_from_free(xf)
        A, G, body = self._blocks(x)
        keep = self.keep
        pts = body[self.tracks.track]
        d_motion = complex_step(lambda xs: predict(xs, pts, self.tau), x, self.free)  # (k, N, 3)
        Jx = np.einsum("nij,knj->nik", self.W, d_motion)[keep]  # (n, 3, k)
        track = self.tracks.track[keep]
        H = np.zeros((self.tracks.n_tracks, 3, self.n_free))
        np.add.at(H, track, A.transpose(0, 2, 1) @ Jx)
        correction = A @ np.linalg.solve(G, H)[track]
        J = (Jx - correction).reshape(-1, self.n_free)
        if self.gauge_point is not None:
            J = np.vstack([J, complex_step(self._gauge, x, self.free)[:, 0][None, :]])
        return np.asarray(J, dtype=float)

    def _x_from_free(self, xf: FloatArray) -> FloatArray:
        x = self.base.astype(float).copy()
        x[list(self.free)] = xf
        return x


@dataclass
class PairwiseProblem:
    """The paper's eq. (10) over the 9 motion parameters (or a free subset)."""

    tracks: Tracks
    reference_time_s: float
    free: tuple[int, ...] = ALL_FREE
    base: FloatArray = field(default_factory=lambda: np.zeros(N_PARAMS))

    def __post_init__(self) -> None:
        self.first, self.second = consecutive_pairs(self.tracks)
        tau = self.tracks.t_s - self.reference_time_s
        self.tau1, self.tau2 = tau[self.first], tau[self.second]
        self.y1, self.y2 = self.tracks.xyz_m[self.first], self.tracks.xyz_m[self.second]

    def _x(self, z: NDArray[Any]) -> NDArray[Any]:
        x = np.broadcast_to(self.base, (*z.shape[:-1], N_PARAMS)).astype(z.dtype)
        x[..., list(self.free)] = z
        return x

    def _predict(self, x: NDArray[Any]) -> NDArray[Any]:
        return np.asarray(transport(x, self.y1, self.tau1, self.tau2) - self.y2)

    def residuals(self, z: FloatArray) -> FloatArray:
        return np.asarray(self._predict(self._x(z)).ravel(), dtype=float)

    def jacobian(self, z: FloatArray) -> FloatArray:
        d = complex_step(lambda xs: self._predict(xs), self._x(z), self.free)  # (k, n, 3)
        return np.asarray(np.moveaxis(d, 0, -1).reshape(-1, len(self.free)), dtype=float)


def consecutive_pairs(tracks: Tracks) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Index pairs ``(i, j)`` of successive observations of the same track."""
    order = np.lexsort((tracks.t_s, tracks.track))
    same = tracks.track[order][1:] == tracks.track[order][:-1]
    return order[:-1][same], order[1:][same]
