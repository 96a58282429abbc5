"""Parametric satellite target: a box bus with two solar panels (paper: 14.4 x 4.8 x 4.4 m).

The body frame has its origin at the bus centre, panels along ``x``. Corner features are the
bus's 8 corners and each panel's 4 corners on its sun-facing side (16 in all).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field

from .._open3d import load_open3d

if TYPE_CHECKING:
    import open3d as o3d


class SatelliteShape(BaseModel):
    """Dimensions in metres; the defaults give an overall 14.4 x 4.8 x 4.4 m envelope."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    kind: Literal["box"] = "box"
    bus_m: tuple[float, float, float] = (3.2, 3.0, 4.4)
    panel_length_m: float = Field(5.6, gt=0)
    panel_width_m: float = Field(4.8, gt=0)
    panel_thickness_m: float = Field(0.06, gt=0)

    def boxes(self) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
        """(min corner, max corner) of the bus and the two panels."""
        bx, by, bz = (v / 2 for v in self.bus_m)
        hw, ht = self.panel_width_m / 2, self.panel_thickness_m / 2
        bus = (np.array([-bx, -by, -bz]), np.array([bx, by, bz]))
        right = (np.array([bx, -hw, -ht]), np.array([bx + self.panel_length_m, hw, ht]))
        left = (np.array([-bx - self.panel_length_m, -hw, -ht]), np.array([-bx, hw, ht]))
        return [bus, right, left]

    def corners_m(self) -> NDArray[np.float64]:
        """The 16 corner features in the body frame, shape ``(16, 3)``."""
        boxes = self.boxes()
        lo, hi = boxes[0]
        bus = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        panels = [
            np.array([[x, y, phi[2]] for x in (plo[0], phi[0]) for y in (plo[1], phi[1])]) for plo, phi in boxes[1:]
        ]
        return np.vstack([bus, *panels])

    def extent_m(self) -> NDArray[np.float64]:
        lo = np.min([b[0] for b in self.boxes()], axis=0)
        hi = np.max([b[1] for b in self.boxes()], axis=0)
        return np.asarray(hi - lo, dtype=float)

    def mesh(self) -> o3d.geometry.TriangleMesh:
        """The target as one Open3D triangle mesh in the body frame."""
        o3d = load_open3d()

        mesh = o3d.geometry.TriangleMesh()
        for lo, hi in self.boxes():
            box = o3d.geometry.TriangleMesh.create_box(*(hi - lo))
            box.translate(lo)
            mesh += box
        return mesh
