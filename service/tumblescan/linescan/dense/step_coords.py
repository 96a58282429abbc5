"""The coordinates the refinement steps in: the spin and the precession as rotation-rate vectors.

The motion's parameters ``x`` give each rotation as an axis (spherical angles ``a, b``) and a
rate ``w``. Steps are taken in the vectors ``V = w l(a, b)`` instead (rad/s, the centre
unchanged), and mapped back to angles and rate exactly, so a step follows a straight line in
``V``. Why: when the spin and precession axes are nearly parallel or anti-parallel, the frames
pin down the total rotation, ``S + P`` at ``T`` and its turn ``P x S``, much better than its
split between spin and precession. The set of motions that fit equally well is then close to the
straight line ``P' = P + mu (S + P)``, ``S' = (S + P) - P'`` in the vectors (both keep ``S + P``
and ``P x S``), but a curve along which the precession axis swings by tens of degrees in the
angles. A Gauss-Newton step in the angles leaves that curve at once (on the box at 50 m, axes
11.5 deg from anti-parallel, even an eighth of the step raised the cost; the damped steps then
crept 0.03 deg/s per step and stopped 0.39 deg/s short after 36); in the vectors the refinement
came within 2 sigmas of the optimum in 8 steps.
A vector of zero rate has no axis: there the step stays in ``x`` (:meth:`StepCoords.usable`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..._typing import FloatArray
from ...geometry.rotations import angles_from_axis, axis_from_angles

# (a, b, w) of the spin and of the precession in x.
ROTATION_BLOCKS = ((0, 1, 2), (3, 4, 5))
# Below this rate (rad/s), or this close to the pole of the angles (sin^2 b), a vector's axis is
# not defined well enough to map a step back: the step stays in x.
MIN_RATE_RAD_S = 1e-12
MIN_SIN2_POLAR = 1e-12


@dataclass(frozen=True)
class StepCoords:
    """The map between the free parameters ``z`` (those of ``x`` listed in ``free``, in that
    order) and the step coordinates ``y``: each rotation whose axis and rate are all free as its
    vector ``w l(a, b)``, every other parameter as it is."""

    free: tuple[int, ...]

    @property
    def _blocks(self) -> list[list[int]]:
        """Positions in ``z`` of each rotation's ``(a, b, w)`` whose three parameters are free."""
        pos = {p: k for k, p in enumerate(self.free)}
        return [[pos[i] for i in blk] for blk in ROTATION_BLOCKS if all(i in pos for i in blk)]

    def usable(self, z: FloatArray) -> bool:
        """Whether ``z`` lies in the chart of :meth:`z_of` (what :meth:`dz_dy` differentiates)
        and every vector there has a well-defined axis (a rate, off the pole)."""
        return all(
            z[w] > MIN_RATE_RAD_S and 0.0 <= z[b] <= np.pi and np.sin(z[b]) ** 2 > MIN_SIN2_POLAR
            for _, b, w in self._blocks
        )

    def y_of(self, z: FloatArray) -> FloatArray:
        """Step coordinates of ``z``."""
        y = np.array(z, dtype=float)
        for idx in self._blocks:
            a, b, w = z[idx]
            y[idx] = w * axis_from_angles(a, b)
        return y

    def z_of(self, y: FloatArray) -> FloatArray:
        """Parameters of ``y``: each vector as its angles (``a`` in ``(-pi, pi]``, ``b`` in
        ``[0, pi]``) and its rate (``>= 0``), the chart of ``canonical_params``."""
        z = np.array(y, dtype=float)
        for idx in self._blocks:
            v = y[idx]
            z[idx] = (*angles_from_axis(v), float(np.linalg.norm(v)))
        return z

    def dz_dy(self, z: FloatArray) -> FloatArray:
        """``dz / dy`` at ``z`` (square, the size of ``z``), for ``z`` in the chart of
        :meth:`z_of`: ``a = atan2(V_y, V_x)``, ``b = atan2(|V_xy|, V_z)``, ``w = |V|``."""
        M = np.eye(len(z))
        y = self.y_of(z)
        for idx in self._blocks:
            vx, vy, vz = y[idx]
            w = z[idx[2]]
            rxy2 = vx * vx + vy * vy
            rxy = np.sqrt(rxy2)
            M[np.ix_(idx, idx)] = [
                [-vy / rxy2, vx / rxy2, 0.0],
                [vx * vz / (rxy * w * w), vy * vz / (rxy * w * w), -rxy / (w * w)],
                [vx / w, vy / w, vz / w],
            ]
        return M
