"""Rotations: axes from spherical angles and back, Rodrigues' rotation of vectors and as matrices.

Every function accepts complex values (Jacobians by complex step) and leading batch axes.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[Any]


def axis_from_angles(alpha_rad: ArrayLike, beta_rad: ArrayLike) -> Array:
    """Unit axis ``(cos a sin b, sin a sin b, cos b)``; shape ``(..., 3)``."""
    a = np.asarray(alpha_rad)
    b = np.asarray(beta_rad)
    sb = np.sin(b)
    return np.stack([np.cos(a) * sb, np.sin(a) * sb, np.cos(b)], axis=-1)


def axis_tangents(alpha_rad: float, beta_rad: float) -> Array:
    """``(3, 2)``: the derivatives of :func:`axis_from_angles` w.r.t. ``alpha`` and ``beta``,
    ``(-sin a sin b, cos a sin b, 0)`` and ``(cos a cos b, sin a cos b, -sin b)``."""
    a, b = alpha_rad, beta_rad
    d_alpha = np.array([-np.sin(a) * np.sin(b), np.cos(a) * np.sin(b), 0.0])
    d_beta = np.array([np.cos(a) * np.cos(b), np.sin(a) * np.cos(b), -np.sin(b)])
    return np.stack([d_alpha, d_beta], axis=1)


def angles_from_axis(axis: ArrayLike) -> tuple[float, float]:
    """Spherical angles ``(alpha, beta)`` in radians of a (not necessarily unit) axis."""
    v = np.asarray(axis, dtype=float)
    v = v / np.linalg.norm(v)
    return float(np.arctan2(v[1], v[0])), float(np.arccos(np.clip(v[2], -1.0, 1.0)))


def rotate(axis: Array, angle_rad: Array, v: Array) -> Array:
    """Rotate vectors ``v`` by ``angle`` about unit ``axis`` (Rodrigues), broadcasting.

    ``v' = v cos a + (l x v) sin a + l (l . v)(1 - cos a)``; shapes broadcast as
    ``axis (..., 3)``, ``angle (...)``, ``v (..., 3)``.
    """
    c = np.cos(angle_rad)
    s = np.sin(angle_rad)
    lx, ly, lz = axis[..., 0], axis[..., 1], axis[..., 2]
    vx, vy, vz = v[..., 0], v[..., 1], v[..., 2]
    k = (lx * vx + ly * vy + lz * vz) * (1.0 - c)
    x = vx * c + (ly * vz - lz * vy) * s + lx * k
    y = vy * c + (lz * vx - lx * vz) * s + ly * k
    z = vz * c + (lx * vy - ly * vx) * s + lz * k
    out = np.empty((*x.shape, 3), dtype=x.dtype)
    out[..., 0], out[..., 1], out[..., 2] = x, y, z
    return out


def rotation_matrix(axis: ArrayLike, angle_rad: ArrayLike) -> Array:
    """Rodrigues rotation matrices ``c I + s [l]x + (1 - c) l l^T``, shape ``(..., 3, 3)``."""
    l = np.asarray(axis)
    a = np.asarray(angle_rad)
    c, s = np.cos(a), np.sin(a)
    C = 1.0 - c
    x, y, z = l[..., 0], l[..., 1], l[..., 2]
    shape = np.broadcast_shapes(x.shape, a.shape)
    R = np.empty((*shape, 3, 3), dtype=np.result_type(l, a, float))
    R[..., 0, 0] = c + x * x * C
    R[..., 0, 1] = x * y * C - z * s
    R[..., 0, 2] = x * z * C + y * s
    R[..., 1, 0] = y * x * C + z * s
    R[..., 1, 1] = c + y * y * C
    R[..., 1, 2] = y * z * C - x * s
    R[..., 2, 0] = z * x * C - y * s
    R[..., 2, 1] = z * y * C + x * s
    R[..., 2, 2] = c + z * z * C
    return R


def tangent_basis(a: Array) -> tuple[Array, Array]:
    """Two unit vectors ``e1, e2`` (3,) orthogonal to the unit ``a`` (3,) and to each other, with
    ``e2 = a × e1`` (a right-handed frame ``e1, e2, a``). ``e1`` is ``a`` crossed with whichever
    coordinate axis is farther from it, so it is defined for every ``a``."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = cross3(a, helper)
    e1 = e1 / np.linalg.norm(e1)
    return e1, cross3(a, e1)


def cross3(u: Array, w: Array) -> Array:
    """``u × w`` over the last axis of 3-vectors, broadcast: ``np.cross``'s arithmetic without its
    overhead, which dominates on the small arrays the spin fit evaluates tens of thousands of
    times (and on single vectors: the fit builds thousands of tangent bases)."""
    if u.ndim == 1 and w.ndim == 1:  # plain floats: a fifth of np.stack's cost on 0-d arrays
        return np.array([u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]])
    u0, u1, u2 = u[..., 0], u[..., 1], u[..., 2]
    w0, w1, w2 = w[..., 0], w[..., 1], w[..., 2]
    return np.stack([u1 * w2 - u2 * w1, u2 * w0 - u0 * w2, u0 * w1 - u1 * w0], axis=-1)
