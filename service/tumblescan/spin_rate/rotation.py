"""Rotations about a fixed axis (Rodrigues) and the axis' conventions (twin, sense, angles)."""

from __future__ import annotations

import numpy as np

from .._typing import FloatArray


def rot(axis: FloatArray, angle_rad: float | FloatArray) -> FloatArray:
    """Rotation matrices (N, 3, 3) by ``angle_rad`` (N,) about the unit ``axis`` (3,), right-handed."""
    a = np.asarray(axis, dtype=float)
    th = np.atleast_1d(np.asarray(angle_rad, dtype=float))
    A = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    c, s = np.cos(th)[:, None, None], np.sin(th)[:, None, None]
    return np.asarray(c * np.eye(3) + s * A + (1 - c) * np.outer(a, a), dtype=float)


def unit_from_angles(theta: float, phi: float) -> FloatArray:
    """The unit vector at polar angle ``theta`` from +z and azimuth ``phi`` from +x toward +y."""
    return np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])


def mirror_twin(a: FloatArray) -> FloatArray:
    """The weak-perspective (Necker) twin ``(-a_x, -a_y, a_z)``."""
    return np.array([-a[0], -a[1], a[2]])


def los_angle_deg(a: FloatArray) -> float:
    """Angle (deg, 0-90) between the axis line and the line of sight (+z)."""
    return float(np.degrees(np.arccos(min(abs(float(a[2])) / float(np.linalg.norm(a)), 1.0))))


def projected_angle_deg(a: FloatArray) -> float:
    """Direction of the axis line in the image, [0, 180) from +x toward +y."""
    return float(np.degrees(np.arctan2(a[1], a[0])) % 180.0)


def angle_between_deg(a: FloatArray, b: FloatArray) -> float:
    c = float(np.dot(a, b) / (np.linalg.norm(a) * np.linalg.norm(b)))
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))
