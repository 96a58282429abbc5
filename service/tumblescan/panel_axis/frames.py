"""Frames: the camera's pointing in the station's ENU frame, ENU to ECEF, and the paper's pitch/yaw.

ENU: x East, y North, z Up. Azimuth A is clockwise from North, elevation E above the horizon, and
the line of sight is ``s = (cosE sinA, cosE cosA, sinE)``. The camera (OpenCV: x right, y down,
z forward) has rows ``x_c = cos r·h + sin r·(s×h)``, ``y_c = s×x_c``, ``z_c = s`` with
``h = (cosA, -sinA, 0)``; at roll r = 0 the image x axis is horizontal (the paper's eq. 8).
"""

from __future__ import annotations

import numpy as np

from .._typing import FloatArray


def R_cam_from_enu(azimuth_deg: float, elevation_deg: float, roll_deg: float = 0.0) -> FloatArray:
    """Rotation (3, 3) taking ENU vectors into the camera frame (rows: camera x, y, z in ENU)."""
    A, E, r = np.radians([azimuth_deg, elevation_deg, roll_deg])
    s = np.array([np.cos(E) * np.sin(A), np.cos(E) * np.cos(A), np.sin(E)])
    h = np.array([np.cos(A), -np.sin(A), 0.0])
    x_c = np.cos(r) * h + np.sin(r) * np.cross(s, h)
    y_c = np.cross(s, x_c)
    return np.vstack([x_c, y_c, s])


def R_ecef_from_enu(lat_deg: float, lon_deg: float) -> FloatArray:
    """Rotation (3, 3) taking ENU vectors at (lat, lon) into ECEF: the paper's M (eq. 3-4), as
    ``pymap3d.enu2uvw`` applies it column by column."""
    import pymap3d

    cols = [np.array(pymap3d.enu2uvw(*e, lat_deg, lon_deg, deg=True), dtype=float) for e in np.eye(3)]
    return np.column_stack(cols)


def station_ecef_m(lat_deg: float, lon_deg: float, height_m: float) -> FloatArray:
    """The station's ECEF position (m, WGS84; the paper's eq. 2)."""
    import pymap3d

    return np.array(pymap3d.geodetic2ecef(lat_deg, lon_deg, height_m, deg=True), dtype=float)


def canonical(v: FloatArray, axis: int) -> FloatArray:
    """The line direction ``v`` signed so that its component ``axis`` is >= 0 (an axis is a line)."""
    v = np.asarray(v, dtype=float)
    return -v if v[axis] < 0 else v


def pitch_yaw_deg(L: FloatArray) -> tuple[float, float]:
    """Eq. 1, ``L = (cosα sinβ, cosα cosβ, sinα)``: pitch α above the x-y plane and yaw β of the
    projection, from +y toward +x (North toward East in ENU)."""
    x, y, z = np.asarray(L, dtype=float) / np.linalg.norm(L)
    return float(np.degrees(np.arctan2(z, np.hypot(x, y)))), float(np.degrees(np.arctan2(x, y)))


def pitch_yaw_jacobian(L: FloatArray, basis: FloatArray) -> FloatArray:
    """d(pitch, yaw)/d(tangent) (2, 2) in rad/rad for the unit direction ``L`` moved along the rows of
    ``basis`` (2, 3)."""
    x, y, z = L
    rho2 = x * x + y * y
    rho = np.sqrt(rho2)
    d_pitch = np.array([-x * z / rho, -y * z / rho, rho])  # gradient of atan2(z, rho) on the unit sphere
    d_yaw = np.array([y / rho2, -x / rho2, 0.0])
    return np.array([[d_pitch @ b for b in basis], [d_yaw @ b for b in basis]])
