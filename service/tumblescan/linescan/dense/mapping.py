"""The motion's per-line rotations that move points seen at ``t = T + tau`` to the reference time.

With a motion ``x``, every point ``p`` seen at ``t = T + tau`` maps to ``T`` as
``M(p, tau; x) = O_p + R(tau)^T (p - O_p)``; ``R(tau)^T`` is computed once per line time, with
its derivatives in the free parameters as axial vectors (``LineMapping._axial``).
"""

from __future__ import annotations

from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from ..._typing import FloatArray, IntArray
from ...geometry.rotations import axis_from_angles, axis_tangents, rotation_matrix

# Points mapped to T per chunk of this many (LineMapping.apply): the gathered rotations stay in cache.
APPLY_CHUNK = 65536
# Rows per chunk of LineMapping.normal_derivative: its gather of each row's line stays in cache.
DERIVATIVE_CHUNK = 4096


class LineMapping:
    """``R(tau)^T`` per line and its derivatives w.r.t. the free parameters."""

    def __init__(self, x: FloatArray, tau_s: FloatArray, free: tuple[int, ...]) -> None:
        self.x = x
        self.tau_s = tau_s
        self.Rt = _rotations_T(x.astype(complex)[None, :], tau_s)[0].real
        self.free = free
        self.center = x[6:9]

    @cached_property
    def _rows(self) -> FloatArray:
        """``R(tau)^T`` per line as 9 contiguous rows ``(9, lines)``: entry ``3a + b`` of every line."""
        return np.ascontiguousarray(self.Rt.reshape(len(self.tau_s), 9).T)

    def apply(self, xyz: FloatArray, line: IntArray) -> FloatArray:
        return self._turned(xyz, line, center=self.center, about_center=False)

    def apply_about_center(self, xyz: FloatArray, line: IntArray) -> FloatArray:
        """``apply(xyz, line) - center``, rounded as that is (the surfel build works about the centre)."""
        return self._turned(xyz, line, center=self.center, about_center=True)

    def rotate(self, v: FloatArray, line: IntArray) -> FloatArray:
        return self._turned(v, line, center=None, about_center=False)

    def _turned(self, xyz: FloatArray, line: IntArray, *, center: FloatArray | None, about_center: bool) -> FloatArray:
        """``O_p + R^T (p - O_p)`` per row (``R^T p`` without a ``center``), less ``O_p`` when
        ``about_center``. The lines' entries are gathered in chunks that stay in cache, and each
        row's products summed in the order ``b = 0, 1, 2``, as the einsum over the gathered
        ``(n, 3, 3)`` did (same rounding, half the time on the millions of points a surfel
        build maps)."""
        rows = self._rows
        out = np.empty((len(xyz), 3))
        for s in range(0, len(xyz), APPLY_CHUNK):
            v = (xyz[s : s + APPLY_CHUNK] if center is None else xyz[s : s + APPLY_CHUNK] - center).T
            ln = line[s : s + APPLY_CHUNK]
            o = out[s : s + APPLY_CHUNK]
            for a in range(3):
                o[:, a] = rows[3 * a][ln] * v[0] + rows[3 * a + 1][ln] * v[1] + rows[3 * a + 2][ln] * v[2]
            if center is not None:
                o += center
                if about_center:
                    o -= center
        return out

    @cached_property
    def _axial(self) -> FloatArray:
        """``(3, lines, turning)``: the axial vector ``g`` of ``R d(R^T)/dx`` per turning parameter.

        ``R R^T = I`` makes ``R d(R^T)`` skew, so ``d(R^T) v = R^T (g x v)`` and
        ``n . d(R^T) v = g . (v x R n)``: three products a parameter where the 3 x 3 derivative
        takes nine. With ``R = Rp Rs``, ``g = -(w_p + Rp w_s)``, the spatial angular velocities
        of each factor: ``tau l`` along its rate, ``sin(theta) dl + (1 - cos(theta)) l x dl``
        along either angle of its axis ``l`` (``theta`` its angle, ``dl`` the axis' derivative).
        """
        x, tau = self.x, self.tau_s
        if not any(p < 6 for p in self.free):
            return np.zeros((3, len(tau), 0))
        Rp = rotation_matrix(axis_from_angles(x[3], x[4]), x[5] * tau)
        omega: dict[int, FloatArray] = {}
        for first, spun in ((0, True), (3, False)):
            a, b, w = x[first], x[first + 1], x[first + 2]
            l = axis_from_angles(a, b)
            theta = w * tau[:, None]
            for k, d in enumerate(axis_tangents(a, b).T):
                omega[first + k] = np.sin(theta) * d + (1 - np.cos(theta)) * np.cross(l, d)
            omega[first + 2] = tau[:, None] * l
            if spun:  # the spin's velocities are carried through the precession
                for k in range(first, first + 3):
                    omega[k] = np.einsum("lab,lb->la", Rp, omega[k])
        return -np.stack([omega[p] for p in self.free if p < 6], axis=-1).transpose(1, 0, 2)

    def normal_derivative(self, n: FloatArray, xyz: FloatArray, line: IntArray) -> FloatArray:
        """``n . dM(xyz, line)/dx_free`` for each row, ``(rows, k)``: ``g . (v x R n)`` for the
        turning parameters (``_axial``, ``v = xyz - O_p``) and ``n - R n`` for the centre's."""
        rows = self._rows
        turning = [j for j, p in enumerate(self.free) if p < 6]
        out = np.empty((len(xyz), len(self.free)))
        # Gathered per chunk that stays in cache: a row's R, then its line's axial vectors.
        for s in range(0, len(xyz), DERIVATIVE_CHUNK):
            ln = line[s : s + DERIVATIVE_CHUNK]
            n_s = n[s : s + DERIVATIVE_CHUNK].T
            v = (xyz[s : s + DERIVATIVE_CHUNK] - self.center).T
            # R n, entry b = sum_a R^T[a, b] n_a
            Rn = [rows[b][ln] * n_s[0] + rows[3 + b][ln] * n_s[1] + rows[6 + b][ln] * n_s[2] for b in range(3)]
            q = (v[1] * Rn[2] - v[2] * Rn[1], v[2] * Rn[0] - v[0] * Rn[2], v[0] * Rn[1] - v[1] * Rn[0])
            o = out[s : s + DERIVATIVE_CHUNK]
            g = self._axial[:, ln]
            o[:, turning] = q[0][:, None] * g[0] + q[1][:, None] * g[1] + q[2][:, None] * g[2]
            for j, p in enumerate(self.free):
                if p >= 6:
                    o[:, j] = n_s[p - 6] - Rn[p - 6]
        return out


def _rotations_T(x: NDArray[np.complex128], tau_s: FloatArray) -> NDArray[np.complex128]:
    """``R(tau)^T = Rs^T Rp^T`` for parameter rows ``(k, 9)`` and offsets ``(m,)``: ``(k, m, 3, 3)``."""
    l_s = axis_from_angles(x[:, 0], x[:, 1])[:, None, :]
    l_p = axis_from_angles(x[:, 3], x[:, 4])[:, None, :]
    Rs = rotation_matrix(l_s, x[:, [2]] * tau_s)
    Rp = rotation_matrix(l_p, x[:, [5]] * tau_s)
    return np.asarray(np.swapaxes(Rp @ Rs, -1, -2))
