"""The motion's per-line rotations that move points seen at ``t = T + tau`` to the reference time.

With a motion ``x``, every point ``p`` seen at ``t = T + tau`` maps to ``T`` as
``M(p, tau; x) = O_p + R(tau)^T (p - O_p)``; ``R(tau)^T`` is computed once per line time, with
its complex-step derivatives in the free parameters.
"""

from __future__ import annotations

from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from ..._typing import FloatArray, IntArray
from ...geometry.rotations import axis_from_angles, rotation_matrix

STEP = 1e-20  # complex-step size: exact derivatives, no cancellation
# Points mapped to T per chunk of this many (LineMapping.apply): the gathered rotations stay in cache.
APPLY_CHUNK = 65536
# Rows per chunk of LineMapping.normal_derivative: its (rows, 9, parameters) gather stays in cache.
DERIVATIVE_CHUNK = 4096


class LineMapping:
    """``R(tau)^T`` per line and its derivatives w.r.t. the free parameters (complex step)."""

    def __init__(self, x: FloatArray, tau_s: FloatArray, free: tuple[int, ...]) -> None:
        self.x = x
        self.tau_s = tau_s
        self.Rt = _rotations_T(x.astype(complex)[None, :], tau_s)[0].real
        self.free = free
        self.center = x[6:9]

    @cached_property
    def dRt(self) -> FloatArray:
        """``(lines, 9, k)``: row ``3a + b`` holds ``d(R^T)[a, b]`` for each free parameter."""
        # The centre (parameters 6-8) does not enter R: its columns are zero, not probed.
        turning = [j for j, p in enumerate(self.free) if p < 6]
        probes = np.tile(self.x.astype(complex), (len(turning), 1))
        probes[np.arange(len(turning)), [self.free[j] for j in turning]] += 1j * STEP
        dRt = np.zeros((len(self.tau_s), 9, len(self.free)))
        step = _rotations_T(probes, self.tau_s).imag / STEP  # (turning, lines, 3, 3)
        dRt[:, :, turning] = step.transpose(1, 2, 3, 0).reshape(len(self.tau_s), 9, len(turning))
        return dRt

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

    def normal_derivative(self, n: FloatArray, xyz: FloatArray, line: IntArray) -> FloatArray:
        """``n . dM(xyz, line)/dx_free`` for each row, ``(rows, k)``; the centre enters as ``(I - R^T)``."""
        v = xyz - self.center
        out = np.zeros((len(xyz), len(self.free)))
        dRt = self.dRt
        # Each row's lines' derivatives gathered once per chunk that stays in cache (not once
        # per entry of R^T over every row), summed in the same order.
        for s in range(0, len(xyz), DERIVATIVE_CHUNK):
            part = dRt[line[s : s + DERIVATIVE_CHUNK]]
            o, n_s, v_s = out[s : s + DERIVATIVE_CHUNK], n[s : s + DERIVATIVE_CHUNK], v[s : s + DERIVATIVE_CHUNK]
            for a in range(3):
                for b in range(3):
                    o += (n_s[:, a] * v_s[:, b])[:, None] * part[:, 3 * a + b]
        Rtn = np.einsum("nab,na->nb", self.Rt[line], n)
        for j, p in enumerate(self.free):
            if p >= 6:
                out[:, j] += n[:, p - 6] - Rtn[:, p - 6]
        return out


def _rotations_T(x: NDArray[np.complex128], tau_s: FloatArray) -> NDArray[np.complex128]:
    """``R(tau)^T = Rs^T Rp^T`` for parameter rows ``(k, 9)`` and offsets ``(m,)``: ``(k, m, 3, 3)``."""
    l_s = axis_from_angles(x[:, 0], x[:, 1])[:, None, :]
    l_p = axis_from_angles(x[:, 3], x[:, 4])[:, None, :]
    Rs = rotation_matrix(l_s, x[:, [2]] * tau_s)
    Rp = rotation_matrix(l_p, x[:, [5]] * tau_s)
    return np.asarray(np.swapaxes(Rp @ Rs, -1, -2))
