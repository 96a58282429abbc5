"""Motion blur: the mean of renders at several instants over the exposure (added for spin-from-images)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .._typing import FloatArray
from .camera import PinholeCamera
from .mesh import Mesh
from .render import Rendering, render


def render_exposure(
    mesh: Mesh,
    camera: PinholeCamera,
    poses: Sequence[tuple[FloatArray, FloatArray]],
    sun_cam: FloatArray,
    *,
    supersample: int = 3,
    ambient: float = 0.03,
) -> Rendering:
    """Radiance averaged over ``poses`` (``(R_cam_from_body, t_cam_m)`` at instants spread evenly over
    the exposure): a box-filter motion blur. One pose is a plain render."""
    radiance = np.zeros((camera.height_px, camera.width_px))
    coverage = np.zeros_like(radiance)
    for R_cam_from_body, t_cam_m in poses:
        r = render(mesh, camera, R_cam_from_body, t_cam_m, sun_cam, supersample=supersample, ambient=ambient)
        radiance += r.radiance
        coverage += r.coverage
    n = max(len(poses), 1)
    return Rendering(radiance / n, coverage / n)
