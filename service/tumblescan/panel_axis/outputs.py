"""Camera-frame estimates in the result's frames: station ENU and ECEF, signed as lines, with
pitch/yaw (eq. 1) and their σ."""

from __future__ import annotations

import numpy as np

from .._typing import FloatArray
from .frames import R_ecef_from_enu, canonical, pitch_yaw_deg, pitch_yaw_jacobian
from .meta import MatrixPointing, PanelAxisInput
from .result import Axis, Direction


class Frames:
    """Turns camera-frame directions into the input's frames (station ENU, ECEF), signed as lines."""

    def __init__(self, meta: PanelAxisInput) -> None:
        R = meta.R_cam_from_ref
        self.R_cam_from_enu: FloatArray | None = None
        self.R_ecef_from_enu: FloatArray | None = None
        self.R_cam_from_ecef: FloatArray | None = None
        if meta.station is not None:
            self.R_ecef_from_enu = R_ecef_from_enu(meta.station.lat_deg, meta.station.lon_deg)
        if R is None:
            return
        if isinstance(meta.pointing, MatrixPointing) and meta.pointing.frame == "ecef":
            self.R_cam_from_ecef = R
            if self.R_ecef_from_enu is not None:
                self.R_cam_from_enu = R @ self.R_ecef_from_enu
        else:
            self.R_cam_from_enu = R
            if self.R_ecef_from_enu is not None:
                self.R_cam_from_ecef = R @ self.R_ecef_from_enu.T

    def signed(self, d_cam: FloatArray) -> FloatArray:
        """``d_cam`` signed as the line's canonical station vector (North >= 0), else camera x >= 0."""
        d = np.asarray(d_cam, dtype=float) / np.linalg.norm(d_cam)
        if self.R_cam_from_enu is not None:
            return d if (self.R_cam_from_enu.T @ d)[1] >= 0 else -d
        if self.R_cam_from_ecef is not None:
            return d if (self.R_cam_from_ecef.T @ d)[1] >= 0 else -d
        return canonical(d, 0)

    def direction(self, d_cam: FloatArray) -> Direction:
        d = self.signed(d_cam)
        enu = self.R_cam_from_enu.T @ d if self.R_cam_from_enu is not None else None
        ecef = self.R_cam_from_ecef.T @ d if self.R_cam_from_ecef is not None else None
        return Direction(
            camera=d.tolist(),
            station_enu=canonical(enu, 1).tolist() if enu is not None else None,
            ecef=canonical(ecef, 1).tolist() if ecef is not None else None,
        )

    def axis(self, d_cam: FloatArray, cov: FloatArray, basis_cam: FloatArray) -> Axis:
        dd = self.direction(d_cam)
        out = Axis(camera=dd.camera, station_enu=dd.station_enu, ecef=dd.ecef)
        out.sigma_deg = float(np.degrees(np.sqrt(max(np.linalg.eigvalsh(cov).max(), 0.0))))
        out.cov_tangent_rad2 = np.asarray(cov).tolist()
        out.tangent_basis_camera = np.asarray(basis_cam).tolist()
        for name, vec, R in (("", dd.station_enu, self.R_cam_from_enu), ("_ecef", dd.ecef, self.R_cam_from_ecef)):
            if vec is None or R is None:
                continue
            L = np.asarray(vec)
            pitch, yaw = pitch_yaw_deg(L)
            setattr(out, f"pitch{name}_deg", pitch)
            setattr(out, f"yaw{name}_deg", yaw)
            if name == "":
                basis = np.asarray(basis_cam) @ R  # rows: basis vectors in ENU
                out.tangent_basis_enu = basis.tolist()
                J = pitch_yaw_jacobian(L, basis)
                c = J @ cov @ J.T
                out.sigma_pitch_deg = float(np.degrees(np.sqrt(max(c[0, 0], 0.0))))
                out.sigma_yaw_deg = float(np.degrees(np.sqrt(max(c[1, 1], 0.0))))
        return out
