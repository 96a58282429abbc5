"""Spin + precession motion model of a tumbling target (method.md section 2).

A body point with position ``P(T)`` at the reference time ``T`` is at

    P(t) = O_p + Rp(t) Rs(t) (P(T) - O_p),
    Rp(t) = Rot(l_p, w_p (t - T)),   Rs(t) = Rot(l_s, w_s (t - T))

where ``l_s`` is the spin axis at ``T``, ``l_p`` the space-fixed precession axis through
``O_p`` and ``Rot`` the Rodrigues rotation. Axes are parameterized by spherical angles
``l = (cos a sin b, sin a sin b, cos b)`` so the 9 unknowns
``x = (a_s, b_s, w_s, a_p, b_p, w_p, O_x, O_y, O_z)`` are unconstrained (paper eqs. 6-8).

Every function here accepts a leading batch of parameter vectors (shape ``(k, 9)``) and
complex values, so Jacobians can be taken by complex step and a swarm can be evaluated in
one call.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..geometry.rotations import angles_from_axis, axis_from_angles, rotate, rotation_matrix

N_PARAMS = 9
PARAM_NAMES = ("a_s", "b_s", "w_s", "a_p", "b_p", "w_p", "O_x", "O_y", "O_z")

Array = NDArray[Any]


def _unpack(x: Array) -> tuple[Array, Array, Array, Array, Array]:
    """Split parameter vectors ``(..., 9)`` into axes, rates and centre, each with a
    trailing point axis inserted so they broadcast against ``(..., n, 3)`` points."""
    l_s = axis_from_angles(x[..., 0], x[..., 1])[..., None, :]
    l_p = axis_from_angles(x[..., 3], x[..., 4])[..., None, :]
    w_s = x[..., 2][..., None]
    w_p = x[..., 5][..., None]
    center = x[..., 6:9][..., None, :]
    return l_s, w_s, l_p, w_p, center


def apply_rotation(x: Array, tau_s: Array, v: Array, *, inverse: bool = False) -> Array:
    """``R(tau) v = Rp Rs v`` (or ``R(tau)^T v`` with ``inverse``) for offsets ``tau = t - T``.

    x: ``(..., 9)`` parameters; tau_s: ``(n,)`` seconds; v: ``(n, 3)`` or ``(..., n, 3)``.
    """
    l_s, w_s, l_p, w_p, _ = _unpack(x)
    if inverse:
        return rotate(l_s, -w_s * tau_s, rotate(l_p, -w_p * tau_s, v))
    return rotate(l_p, w_p * tau_s, rotate(l_s, w_s * tau_s, v))


def predict(x: Array, body_m: Array, tau_s: Array) -> Array:
    """Forward model: positions at ``T + tau`` of body points given at ``T``.

    ``P(t) = O_p + R(tau) (P(T) - O_p)``; x ``(..., 9)``, body_m ``(n, 3)``, tau_s ``(n,)``
    -> ``(..., n, 3)`` metres.
    """
    center = _unpack(x)[4]
    return center + apply_rotation(x, tau_s, body_m - center)


def rotation_matrices(x: NDArray[np.float64], tau_s: NDArray[np.float64]) -> NDArray[np.float64]:
    """``R(tau) = Rp(tau) Rs(tau)`` for each offset, shape ``(n, 3, 3)``."""
    l_s = axis_from_angles(x[0], x[1])
    l_p = axis_from_angles(x[3], x[4])
    return np.asarray(rotation_matrix(l_p, x[5] * tau_s) @ rotation_matrix(l_s, x[2] * tau_s), dtype=float)


def to_reference(x: Array, obs_m: Array, tau_s: Array) -> Array:
    """Backward model: positions at ``T`` of points observed at ``T + tau``.

    ``P(T) = O_p + R(tau)^T (P(t) - O_p)``; shapes as :func:`predict`.
    """
    center = _unpack(x)[4]
    return center + apply_rotation(x, tau_s, obs_m - center, inverse=True)


def transport(x: Array, obs_m: Array, tau_from_s: Array, tau_to_s: Array) -> Array:
    """Map points observed at ``T + tau_from`` to ``T + tau_to``: ``O + R(to) R(from)^T (P - O)``."""
    center = _unpack(x)[4]
    at_ref = apply_rotation(x, tau_from_s, obs_m - center, inverse=True)
    return center + apply_rotation(x, tau_to_s, at_ref)


def canonical_params(x: ArrayLike) -> NDArray[np.float64]:
    """The same motion with both rates >= 0 (``(l, w) == (-l, -w)``), ``b`` in ``[0, pi]``
    and ``a`` in ``(-pi, pi]``."""
    p = np.array(x, dtype=float)
    for a, b, w in ((0, 1, 2), (3, 4, 5)):
        # Fold b into [0, pi] first: (a, -b) and (a + pi, b) name the same axis.
        b_mod = np.mod(p[b], 2 * np.pi)
        if b_mod > np.pi:
            p[a], b_mod = p[a] + np.pi, 2 * np.pi - b_mod
        p[b] = b_mod
        if p[w] < 0:
            p[a], p[b], p[w] = p[a] + np.pi, np.pi - p[b], -p[w]
        p[a] = np.pi - np.mod(np.pi - p[a], 2 * np.pi)
    return p


@dataclass(frozen=True)
class Motion:
    """A spin + precession motion in SI units, with axes as unit vectors.

    spin_axis: (3,) spin axis at ``reference_time_s``. spin_rate_rad_s: spin rate.
    precession_axis: (3,) space-fixed precession axis (any unit vector when the rate is 0).
    precession_rate_rad_s: precession rate. center_m: (3,) point on both axes, metres.
    """

    spin_axis: tuple[float, float, float]
    spin_rate_rad_s: float
    precession_axis: tuple[float, float, float]
    precession_rate_rad_s: float
    center_m: tuple[float, float, float]
    reference_time_s: float = 0.0

    @classmethod
    def from_params(cls, x: ArrayLike, reference_time_s: float = 0.0) -> Motion:
        p = np.asarray(x, dtype=float)
        l_s = axis_from_angles(p[0], p[1])
        l_p = axis_from_angles(p[3], p[4])
        return cls(
            spin_axis=_vec3(l_s),
            spin_rate_rad_s=float(p[2]),
            precession_axis=_vec3(l_p),
            precession_rate_rad_s=float(p[5]),
            center_m=_vec3(p[6:9]),
            reference_time_s=reference_time_s,
        )

    @classmethod
    def from_degrees(
        cls,
        *,
        spin_axis: ArrayLike,
        spin_rate_deg_s: float,
        precession_axis: ArrayLike = (0.0, 0.0, 1.0),
        precession_rate_deg_s: float = 0.0,
        center_m: ArrayLike = (0.0, 0.0, 0.0),
        reference_time_s: float = 0.0,
    ) -> Motion:
        l_s = np.asarray(spin_axis, dtype=float)
        l_p = np.asarray(precession_axis, dtype=float)
        return cls(
            spin_axis=_vec3(l_s / np.linalg.norm(l_s)),
            spin_rate_rad_s=float(np.radians(spin_rate_deg_s)),
            precession_axis=_vec3(l_p / np.linalg.norm(l_p)),
            precession_rate_rad_s=float(np.radians(precession_rate_deg_s)),
            center_m=_vec3(np.asarray(center_m, dtype=float)),
            reference_time_s=reference_time_s,
        )

    def params(self) -> NDArray[np.float64]:
        """The 9-vector ``x`` of the self-constrained parameterization."""
        a_s, b_s = angles_from_axis(self.spin_axis)
        a_p, b_p = angles_from_axis(self.precession_axis)
        return np.array([a_s, b_s, self.spin_rate_rad_s, a_p, b_p, self.precession_rate_rad_s, *self.center_m])

    def canonical(self) -> Motion:
        """The same motion with rates >= 0: ``(l, w) == (-l, -w)`` for both axes."""
        l_s, w_s = np.asarray(self.spin_axis), self.spin_rate_rad_s
        l_p, w_p = np.asarray(self.precession_axis), self.precession_rate_rad_s
        if w_s < 0:
            l_s, w_s = -l_s, -w_s
        if w_p < 0:
            l_p, w_p = -l_p, -w_p
        return Motion(_vec3(l_s), w_s, _vec3(l_p), w_p, self.center_m, self.reference_time_s)

    def at_reference(self, t_s: float) -> Motion:
        """The same motion described with reference time ``t_s`` (spin axis taken then)."""
        return Motion(
            _vec3(self.spin_axis_at(t_s)),
            self.spin_rate_rad_s,
            self.precession_axis,
            self.precession_rate_rad_s,
            self.center_m,
            float(t_s),
        )

    def spin_axis_at(self, t_s: ArrayLike) -> NDArray[np.float64]:
        """Spin axis at times ``t_s``: ``Rp(t) l_s``; shape ``(..., 3)``."""
        tau = np.asarray(t_s, dtype=float) - self.reference_time_s
        l_p = np.asarray(self.precession_axis)
        l_s = np.broadcast_to(np.asarray(self.spin_axis), (*tau.shape, 3))
        return np.asarray(rotate(l_p, self.precession_rate_rad_s * tau, l_s), dtype=float)

    def position(self, body_m: ArrayLike, t_s: ArrayLike) -> NDArray[np.float64]:
        """Positions at ``t_s`` ``(n,)`` of body points ``(n, 3)`` given at the reference time."""
        tau = np.asarray(t_s, dtype=float) - self.reference_time_s
        return np.asarray(predict(self.params(), np.asarray(body_m, dtype=float), tau), dtype=float)

    def nutation_angle_deg(self) -> float:
        """Angle between spin and precession axes (the cone half-angle), degrees."""
        c = float(np.dot(self.spin_axis, self.precession_axis))
        return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def _vec3(v: ArrayLike) -> tuple[float, float, float]:
    a = np.asarray(v, dtype=float).reshape(3)
    return (float(a[0]), float(a[1]), float(a[2]))
