"""The simulated target: a box bus with a payload box and two wings on yokes.

Body frame: the bus centre is the origin, the wings lie along ±y and a drive angle turns them about
y (so the panel axis is always the body y axis), the payload sits on +z.
"""

from __future__ import annotations

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from .._typing import FloatArray
from ..imaging.mesh import Mesh, box, merge

BUS_ALBEDO = 0.55
PAYLOAD_ALBEDO = 0.7
YOKE_ALBEDO = 0.35
PANEL_ALBEDO = 0.28


class Spacecraft(BaseModel):
    """Sizes in metres; ``drive_deg`` turns both wings about the body y axis."""

    model_config = ConfigDict(extra="forbid")

    bus_m: tuple[float, float, float] = (2.0, 2.0, 2.5)
    payload_m: tuple[float, float, float] = (0.8, 0.8, 0.5)
    yoke_m: float = 0.7
    panel_length_m: float = Field(5.5, gt=0)
    panel_width_m: float = Field(2.0, gt=0)
    sub_panels: int = Field(3, ge=1)
    gap_m: float = 0.05
    thickness_m: float = 0.02
    drive_deg: float = 0.0

    @property
    def R_drive(self) -> FloatArray:
        a = np.radians(self.drive_deg)
        return np.array([[np.cos(a), 0.0, np.sin(a)], [0.0, 1.0, 0.0], [-np.sin(a), 0.0, np.cos(a)]])

    @property
    def panel_normal_body(self) -> FloatArray:
        return np.asarray(self.R_drive @ np.array([0.0, 0.0, 1.0]), dtype=float)

    @property
    def wing_root_m(self) -> float:
        """Distance from the bus centre to the inner end of each wing, along y."""
        return self.bus_m[1] / 2 + self.yoke_m

    def mesh(self) -> Mesh:
        _, by, bz = self.bus_m
        parts = [
            box((0, 0, 0), self.bus_m, BUS_ALBEDO),
            box((0, 0, bz / 2 + self.payload_m[2] / 2), self.payload_m, PAYLOAD_ALBEDO),
        ]
        n = self.sub_panels
        sub = (self.panel_length_m - (n - 1) * self.gap_m) / n
        for side in (1.0, -1.0):
            parts.append(box((0, side * (by / 2 + self.yoke_m / 2), 0), (0.08, self.yoke_m, 0.08), YOKE_ALBEDO))
            for k in range(n):
                y = self.wing_root_m + k * (sub + self.gap_m) + sub / 2
                parts.append(
                    box((0, side * y, 0), (self.panel_width_m, sub, self.thickness_m), PANEL_ALBEDO, self.R_drive)
                )
        return merge(parts)

    def wing_corners_body(self, side: float, face: float) -> FloatArray:
        """The 4 corners (4, 3) of one wing's face (``face`` = ±1 for ±normal): root-(-x), tip-(-x),
        tip-(+x), root-(+x), wing length along y."""
        w, t = self.panel_width_m / 2, self.thickness_m / 2 * face
        y0, y1 = self.wing_root_m, self.wing_root_m + self.panel_length_m
        c = np.array([[-w, side * y0, t], [-w, side * y1, t], [w, side * y1, t], [w, side * y0, t]])
        return np.asarray(c @ self.R_drive.T, dtype=float)


def random_spacecraft(rng: np.random.Generator) -> Spacecraft:
    """Sizes drawn from the digest's ranges (bus about 2x2x2.5 m, wings 4-7 x 1.6-2.6 m, 2-4 sub-panels)."""
    return Spacecraft(
        bus_m=(float(rng.uniform(1.8, 2.2)), float(rng.uniform(1.8, 2.2)), float(rng.uniform(2.2, 2.8))),
        payload_m=(float(rng.uniform(0.6, 1.0)), float(rng.uniform(0.6, 1.0)), float(rng.uniform(0.3, 0.7))),
        yoke_m=float(rng.uniform(0.5, 1.0)),
        panel_length_m=float(rng.uniform(4.0, 7.0)),
        panel_width_m=float(rng.uniform(1.6, 2.6)),
        sub_panels=int(rng.integers(2, 5)),
        drive_deg=float(rng.uniform(-180, 180)),
    )
